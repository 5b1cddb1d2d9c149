/// How a push is carried out: approach until the IR says the object is about to be touched,
/// then push at constant wheel speed for a fixed time.
#[derive(Debug, Clone, Copy)]
pub struct PushSettings {
    /// Wheel speed while approaching, m/s.
    pub approach_speed: f64,
    /// Gap (m) at which the approach stops: "just before contact".
    pub stop_gap: f64,
    /// Wheel speed while pushing, m/s.
    pub push_speed: f64,
    /// Push duration, seconds of simulated time.
    pub push_duration: f64,
    /// Give up the approach after this long without seeing the object close, seconds.
    pub approach_timeout: f64,
    /// Also take a stalled front gap as contact (see [`PushRoutine`]). A face
    /// running alongside the robot's path also keeps the gap still: a planner whose push
    /// went nowhere can retry without it.
    pub stall_contact: bool,
}

impl Default for PushSettings {
    fn default() -> Self {
        Self {
            approach_speed: 0.08,
            stop_gap: 0.003,
            push_speed: 0.1,
            push_duration: 2.0,
            approach_timeout: 6.0,
            stall_contact: true,
        }
    }
}

/// Where a push stands.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PushPhase {
    Approach { since: f64 },
    Push { until: f64 },
    Done { contact: bool },
}

/// The push as a state machine, fed what the estimator perceives at each control step.
///
/// The estimator infers contact from the IR alone (the paper's ObjInContact), in two ways:
/// the front gap falls under `stop_gap`, or the gap stops shrinking although the robot
/// drives forward (`ObjectEstimate::stalled`, see `agp_perception::ApproachContact`): a
/// sharp corner met head-on slips between the front rays, whose readings then come from
/// the faces behind it and never show a small gap. The routine decides only to push.
#[derive(Debug, Clone)]
pub struct PushRoutine {
    settings: PushSettings,
    phase: PushPhase,
    /// Simulated time at which contact was inferred.
    pub contact_time: Option<f64>,
    /// The last IR sample seen, and how many new ones the approach has seen.
    last_sample: Option<u64>,
    samples: usize,
}

impl PushRoutine {
    pub fn new(settings: PushSettings, now: f64) -> Self {
        Self {
            settings,
            phase: PushPhase::Approach { since: now },
            contact_time: None,
            last_sample: None,
            samples: 0,
        }
    }

    pub fn phase(&self) -> PushPhase {
        self.phase
    }

    /// Wheel speeds (left, right) for this step, given what the estimator perceives at the
    /// frame: the front gap (m, `None`: nothing ahead) and whether that gap has stopped
    /// shrinking while the robot drove forward (`ObjectEstimate::stalled`), and the
    /// frame's time. Contact is the estimator's to see: the routine decides only to push
    /// once the gap is under `stop_gap`, or stalled when `stall_contact` allows it.
    pub fn step(
        &mut self,
        front_gap: Option<f64>,
        stalled: bool,
        now: f64,
        ir_sample: u64,
    ) -> (f64, f64) {
        match self.phase {
            PushPhase::Approach { since } => {
                if self.last_sample != Some(ir_sample) {
                    self.last_sample = Some(ir_sample);
                    self.samples += 1;
                }
                // The estimator judges a stall over the last five IR samples: only once
                // they all belong to this approach (not to the travel before it).
                let judged = self.samples > agp_shared_types::STALL_SAMPLES;
                let near = front_gap.is_some_and(|g| g <= self.settings.stop_gap)
                    || (self.settings.stall_contact && stalled && judged);
                if near {
                    self.contact_time = Some(now);
                    self.phase = PushPhase::Push {
                        until: now + self.settings.push_duration,
                    };
                    let v = self.settings.push_speed;
                    (v, v)
                } else if now - since > self.settings.approach_timeout {
                    self.phase = PushPhase::Done { contact: false };
                    (0.0, 0.0)
                } else {
                    let v = self.settings.approach_speed;
                    (v, v)
                }
            }
            PushPhase::Push { until } => {
                if now >= until {
                    self.phase = PushPhase::Done { contact: true };
                    (0.0, 0.0)
                } else {
                    let v = self.settings.push_speed;
                    (v, v)
                }
            }
            PushPhase::Done { .. } => (0.0, 0.0),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_gap_under_the_stop_gap_or_a_stall_starts_the_push_and_the_push_lasts_its_time() {
        let settings = PushSettings::default();
        let mut r = PushRoutine::new(settings, 0.0);
        assert_eq!(r.step(Some(0.02), false, 0.1, 0), (0.08, 0.08));
        assert!(matches!(r.phase(), PushPhase::Approach { .. }));
        assert_eq!(r.step(Some(0.002), false, 0.2, 1), (0.1, 0.1));
        assert!(matches!(r.phase(), PushPhase::Push { .. }));
        assert_eq!(r.contact_time, Some(0.2));
        r.step(None, false, 0.2 + settings.push_duration, 2);
        assert_eq!(r.phase(), PushPhase::Done { contact: true });

        let mut r = PushRoutine::new(settings, 0.0);
        // A stall is judged over the last five samples' gaps (six samples): one judged
        // over samples that came before the approach does not count.
        for k in 0..5 {
            r.step(Some(0.02), true, 0.01 * k as f64, k);
            assert!(
                matches!(r.phase(), PushPhase::Approach { .. }),
                "sample {k}"
            );
        }
        r.step(Some(0.02), true, 0.05, 5);
        assert!(matches!(r.phase(), PushPhase::Push { .. }));
    }

    #[test]
    fn without_stall_contact_a_stalled_gap_does_not_start_the_push() {
        let settings = PushSettings {
            stall_contact: false,
            ..PushSettings::default()
        };
        let mut r = PushRoutine::new(settings, 0.0);
        for k in 0..10 {
            r.step(Some(0.02), true, 0.01 * k as f64, k);
        }
        assert!(matches!(r.phase(), PushPhase::Approach { .. }));
        r.step(Some(0.02), true, settings.approach_timeout + 0.1, 10);
        assert_eq!(r.phase(), PushPhase::Done { contact: false });
    }
}
