//! Realtime: physics's own account of what its watchdog did, and of any motion of the robot
//! while no command came.
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
            "watchdog stop: the wheels ({:.0}, {:.0} mm/s) stopped {:.0} ms after the last command",
            self.wheels_mps.0 * 1e3,
            self.wheels_mps.1 * 1e3,
            ms(self.last_command_ns, self.fired_ns)
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
            " [last_command_ns={} fired_ns={} resumed_ns={} wheels_mm_s={:.0},{:.0} accounted={} motion_um={:.1} turn_mdeg={:.1}]",
            self.last_command_ns,
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
            "watchdog fired: no command for {:.0} ms, the wheels ({:.0}, {:.0} mm/s) stopped [fired_ns={}]",
            s.fired_ns.saturating_sub(s.last_command_ns) as f64 * 1e-6,
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
    /// The last fresh command, monotonic ns (`None` before the first).
    last_command_ns: Option<u64>,
    current: Option<WatchdogStop>,
    stops: u64,
    longest_ns: u64,
    motion_m: f64,
    turn_rad: f64,
}

impl WatchdogAccount {
    pub fn new(watchdog: Duration) -> Self {
        Self {
            period_ns: u64::try_from(watchdog.as_nanos()).unwrap_or(u64::MAX),
            last_command_ns: None,
            current: None,
            stops: 0,
            longest_ns: 0,
            motion_m: 0.0,
            turn_rad: 0.0,
        }
    }

    /// A fresh command arrived at `now_ns`: the stop under way, if any, ends and is returned.
    pub fn command(&mut self, now_ns: u64) -> Option<WatchdogStop> {
        self.last_command_ns = Some(now_ns);
        let mut stop = self.current.take()?;
        stop.resumed_ns = Some(now_ns);
        self.longest_ns = self.longest_ns.max(now_ns.saturating_sub(stop.fired_ns));
        Some(stop)
    }

    /// The watchdog stops the wheels (`wheels_mps`) in the tick of `now_ns`: a stop starts,
    /// unless one is under way or no command ever came. Returns the stop when it starts.
    pub fn fire(&mut self, now_ns: u64, wheels_mps: (f64, f64)) -> Option<&WatchdogStop> {
        let last_command_ns = self.last_command_ns?;
        if self.current.is_some() {
            return None;
        }
        self.stops += 1;
        self.current = Some(WatchdogStop {
            last_command_ns,
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
            "watchdog ({:.0} ms): {} stop(s) of the wheels with no command, the longest {:.0} ms{}; robot motion beyond one watchdog period after a stop: at most {:.3} mm, {:.3} deg",
            self.period_ns as f64 * 1e-6,
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

    fn account() -> WatchdogAccount {
        WatchdogAccount::new(Duration::from_millis(250))
    }

    #[test]
    fn no_stop_is_booked_before_the_first_command() {
        let mut w = account();
        assert!(w.fire(300 * MS, (0.0, 0.0)).is_none());
        w.stepped(600 * MS, Pose2::new(0.0, 0.0, 0.0));
        assert_eq!(w.current(), None);
        assert_eq!(w.stops, 0);
    }

    #[test]
    fn a_stop_runs_from_the_watchdog_to_the_next_command_and_says_its_moments() {
        let mut w = account();
        w.command(1_000 * MS);
        let fired = w.fire(1_251 * MS, (0.1, 0.12)).expect("a stop starts");
        assert!(
            fired
                .fired_line()
                .to_string()
                .ends_with("[fired_ns=1251000000]")
        );
        assert!(w.fire(1_300 * MS, (0.0, 0.0)).is_none(), "the same stop");
        let stop = w.command(2_000 * MS).expect("the stop ends on the command");
        assert_eq!(stop.last_command_ns, 1_000 * MS);
        assert_eq!(stop.fired_ns, 1_251 * MS);
        assert_eq!(stop.resumed_ns, Some(2_000 * MS));
        assert_eq!(w.stops, 1);
        assert_eq!(w.longest_ns, 749 * MS);
        let line = stop.to_string();
        assert!(
            line.contains("(100, 120 mm/s) stopped 251 ms after"),
            "{line}"
        );
        assert!(line.contains("last_command_ns=1000000000 "), "{line}");
        assert!(line.contains("resumed_ns=2000000000 "), "{line}");
        assert_eq!(w.command(2_010 * MS), None);
    }

    #[test]
    fn motion_counts_only_from_one_watchdog_period_after_the_stop_and_a_reset_is_no_motion() {
        let mut w = account();
        w.command(0);
        w.fire(250 * MS, (0.1, 0.1));
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
        let stop = w.command(1_000 * MS).expect("ended");
        assert!((stop.motion_m - 0.005).abs() < 1e-12, "{stop:?}");
        assert!((stop.turn_rad - 0.5_f64.to_radians()).abs() < 1e-12);
        assert!(w.to_string().contains("at most 5.000 mm, 0.500 deg"), "{w}");
    }

    #[test]
    fn a_turn_across_pi_is_the_short_way_round() {
        let mut w = account();
        w.command(0);
        w.fire(250 * MS, (0.0, 0.0));
        w.stepped(500 * MS, Pose2::new(0.0, 0.0, 3.0));
        w.stepped(600 * MS, Pose2::new(0.0, 0.0, -3.0));
        let turn = w.command(700 * MS).expect("ended").turn_rad;
        assert!(
            (turn - (2.0 * std::f64::consts::PI - 6.0)).abs() < 1e-12,
            "{turn}"
        );
    }
}
