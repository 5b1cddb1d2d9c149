//! What the estimator told a planner over a task, and how it stood against ground truth at
//! the end: the `estimate` block of every judged task (the supervisor's judge, the
//! benchmarks' episodes).

use agp_shared_types::{ObjectEstimate, Pose2};
use glam::DVec2;

use crate::symmetric_angle_error;

/// The estimates of a task as a reader took them: how many were published, how many of
/// them held a valid pose, and the last one. Bounded: it keeps one estimate.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct EstimateLog {
    received: u64,
    /// Estimates of steps between two received ones that never arrived (a reader's
    /// buffer overflowed).
    missed: u64,
    valid: u64,
    last: Option<ObjectEstimate>,
}

/// The `estimate` block of a judged task.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct EstimateVerdict {
    /// Estimates published during the task (received plus those a reader missed).
    pub published: u64,
    /// Of those received, the share with a valid object pose (`null` with none received).
    pub valid_fraction: Option<f64>,
    /// The last published estimate's object pose against the object's final true pose:
    /// distance, mm, and orientation error modulo the object's true symmetry, deg (`null`
    /// when that estimate holds no valid pose).
    pub final_position_error_mm: Option<f64>,
    pub final_orientation_error_deg: Option<f64>,
}

impl EstimateLog {
    /// Takes the next estimate. One of a later step than the step after the last one's
    /// counts the steps between as missed (one estimate per frame); one of the same or an
    /// earlier step (a reset, a restarted physics) counts none.
    pub fn take(&mut self, e: &ObjectEstimate) {
        if let Some(last) = &self.last
            && e.step > last.step + 1
        {
            self.missed += e.step - last.step - 1;
        }
        self.received += 1;
        self.valid += u64::from(e.valid == 1);
        self.last = Some(*e);
    }

    /// Judges the log against the object's final true pose `truth`, orientation modulo the
    /// object's true symmetry of order `true_order` (0: a disc, whose orientation is not
    /// judged). The judge's call: only it reads the truth.
    pub fn judged(&self, truth: Pose2, true_order: u32) -> EstimateVerdict {
        let last = self.last.filter(|e| e.valid == 1);
        EstimateVerdict {
            published: self.received + self.missed,
            valid_fraction: (self.received > 0).then(|| self.valid as f64 / self.received as f64),
            final_position_error_mm: last
                .map(|e| DVec2::new(e.pose.x - truth.x, e.pose.y - truth.y).length() * 1e3),
            final_orientation_error_deg: last.map(|e| {
                symmetric_angle_error(e.pose.theta - truth.theta, true_order)
                    .abs()
                    .to_degrees()
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn estimate(step: u64, valid: bool, pose: Pose2) -> ObjectEstimate {
        ObjectEstimate {
            step,
            valid: u8::from(valid),
            pose,
            ..ObjectEstimate::default()
        }
    }

    #[test]
    fn the_verdict_counts_missed_steps_as_published_and_judges_the_last_estimate() {
        let mut log = EstimateLog::default();
        let p = Pose2::new(0.1, 0.2, 0.5);
        log.take(&estimate(10, false, Pose2::default()));
        log.take(&estimate(11, true, p));
        // Steps 12..=14 never arrived.
        log.take(&estimate(
            15,
            true,
            Pose2::new(0.103, 0.204, 0.5 + 3f64.to_radians()),
        ));
        let v = log.judged(p, 1);
        assert_eq!(v.published, 6);
        assert_eq!(v.valid_fraction, Some(2.0 / 3.0));
        // A 3-4-5 triangle: 5 mm.
        assert!((v.final_position_error_mm.unwrap() - 5.0).abs() < 1e-9);
        assert!((v.final_orientation_error_deg.unwrap() - 3.0).abs() < 1e-9);
    }

    #[test]
    fn a_reset_repeats_a_step_without_counting_a_miss() {
        let mut log = EstimateLog::default();
        for step in [0, 1, 2, 2, 3, 0, 1] {
            log.take(&estimate(step, true, Pose2::default()));
        }
        assert_eq!(log.judged(Pose2::default(), 1).published, 7);
    }

    #[test]
    fn the_orientation_of_a_square_is_judged_modulo_a_quarter_turn() {
        let mut log = EstimateLog::default();
        log.take(&estimate(1, true, Pose2::new(0.0, 0.0, 92f64.to_radians())));
        let v = log.judged(Pose2::default(), 4);
        assert!((v.final_orientation_error_deg.unwrap() - 2.0).abs() < 1e-9);
    }

    #[test]
    fn a_last_estimate_without_a_pose_gives_no_final_errors() {
        let mut log = EstimateLog::default();
        log.take(&estimate(1, true, Pose2::default()));
        log.take(&estimate(2, false, Pose2::default()));
        let v = log.judged(Pose2::new(1.0, 1.0, 1.0), 1);
        assert_eq!(v.final_position_error_mm, None);
        assert_eq!(v.final_orientation_error_deg, None);
        assert_eq!(v.valid_fraction, Some(0.5));
    }

    #[test]
    fn an_empty_log_has_no_valid_fraction() {
        let v = EstimateLog::default().judged(Pose2::default(), 1);
        assert_eq!((v.published, v.valid_fraction), (0, None));
    }
}
