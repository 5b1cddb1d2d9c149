//! Realtime: physics's own account of what its watchdog did, and of any motion of the robot
//! while no command came.
//!
//! The watchdog and the age of a command are counted in ticks of the realtime clock (one
//! world step each), the clock the robot moves by:
//! - a command is applied only if the frame it answers is at most one watchdog period old
//!   (`watchdog_ticks` ticks) in the tick it arrives: one held on its way (a stopped bridge,
//!   a loaded machine) would drive the robot on what it sensed long ago, and is refused and
//!   counted instead;
//! - the wheels stop in the tick that comes one watchdog period after the tick the last
//!   fresh command was applied in: they never turn longer than that on one command, in
//!   simulated time. Physics descheduled on a loaded machine delays its ticks (the world
//!   stands still meanwhile, then catches up tick by tick); the stop's line gives both its
//!   ticks and its moments on the machine's clock, so such a delay is told apart.
//!
//! A *stop* runs from the tick the watchdog stops the wheels (no fresh command for the
//! watchdog period, after a first one) to the next fresh command. From one watchdog period
//! after it fired on, nothing may move the robot (no command drives it, the wheels are
//! stopped): the account keeps the robot's largest displacement and turn from its pose at
//! that moment. A reset of the world during a stop (the pose jumps on purpose) takes that
//! pose again.
//!
//! Each stop is said in one line when it ends ([`WatchdogStop`]'s `Display`), with its
//! moments on the machine's monotonic clock (`CLOCK_MONOTONIC`, ns), so a tool that cut the
//! link can match the stop with its fault; the summary ([`WatchdogAccount`]'s `Display`)
//! goes beside the tick account when physics ends.

use std::time::Duration;

use agp_shared_types::Pose2;
use agp_shared_types::angle::wrap_angle;

/// One stop of the wheels by the watchdog.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WatchdogStop {
    /// The last fresh command before the stop, monotonic ns.
    pub last_command_ns: u64,
    /// When the frame that command answered was published, monotonic ns (physics's own
    /// stamp, carried back in the command's timing; 0 when it had none).
    pub last_frame_ns: u64,
    /// Ticks of the realtime clock from the tick that applied that command to the stop.
    pub ticks: u64,
    /// The watchdog period, in ticks.
    pub watchdog_ticks: u64,
    /// The tick the watchdog stopped the wheels, monotonic ns.
    pub fired_ns: u64,
    /// The next fresh command, monotonic ns (`None` while the stop lasts).
    pub resumed_ns: Option<u64>,
    /// The wheel speeds the watchdog stopped, m/s.
    pub wheels_mps: (f64, f64),
    /// The robot's pose one watchdog period after the stop fired (`None` until then).
    reference: Option<Pose2>,
    /// The largest displacement (m) and turn (rad) of the robot from `reference`.
    pub motion_m: f64,
    pub turn_rad: f64,
    /// Whether the stop lasted beyond one watchdog period after it fired (the motion is
    /// accounted from then on).
    pub accounted: bool,
}

impl std::fmt::Display for WatchdogStop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let ms = |a: u64, b: u64| b.saturating_sub(a) as f64 * 1e-6;
        write!(
            f,
            "watchdog stop: the wheels ({:.0}, {:.0} mm/s) stopped {:.0} ms after the last command ({} ticks of the realtime clock, the watchdog {})",
            self.wheels_mps.0 * 1e3,
            self.wheels_mps.1 * 1e3,
            ms(self.last_command_ns, self.fired_ns),
            self.ticks,
            self.watchdog_ticks
        )?;
        match self.resumed_ns {
            Some(r) => write!(f, ", a command again {:.0} ms later", ms(self.fired_ns, r))?,
            None => write!(f, ", no command since")?,
        }
        if self.accounted {
            write!(
                f,
                "; robot motion beyond one watchdog period after it: {:.3} mm, {:.3} deg",
                self.motion_m * 1e3,
                self.turn_rad.to_degrees()
            )?;
        } else {
            write!(f, "; shorter than one watchdog period after it")?;
        }
        write!(
            f,
            " [last_command_ns={} last_frame_ns={} ticks={} watchdog_ticks={} fired_ns={} resumed_ns={} wheels_mm_s={:.0},{:.0} accounted={} motion_um={:.1} turn_mdeg={:.1}]",
            self.last_command_ns,
            self.last_frame_ns,
            self.ticks,
            self.watchdog_ticks,
            self.fired_ns,
            self.resumed_ns.unwrap_or(0),
            self.wheels_mps.0 * 1e3,
            self.wheels_mps.1 * 1e3,
            u8::from(self.accounted),
            self.motion_m * 1e6,
            self.turn_rad.to_degrees() * 1e3
        )
    }
}

