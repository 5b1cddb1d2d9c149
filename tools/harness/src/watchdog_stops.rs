//! Physics's watchdog stops on the realtime clock, as physics itself says them in its log
//! (`agp-physics: watchdog stop: ... [last_command_ns=... fired_ns=... resumed_ns=...
//! wheels_mm_s=L,R accounted=0|1 motion_um=... turn_mdeg=...]`, one line per stop when it
//! ends), and how a stop answers a fault that took the link down: `bench-faults` matches each
//! fault across a bridge's link with the stop it caused, on the machine's monotonic clock
//! (`agp_shared_types::monotonic_ns`, the clock physics stamps the stops with).

use std::path::Path;

/// One stop of the wheels, as physics logged it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoggedStop {
    /// The last fresh command before the stop, monotonic ns.
    pub last_command_ns: u64,
    /// When the frame that command answered was published, monotonic ns (0: not said).
    pub last_frame_ns: u64,
    /// Ticks of physics's realtime clock from that command to the stop, and the watchdog
    /// period in ticks (`None`: a line of a physics that did not say them).
    pub ticks: Option<(u64, u64)>,
    /// The tick the watchdog stopped the wheels.
    pub fired_ns: u64,
    /// The next fresh command (`None`: none came before physics ended).
    pub resumed_ns: Option<u64>,
    /// The wheel speeds the watchdog stopped, mm/s.
    pub wheels_mm_s: (f64, f64),
    /// Whether the stop lasted beyond one watchdog period after it fired, so the motion
    /// below was accounted.
    pub accounted: bool,
    /// The robot's largest displacement (mm) and turn (deg) from one watchdog period after
    /// the stop on.
    pub motion_mm: f64,
    pub turn_deg: f64,
}

impl LoggedStop {
    /// The stop in one line of physics's log, if it is one.
    pub fn parse(line: &str) -> Option<Self> {
        if !line.contains("watchdog stop:") {
            return None;
        }
        let (_, tail) = line.rsplit_once('[')?;
        let tail = tail.trim_end().strip_suffix(']')?;
        let field = |name: &str| {
            tail.split_whitespace()
                .find_map(|kv| kv.strip_prefix(name)?.strip_prefix('='))
        };
        let num = |name: &str| field(name)?.parse::<f64>().ok();
        let int = |name: &str| field(name)?.parse::<u64>().ok();
        let (l, r) = field("wheels_mm_s")?.split_once(',')?;
        let resumed = int("resumed_ns")?;
        Some(Self {
            last_command_ns: int("last_command_ns")?,
            last_frame_ns: int("last_frame_ns").unwrap_or(0),
            ticks: int("ticks").zip(int("watchdog_ticks")),
            fired_ns: int("fired_ns")?,
            resumed_ns: (resumed != 0).then_some(resumed),
            wheels_mm_s: (l.parse().ok()?, r.parse().ok()?),
            accounted: field("accounted")? == "1",
            motion_mm: num("motion_um")? * 1e-3,
            turn_deg: num("turn_mdeg")? * 1e-3,
        })
    }

    /// Whether the wheels were turning when the watchdog stopped them.
    pub fn was_moving(&self) -> bool {
        self.wheels_mm_s.0 != 0.0 || self.wheels_mm_s.1 != 0.0
    }

    /// From the last command to the watchdog's stop, ms.
    pub fn stopped_after_ms(&self) -> f64 {
        self.fired_ns.saturating_sub(self.last_command_ns) as f64 * 1e-6
    }

    /// Whether the wheels turned on the last command for more ticks of physics's clock than
    /// its watchdog period (physics stops them in the tick one period after; `None` when the
    /// line does not say).
    pub fn stopped_late(&self) -> Option<bool> {
        self.ticks.map(|(t, period)| t > period)
    }
}

/// What physics's log says of its watchdog so far.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct WatchdogLog {
    /// The stops that ended (or that physics's end cut short), in order.
    pub stops: Vec<LoggedStop>,
    /// The moments (monotonic ns) of every stop that started.
    pub fired_ns: Vec<u64>,
}

impl WatchdogLog {
    /// Reads the log file `path` (nothing when it cannot be read).
    pub fn read(path: &Path) -> Self {
        let text = std::fs::read_to_string(path).unwrap_or_default();
        Self::from_text(&text)
    }

    pub fn from_text(text: &str) -> Self {
        let mut log = Self::default();
        for line in text.lines() {
            if let Some(stop) = LoggedStop::parse(line) {
                log.stops.push(stop);
            } else if line.contains("watchdog fired:")
                && let Some(ns) = line
                    .rsplit_once("[fired_ns=")
                    .and_then(|(_, t)| t.trim_end().strip_suffix(']'))
                    .and_then(|n| n.parse().ok())
            {
                log.fired_ns.push(ns);
            }
        }
        log
    }

