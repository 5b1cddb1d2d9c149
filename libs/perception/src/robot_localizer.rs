//! The robot's own pose as the robot knows it: wheel odometry, pulled towards each overhead
//! fix (robot-and-world.md). Nothing here sees the object.

use agp_shared_types::angle::wrap_angle;
use agp_world::Pose;
use glam::DVec2;

/// Odometry corrected by the overhead fixes: the pose is `offset ∘ odometry`, and each new
/// fix moves the offset so that the pose goes `gain` of the way to the fix.
///
/// Odometry drifts without bound; a fix is noisy (about 1 mm and 0.5 deg) but does not
/// drift. Blending each fix in part keeps the pose smooth (the routines steer by it) while
/// the drift stays bounded.
///
/// Only fixes taken after the localizer's first frame count: the fix that frame already
/// carries was taken at an unknown earlier moment, and after a physics reset it is the
/// robot's pose before the reset (a reset sets odometry to the robot's new pose but takes
/// no fix; the next comes a fix period, 1 s, later). Taken, it pulled the pose `gain` of
/// the way back to where the robot was: 30 % of the reset's jump, 18 mm for a 60 mm one,
/// still 0.7^n of that after n fixes, so that a circling right after a reset drew the
/// border up to 14 mm off and matched the object 6 mm off.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobotLocalizer {
    /// Rotation of the offset, rad.
    rotation: f64,
    /// Translation of the offset, m.
    translation: DVec2,
    /// The latest fix seen; `None` before the first frame.
    last_fix_seq: Option<u64>,
    gain: f64,
}

impl RobotLocalizer {
    /// A localizer that trusts odometry as it is until the first fix taken after its first
    /// frame; `gain` in (0, 1].
    #[track_caller]
    pub fn new(gain: f64) -> Self {
        assert!(
            gain > 0.0 && gain <= 1.0,
            "the fix gain must be in (0, 1], got {gain}"
        );
        Self {
            rotation: 0.0,
            translation: DVec2::ZERO,
            last_fix_seq: None,
            gain,
        }
    }

    /// The pose for this odometry, taking the fix in if it is new (`fix_seq` is not 0 and
    /// changed since the previous frame; the first frame's fix is not new, see the type's
    /// documentation).
    pub fn update(&mut self, odometry: Pose, fix: Pose, fix_seq: u64) -> Pose {
        let seen = self.last_fix_seq.replace(fix_seq);
        if fix_seq != 0 && seen.is_some_and(|s| s != fix_seq) {
            let now = self.apply(odometry);
            let k = self.gain;
            let target_theta = now.theta + k * wrap_angle(fix.theta - now.theta);
            let target_pos = now.position().lerp(fix.position(), k);
            self.rotation = wrap_angle(target_theta - odometry.theta);
            self.translation =
                target_pos - DVec2::from_angle(self.rotation).rotate(odometry.position());
        }
        self.apply(odometry)
    }

    /// The pose for this odometry with the present offset.
    pub fn apply(&self, odometry: Pose) -> Pose {
        let p = self.translation + DVec2::from_angle(self.rotation).rotate(odometry.position());
        Pose::new(p.x, p.y, wrap_angle(odometry.theta + self.rotation))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn without_a_fix_the_pose_is_odometry() {
        let mut l = RobotLocalizer::new(0.5);
        let o = Pose::new(0.1, -0.2, 0.3);
        assert_eq!(l.update(o, Pose::default(), 0), o);
    }

    #[test]
    fn a_fix_already_there_at_the_first_frame_is_not_taken_the_next_one_is() {
        // A physics reset put the robot at (0.3, 0.1) and its odometry there; the frame
        // still carries the fix of its pose before the reset (seq 7).
        let mut l = RobotLocalizer::new(0.3);
        let odometry = Pose::new(0.3, 0.1, 0.5);
        let stale = Pose::new(0.0, 0.0, -1.0);
        assert_eq!(l.update(odometry, stale, 7), odometry);
        assert_eq!(l.update(odometry, stale, 7), odometry);
        // The first fix taken after the reset (seq 8) counts.
        let fix = Pose::new(0.31, 0.1, 0.5);
        let p = l.update(odometry, fix, 8);
        assert!((p.x - 0.303).abs() < 1e-12, "{p:?}");
    }

    #[test]
    fn a_fix_with_full_gain_moves_the_pose_onto_it_and_odometry_moves_it_on_from_there() {
        let mut l = RobotLocalizer::new(1.0);
        let fix = Pose::new(1.0, 1.0, 1.0);
        // The first frame carries no fix yet.
        l.update(Pose::new(0.0, 0.0, 0.0), Pose::default(), 0);
        let p = l.update(Pose::new(0.0, 0.0, 0.0), fix, 1);
        assert!((p.position() - fix.position()).length() < 1e-12);
        assert!(wrap_angle(p.theta - fix.theta).abs() < 1e-12);
        // Odometry drives 0.1 m straight ahead: the pose drives 0.1 m along its heading.
        let q = l.update(Pose::new(0.1, 0.0, 0.0), fix, 1);
        let expected = fix.position() + 0.1 * DVec2::from_angle(1.0);
        assert!((q.position() - expected).length() < 1e-12, "{q:?}");
    }

    #[test]
    fn a_fix_with_half_gain_moves_the_pose_half_way() {
        let mut l = RobotLocalizer::new(0.5);
        l.update(Pose::new(0.0, 0.0, 0.0), Pose::default(), 2);
        let p = l.update(Pose::new(0.0, 0.0, 0.0), Pose::new(0.002, 0.0, 0.02), 3);
        assert!(
            (p.x - 0.001).abs() < 1e-12 && (p.theta - 0.01).abs() < 1e-12,
            "{p:?}"
        );
        // The same fix again changes nothing.
        assert_eq!(
            l.update(Pose::new(0.0, 0.0, 0.0), Pose::new(0.0, 0.0, 0.0), 3),
            p
        );
    }
}
