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
    /// Also infer contact when the front gap stops shrinking (see [`PushRoutine`]). A face
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

/// IR samples over which a stalled gap is judged (5 samples = 78 ms at 64 Hz).
const STALL_SAMPLES: usize = 5;

/// Largest front gap (m) at which a gap that stops shrinking means contact. Beyond it the
/// response table flattens (120 -> 104 raw from 50 to 60 mm, noise about 5 raw): a free
/// approach no longer shows as a shrinking gap, and noise alone stopped approaches some
/// 50 mm short of the object (a fifth of the L's unseen pushes then moved it less than
/// 25 mm). The corner the rule exists for still shows within it: at 40 mm the triangle's
/// head-on pushes went unnoticed and turned it 50 deg, at 45 its largest turn at alpha 0 is
/// the paper's 39 deg again.
const STALL_MAX_GAP: f64 = 0.045;

/// The push as a state machine, fed one IR frame per control step.
///
/// Contact is inferred from the IR alone (the paper's ObjInContact), in two ways: the front
/// gap falls under `stop_gap`, or the gap stops shrinking although the robot drives forward
/// (the object moves with it). The second catches a sharp corner met head-on, which slips
/// between the front rays: their readings then come from the faces behind the corner and
/// never show a small gap.
#[derive(Debug, Clone)]
pub struct PushRoutine {
    settings: PushSettings,
    phase: PushPhase,
    /// Simulated time at which contact was inferred.
    pub contact_time: Option<f64>,
    last_sample: u64,
    gaps: [Option<f64>; STALL_SAMPLES + 1],
    samples_seen: usize,
}

impl PushRoutine {
    pub fn new(settings: PushSettings, now: f64) -> Self {
        Self {
            settings,
            phase: PushPhase::Approach { since: now },
            contact_time: None,
            last_sample: u64::MAX,
            gaps: [None; STALL_SAMPLES + 1],
            samples_seen: 0,
        }
    }

    /// Whether the gap has stopped shrinking over the last samples while approaching.
    fn stalled(&self, sample_period: f64) -> bool {
        if self.samples_seen <= STALL_SAMPLES {
            return false;
        }
        let (Some(now), Some(then)) = (self.gaps[0], self.gaps[STALL_SAMPLES]) else {
            return false;
        };
        if now > STALL_MAX_GAP {
            return false;
        }
        let expected = self.settings.approach_speed * sample_period * STALL_SAMPLES as f64;
        // Within IR range a free approach closes the gap by `expected` (5 mm at 80 mm/s);
        // distance noise is about 1 mm at these ranges. Under a quarter of it: pushing.
        then - now < 0.25 * expected
    }

    pub fn phase(&self) -> PushPhase {
        self.phase
    }

    /// Wheel speeds (left, right) for this step, given the front gap the estimator perceives
    /// (m, `None`: nothing ahead), the IR sampling period (s), the frame's time and its IR
    /// sample counter.
    pub fn update(
        &mut self,
        front_gap: Option<f64>,
        ir_period_s: f64,
        now: f64,
        ir_sample: u64,
    ) -> (f64, f64) {
        match self.phase {
            PushPhase::Approach { since } => {
                let gap = front_gap;
                if ir_sample != self.last_sample {
                    self.last_sample = ir_sample;
                    self.gaps.rotate_right(1);
                    self.gaps[0] = gap;
                    self.samples_seen += 1;
                }
                let near = gap.is_some_and(|g| g <= self.settings.stop_gap)
                    || (self.settings.stall_contact && self.stalled(ir_period_s));
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
    use agp_world::RobotDescription;

    use super::*;

    /// Feeds `samples` IR frames at 64 Hz, every front ray reading a surface `gap` beyond
    /// the shell (the gap standing still, as when the robot pushes or the reading is stuck),
    /// and returns the phase reached.
    fn still_gap(gap: f64, samples: u64) -> PushPhase {
        let robot = RobotDescription::epuck();
        let sense = agp_perception::ContactSense::new(&robot);
        let mut raw = [0.0_f32; 8];
        for (&i, inner) in robot.front_sensors().iter().zip(sense.inner_lengths()) {
            raw[i] = robot.response.reading(gap + inner) as f32;
        }
        let period = 1.0 / sense.ir_rate_hz();
        let mut routine = PushRoutine::new(PushSettings::default(), 0.0);
        for k in 0..samples {
            routine.update(sense.front_gap(&raw), period, k as f64 * period, k);
        }
        routine.phase()
    }

    #[test]
    fn a_gap_that_stops_shrinking_close_by_is_contact() {
        assert!(matches!(still_gap(0.02, 10), PushPhase::Push { .. }));
    }

    #[test]
    fn a_gap_that_stands_still_far_out_is_not_contact() {
        // Past 45 mm the response table is too flat to see the approach close the gap.
        assert!(matches!(still_gap(0.05, 10), PushPhase::Approach { .. }));
    }
}
