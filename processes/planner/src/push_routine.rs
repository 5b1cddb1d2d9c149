use crate::ContactSense;

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
}

impl Default for PushSettings {
    fn default() -> Self {
        Self {
            approach_speed: 0.08,
            stop_gap: 0.003,
            push_speed: 0.1,
            push_duration: 2.0,
            approach_timeout: 6.0,
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

/// The push as a state machine, fed one IR frame per control step.
#[derive(Debug, Clone)]
pub struct PushRoutine {
    settings: PushSettings,
    phase: PushPhase,
    /// Simulated time at which contact was inferred.
    pub contact_time: Option<f64>,
}

impl PushRoutine {
    pub fn new(settings: PushSettings, now: f64) -> Self {
        Self {
            settings,
            phase: PushPhase::Approach { since: now },
            contact_time: None,
        }
    }

    pub fn phase(&self) -> PushPhase {
        self.phase
    }

    /// Wheel speeds (left, right) for this step, given the frame's time and IR readings.
    pub fn update(&mut self, sense: &ContactSense, now: f64, ir_raw: &[f32; 8]) -> (f64, f64) {
        match self.phase {
            PushPhase::Approach { since } => {
                let near = sense
                    .front_gap(ir_raw)
                    .is_some_and(|g| g <= self.settings.stop_gap);
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