    /// Whether a stop is under way (it started and has not ended).
    pub fn stop_under_way(&self) -> bool {
        self.fired_ns.len() > self.stops.len()
    }
}

/// The stop that spans a link down: the first still under way at `from_ns` (the moment
/// the link went down, plus what was already on its way then) whose last command came
/// before the link was back (`up_ns`). A stop that a command on its way ended just after
/// the link went down is not it; the stop after that command is.
pub fn stop_of_fault(stops: &[LoggedStop], from_ns: u64, up_ns: u64) -> Option<LoggedStop> {
    stops
        .iter()
        .find(|s| s.resumed_ns.is_none_or(|r| r >= from_ns) && s.last_command_ns <= up_ns)
        .copied()
}

#[cfg(test)]
mod tests {
    use super::*;

    const LINE: &str = "agp-physics: watchdog stop: the wheels (100, -20 mm/s) stopped 251 ms after the last command, a command again 749 ms later; robot motion beyond one watchdog period after it: 0.000 mm, 0.000 deg [last_command_ns=1000 fired_ns=2000 resumed_ns=3000 wheels_mm_s=100,-20 accounted=1 motion_um=1.5 turn_mdeg=2.0]";

    #[test]
    fn a_stop_line_of_physics_reads_back_and_other_lines_do_not() {
        let s = LoggedStop::parse(LINE).expect("a stop");
        assert_eq!(
            (s.last_command_ns, s.fired_ns, s.resumed_ns),
            (1000, 2000, Some(3000))
        );
        assert_eq!(s.wheels_mm_s, (100.0, -20.0));
        assert_eq!(
            (s.last_frame_ns, s.ticks, s.stopped_late()),
            (0, None, None)
        );
        assert!(s.accounted && s.was_moving());
        let ticked = LINE.replace(
            "[last_command_ns=1000 ",
            "[last_command_ns=1000 last_frame_ns=990 ticks=161 watchdog_ticks=160 ",
        );
        let t = LoggedStop::parse(&ticked).expect("a stop");
        assert_eq!((t.last_frame_ns, t.ticks), (990, Some((161, 160))));
        assert_eq!(t.stopped_late(), Some(true));
        assert!((s.motion_mm - 0.0015).abs() < 1e-12);
        assert!((s.turn_deg - 0.002).abs() < 1e-12);
        let open = LINE.replace("resumed_ns=3000", "resumed_ns=0");
        assert_eq!(LoggedStop::parse(&open).expect("a stop").resumed_ns, None);
        assert_eq!(LoggedStop::parse("agp-physics: realtime: 10 ticks"), None);
        assert_eq!(LoggedStop::parse("watchdog stop: [garbled"), None);
    }

    #[test]
    fn a_stop_that_fired_and_has_not_ended_is_under_way() {
        let fired = "agp-physics: watchdog fired: no command for 251 ms, the wheels (0, 0 mm/s) stopped [fired_ns=2000]";
        let log = WatchdogLog::from_text(&format!("{fired}\nother\n"));
        assert_eq!(log.fired_ns, vec![2000]);
        assert!(log.stop_under_way());
        let log = WatchdogLog::from_text(&format!("{fired}\n{LINE}\n"));
        assert!(!log.stop_under_way());
        assert_eq!(log.stops.len(), 1);
    }

    #[test]
    fn a_fault_is_matched_with_the_stop_that_spans_it_not_an_earlier_one() {
        let stop = |last, resumed| LoggedStop {
            last_command_ns: last,
            last_frame_ns: 0,
            ticks: None,
            fired_ns: last + 250,
            resumed_ns: resumed,
            wheels_mm_s: (0.0, 0.0),
            accounted: true,
            motion_mm: 0.0,
            turn_deg: 0.0,
        };
        let stops = [
            stop(100, Some(900)),
            stop(2_000, Some(4_000)),
            stop(6_000, None),
        ];
        // The link down at 1,990 and back at 3,500: the second stop.
        assert_eq!(stop_of_fault(&stops, 1_990, 3_500), Some(stops[1]));
        // Down at 850, and a command on its way then ended the first stop at 900: the
        // second.
        assert_eq!(stop_of_fault(&stops, 850 + 100, 3_500), Some(stops[1]));
        // Down at 5,000, back at 5,500, and commands went on until 6,000: no stop spans it
        // from before the link was back.
        assert_eq!(stop_of_fault(&stops, 5_000, 5_500), None);
        // Down at 5,990: the stop still under way.
        assert_eq!(stop_of_fault(&stops, 5_990, 7_000), Some(stops[2]));
    }
}