impl WatchdogStop {
    /// The line said when the stop starts (a tool waiting for the link to come back tells a
    /// stop under way from none by it).
    pub fn fired_line(&self) -> FiredLine<'_> {
        FiredLine(self)
    }
}

/// [`WatchdogStop::fired_line`]: formatted as it is printed, with no allocation.
pub struct FiredLine<'a>(&'a WatchdogStop);

impl std::fmt::Display for FiredLine<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let s = self.0;
        write!(
            f,
            "watchdog fired: no command for {:.0} ms ({} ticks), the wheels ({:.0}, {:.0} mm/s) stopped [fired_ns={}]",
            s.fired_ns.saturating_sub(s.last_command_ns) as f64 * 1e-6,
            s.ticks,
            s.wheels_mps.0 * 1e3,
            s.wheels_mps.1 * 1e3,
            s.fired_ns
        )
    }
}

/// Every stop of a realtime run, as [`WatchdogStop`]s are booked.
#[derive(Debug, Clone, PartialEq)]
pub struct WatchdogAccount {
    period_ns: u64,
    /// The watchdog period in ticks of the realtime clock.
    period_ticks: u64,
    /// The last fresh command: when it came (monotonic ns), the tick that applied it (the
    /// step of the frame that tick stepped from), when its frame was published (`None`
    /// before the first).
    last_command: Option<(u64, u64, u64)>,
    current: Option<WatchdogStop>,
    stops: u64,
    longest_ns: u64,
    motion_m: f64,
    turn_rad: f64,
    /// Commands refused as answering a frame older than one watchdog period.
    stale: u64,
}

impl WatchdogAccount {
    /// The account of a watchdog of `watchdog` on a realtime clock ticking at `rate_hz`.
    pub fn new(watchdog: Duration, rate_hz: f64) -> Self {
        Self {
            period_ns: u64::try_from(watchdog.as_nanos()).unwrap_or(u64::MAX),
            period_ticks: ((watchdog.as_secs_f64() * rate_hz).round() as u64).max(1),
            last_command: None,
            current: None,
            stops: 0,
            longest_ns: 0,
            motion_m: 0.0,
            turn_rad: 0.0,
            stale: 0,
        }
    }

    /// Whether a command answering frame `answered`, received in the tick that steps the
    /// world from frame `step`, is applied: only if that frame is at most one watchdog
    /// period old. One refused is counted.
    pub fn admits(&mut self, step: u64, answered: u64) -> bool {
        let fresh = step.saturating_sub(answered) <= self.period_ticks;
        if !fresh {
            self.stale += 1;
        }
        fresh
    }

    /// Whether the watchdog stops the wheels in the tick that steps the world from frame
    /// `step`: one watchdog period of ticks after the tick that applied the last fresh
    /// command, or no command yet.
    pub fn expired(&self, step: u64) -> bool {
        self.last_command
            .is_none_or(|(_, at, _)| step.saturating_sub(at) >= self.period_ticks)
    }

    /// A fresh command arrived at `now_ns` and is applied in the tick from frame `step`; it
    /// answered the frame published at `frame_ns`. The stop under way, if any, ends and is
    /// returned.
    pub fn command(&mut self, now_ns: u64, step: u64, frame_ns: u64) -> Option<WatchdogStop> {
        self.last_command = Some((now_ns, step, frame_ns));
        let mut stop = self.current.take()?;
        stop.resumed_ns = Some(now_ns);
        self.longest_ns = self.longest_ns.max(now_ns.saturating_sub(stop.fired_ns));
        Some(stop)
    }

