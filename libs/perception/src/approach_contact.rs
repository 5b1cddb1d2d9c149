//! The paper's ObjInContact for a corner met head-on: contact inferred when the front gap
//! stops shrinking although the robot drives forward (the object moves with it). A sharp
//! corner slips between the front rays: their readings then come from the faces behind it
//! and never show a small gap, but the gap they show stops closing once the robot pushes.

use agp_world::Pose;

pub use agp_shared_types::STALL_SAMPLES;

/// Largest front gap (m) at which a gap that stops shrinking means contact. Beyond it the
/// response table flattens (120 -> 104 raw from 50 to 60 mm, noise about 5 raw): a free
/// approach no longer shows as a shrinking gap, and noise alone stopped approaches some
/// 50 mm short of the object (a fifth of the L's unseen pushes then moved it less than
/// 25 mm). The corner the rule exists for still shows within it: at 40 mm the triangle's
/// head-on pushes went unnoticed and turned it 50 deg, at 45 its largest turn at alpha 0 is
/// the paper's 39 deg again.
pub const STALL_MAX_GAP: f64 = 0.045;

/// Least forward travel (m) over [`STALL_SAMPLES`] samples for a still gap to count: half
/// of what an approach at 80 mm/s covers (6.25 mm). A robot that barely moves says nothing
/// about contact by its gap.
pub const STALL_MIN_TRAVEL: f64 = 0.003;

/// A free approach closes the gap by the distance driven; distance noise is about 1 mm
/// within [`STALL_MAX_GAP`]. A gap that closed by less than this share of it: pushing.
pub const STALL_SHARE: f64 = 0.25;

/// Watches the front gap at each new IR sample against the robot's forward travel.
#[derive(Debug, Clone)]
pub struct ApproachContact {
    /// The last samples, newest first: the front gap and the robot's pose.
    history: [(Option<f64>, Pose); STALL_SAMPLES + 1],
    seen: usize,
    last_sample: Option<u64>,
    stalled: bool,
}

impl Default for ApproachContact {
    fn default() -> Self {
        Self::new()
    }
}

impl ApproachContact {
    /// Nothing seen yet.
    pub fn new() -> Self {
        Self {
            history: [(None, Pose::default()); STALL_SAMPLES + 1],
            seen: 0,
            last_sample: None,
            stalled: false,
        }
    }

    /// One frame: its IR sample counter, the front gap it shows (m) and the robot's pose.
    /// A repeated sample changes nothing. Allocates nothing.
    pub fn observe(&mut self, ir_sample: u64, front_gap: Option<f64>, robot: Pose) {
        if self.last_sample == Some(ir_sample) {
            return;
        }
        self.last_sample = Some(ir_sample);
        self.history.rotate_right(1);
        self.history[0] = (front_gap, robot);
        self.seen = (self.seen + 1).min(STALL_SAMPLES + 1);
        self.stalled = self.judge();
    }

    fn judge(&self) -> bool {
        if self.seen <= STALL_SAMPLES {
            return false;
        }
        let ((Some(now), at), (Some(then), from)) = (self.history[0], self.history[STALL_SAMPLES])
        else {
            return false;
        };
        if now > STALL_MAX_GAP {
            return false;
        }
        let travel = (at.position() - from.position()).dot(glam::DVec2::from_angle(at.theta));
        travel >= STALL_MIN_TRAVEL && then - now < STALL_SHARE * travel
    }

    /// Whether, at the latest sample, the gap has stopped shrinking while the robot drove
    /// forward within [`STALL_MAX_GAP`]: the object moves with the robot.
    pub fn stalled(&self) -> bool {
        self.stalled
    }

    /// Forgets what was seen (a new world).
    pub fn reset(&mut self) {
        *self = Self::new();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Feeds samples of a robot driving along +x at `speed` (m/s, 64 Hz samples) with the
    /// gap given by `gap(k)`; returns whether it judged the gap stalled at the end.
    fn drive(samples: u64, speed: f64, gap: impl Fn(u64) -> Option<f64>) -> bool {
        let mut c = ApproachContact::new();
        for k in 0..samples {
            let x = speed * k as f64 / 64.0;
            c.observe(k, gap(k), Pose::new(x, 0.0, 0.0));
        }
        c.stalled()
    }

    #[test]
    fn a_gap_that_stands_still_close_by_while_the_robot_drives_is_contact() {
        assert!(drive(10, 0.08, |_| Some(0.02)));
    }

    #[test]
    fn a_gap_that_closes_as_fast_as_the_robot_drives_is_no_contact() {
        assert!(!drive(10, 0.08, |k| Some(0.04 - 0.08 * k as f64 / 64.0)));
    }

    #[test]
    fn a_still_gap_far_out_or_a_robot_standing_still_is_no_contact() {
        // Past 45 mm the response table is too flat to see the approach close the gap.
        assert!(!drive(10, 0.08, |_| Some(0.05)));
        assert!(!drive(10, 0.0, |_| Some(0.02)));
        // Too few samples to judge.
        assert!(!drive(5, 0.08, |_| Some(0.02)));
    }

    #[test]
    fn a_repeated_sample_changes_nothing() {
        let mut c = ApproachContact::new();
        for k in 0..10 {
            c.observe(k, Some(0.02), Pose::new(0.08 * k as f64 / 64.0, 0.0, 0.0));
        }
        assert!(c.stalled());
        c.observe(9, Some(0.0), Pose::new(1.0, 0.0, 0.0));
        assert!(c.stalled());
    }
}
