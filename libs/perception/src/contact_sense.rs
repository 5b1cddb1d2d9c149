use agp_world::RobotDescription;

/// Infers from the four front IR readings how far the object is from the robot's body:
/// the E-puck has no contact sensor (the paper's ObjInContact).
///
/// A sensor sits inside the body: its ray travels a few millimetres before it leaves the
/// shell, so the gap between shell and object along a ray is the inverted reading minus that
/// inner length.
#[derive(Debug, Clone)]
pub struct ContactSense {
    robot: RobotDescription,
    front: [usize; 4],
    inner: [f64; 4],
}

impl ContactSense {
    /// The contact sense of `robot`: its front sensors and where each ray leaves its shell.
    pub fn new(robot: &RobotDescription) -> Self {
        let front = robot.front_sensors();
        let inner = front.map(|i| {
            let s = &robot.ir_sensors[i];
            let (m, d) = (s.mount, s.direction());
            let md = m.dot(d);
            -md + (md * md - m.length_squared() + robot.body_radius * robot.body_radius)
                .max(0.0)
                .sqrt()
        });
        Self {
            robot: robot.clone(),
            front,
            inner,
        }
    }

    /// Smallest gap (metres) between the body's shell and an object along a front ray, by
    /// inverting the calibrated response curve; `None` when no front sensor sees anything.
    pub fn front_gap(&self, ir_raw: &[f32; 8]) -> Option<f64> {
        self.front
            .iter()
            .zip(self.inner)
            .filter_map(|(&i, inner)| {
                self.robot
                    .response
                    .distance(ir_raw[i] as f64)
                    .map(|d| (d - inner).max(0.0))
            })
            .reduce(f64::min)
    }

    /// The robot's IR sampling rate, Hz.
    pub fn ir_rate_hz(&self) -> f64 {
        self.robot.ir_rate_hz
    }

    /// Length of each front ray inside the body, metres (IR1, IR2, IR7, IR8 order).
    pub fn inner_lengths(&self) -> [f64; 4] {
        self.inner
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_reading_at_the_shell_means_no_gap() {
        let robot = RobotDescription::epuck();
        let sense = ContactSense::new(&robot);
        for (k, &i) in robot.front_sensors().iter().enumerate() {
            let s = &robot.ir_sensors[i];
            let inner = sense.inner_lengths()[k];
            // The point `inner` along the ray lies on the shell.
            let p = s.mount + s.direction() * inner;
            assert!((p.length() - robot.body_radius).abs() < 1e-12);
            let mut raw = [0f32; 8];
            raw[i] = robot.response.reading(inner + 0.004) as f32;
            let gap = sense.front_gap(&raw).unwrap();
            // f32 rounding of the reading moves the inverted distance by far under 0.1 mm.
            assert!((gap - 0.004).abs() < 1e-4, "sensor {i}: gap {gap}");
        }
        assert_eq!(sense.front_gap(&[0.0; 8]), None);
    }
}