    /// The watchdog stops the wheels (`wheels_mps`) in the tick of `now_ns` that steps the
    /// world from frame `step`: a stop starts, unless one is under way or no command ever
    /// came. Returns the stop when it starts.
    pub fn fire(
        &mut self,
        now_ns: u64,
        step: u64,
        wheels_mps: (f64, f64),
    ) -> Option<&WatchdogStop> {
        let (last_command_ns, at, last_frame_ns) = self.last_command?;
        if self.current.is_some() {
            return None;
        }
        self.stops += 1;
        self.current = Some(WatchdogStop {
            last_command_ns,
            last_frame_ns,
            ticks: step.saturating_sub(at),
            watchdog_ticks: self.period_ticks,
            fired_ns: now_ns,
            resumed_ns: None,
            wheels_mps,
            reference: None,
            motion_m: 0.0,
            turn_rad: 0.0,
            accounted: false,
        });
        self.current.as_ref()
    }

    /// The world was reset: a stop under way takes the robot's pose again.
    pub fn reset(&mut self) {
        if let Some(stop) = &mut self.current {
            stop.reference = None;
        }
    }

    /// After the tick of `now_ns` stepped the world, with the robot at `pose`.
    pub fn stepped(&mut self, now_ns: u64, pose: Pose2) {
        let Some(stop) = &mut self.current else {
            return;
        };
        if now_ns < stop.fired_ns.saturating_add(self.period_ns) {
            return;
        }
        stop.accounted = true;
        let Some(r) = stop.reference else {
            stop.reference = Some(pose);
            return;
        };
        stop.motion_m = stop.motion_m.max((pose.x - r.x).hypot(pose.y - r.y));
        stop.turn_rad = stop.turn_rad.max(wrap_angle(pose.theta - r.theta).abs());
        self.motion_m = self.motion_m.max(stop.motion_m);
        self.turn_rad = self.turn_rad.max(stop.turn_rad);
    }

    /// The stop under way, if any.
    pub fn current(&self) -> Option<&WatchdogStop> {
        self.current.as_ref()
    }
}

impl std::fmt::Display for WatchdogAccount {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "watchdog ({:.0} ms, {} ticks): {} command(s) refused as answering a frame older than that; {} stop(s) of the wheels with no command, the longest {:.0} ms{}; robot motion beyond one watchdog period after a stop: at most {:.3} mm, {:.3} deg",
            self.period_ns as f64 * 1e-6,
            self.period_ticks,
            self.stale,
            self.stops,
            self.longest_ns as f64 * 1e-6,
            if self.current.is_some() {
                " (the last still under way)"
            } else {
                ""
            },
            self.motion_m * 1e3,
            self.turn_rad.to_degrees()
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    /// 250 ms at 640 Hz: 160 ticks.
    fn account() -> WatchdogAccount {
        WatchdogAccount::new(Duration::from_millis(250), 640.0)
    }

    #[test]
    fn no_stop_is_booked_before_the_first_command() {
        let mut w = account();
        assert!(w.expired(0));
        assert!(w.fire(300 * MS, 192, (0.0, 0.0)).is_none());
        w.stepped(600 * MS, Pose2::new(0.0, 0.0, 0.0));
        assert_eq!(w.current(), None);
        assert_eq!(w.stops, 0);
    }

    #[test]
    fn a_stop_runs_from_the_watchdog_to_the_next_command_and_says_its_moments() {
        let mut w = account();
        w.command(1_000 * MS, 640, 990 * MS);
        let fired = w.fire(1_251 * MS, 800, (0.1, 0.12)).expect("a stop starts");
        assert!(
            fired
                .fired_line()
                .to_string()
                .ends_with("[fired_ns=1251000000]")
        );
        assert!(
            w.fire(1_300 * MS, 832, (0.0, 0.0)).is_none(),
            "the same stop"
        );
        let stop = w
            .command(2_000 * MS, 1280, 1_995 * MS)
            .expect("the stop ends on the command");
        assert_eq!(stop.last_command_ns, 1_000 * MS);
        assert_eq!(stop.last_frame_ns, 990 * MS);
        assert_eq!((stop.ticks, stop.watchdog_ticks), (160, 160));
        assert_eq!(stop.fired_ns, 1_251 * MS);
        assert_eq!(stop.resumed_ns, Some(2_000 * MS));
        assert_eq!(w.stops, 1);
        assert_eq!(w.longest_ns, 749 * MS);
        let line = stop.to_string();
        assert!(
            line.contains("(100, 120 mm/s) stopped 251 ms after the last command (160 ticks of the realtime clock, the watchdog 160)"),
            "{line}"
        );
        assert!(line.contains("last_command_ns=1000000000 "), "{line}");
        assert!(
            line.contains("last_frame_ns=990000000 ticks=160 watchdog_ticks=160 "),
            "{line}"
        );
        assert!(line.contains("resumed_ns=2000000000 "), "{line}");
        assert_eq!(w.command(2_010 * MS, 1286, 2_005 * MS), None);
    }

    #[test]
    fn a_command_answering_a_frame_older_than_one_watchdog_period_is_refused_and_counted() {
        let mut w = account();
        // In the tick from frame 1000: frames 840..=1000 are at most 160 ticks old.
        assert!(w.admits(1000, 1000));
        assert!(w.admits(1000, 840));
        assert!(!w.admits(1000, 839));
        assert!(!w.admits(1000, 0));
        // A frame from after this tick's (never sent by physics) is no older than it.
        assert!(w.admits(1000, 1001));
        assert_eq!(w.stale, 2);
        assert!(
            w.to_string()
                .starts_with("watchdog (250 ms, 160 ticks): 2 command(s) refused as answering a frame older than that;"),
            "{w}"
        );
    }

    #[test]
    fn the_wheels_stop_one_watchdog_period_of_ticks_after_the_last_command_however_late_the_ticks_come()
     {
        let mut w = account();
        w.command(0, 100, 0);
        // The ticks are what counts, not the machine's clock: 159 ticks after the command
        // the wheels still turn though 900 ms passed (physics was descheduled), and they
        // stop in the 160th however soon it comes.
        assert!(!w.expired(100));
        assert!(!w.expired(259));
        assert!(w.expired(260));
        let stop = w.fire(MS, 260, (0.1, 0.1)).expect("a stop");
        assert_eq!(stop.ticks, 160);
        // A fresh command starts the count again.
        w.command(2 * MS, 300, MS);
        assert!(!w.expired(459));
        assert!(w.expired(460));
    }

    #[test]
    fn motion_counts_only_from_one_watchdog_period_after_the_stop_and_a_reset_is_no_motion() {
        let mut w = account();
        w.command(0, 0, 0);
        w.fire(250 * MS, 160, (0.1, 0.1));
        // Within the period after the stop (a dynamic robot may still roll): not counted.
        w.stepped(300 * MS, Pose2::new(0.0, 0.0, 0.0));
        w.stepped(499 * MS, Pose2::new(0.010, 0.0, 0.0));
        assert!(!w.current().expect("under way").accounted);
        // From then on, 3 mm and 4 mm away is 5 mm; a turn of 0.5 deg.
        w.stepped(500 * MS, Pose2::new(0.010, 0.0, 0.0));
        w.stepped(600 * MS, Pose2::new(0.013, 0.004, 0.5_f64.to_radians()));
        w.stepped(700 * MS, Pose2::new(0.010, 0.0, 0.0));
        // A reset moves the robot on purpose: the pose is taken again.
        w.reset();
        w.stepped(800 * MS, Pose2::new(0.3, 0.2, 1.0));
        w.stepped(900 * MS, Pose2::new(0.3, 0.2, 1.0));
        let stop = w.command(1_000 * MS, 640, 0).expect("ended");
        assert!((stop.motion_m - 0.005).abs() < 1e-12, "{stop:?}");
        assert!((stop.turn_rad - 0.5_f64.to_radians()).abs() < 1e-12);
        assert!(w.to_string().contains("at most 5.000 mm, 0.500 deg"), "{w}");
    }

    #[test]
    fn a_turn_across_pi_is_the_short_way_round() {
        let mut w = account();
        w.command(0, 0, 0);
        w.fire(250 * MS, 160, (0.0, 0.0));
        w.stepped(500 * MS, Pose2::new(0.0, 0.0, 3.0));
        w.stepped(600 * MS, Pose2::new(0.0, 0.0, -3.0));
        let turn = w.command(700 * MS, 448, 0).expect("ended").turn_rad;
        assert!(
            (turn - (2.0 * std::f64::consts::PI - 6.0)).abs() < 1e-12,
            "{turn}"
        );
    }
}
