use std::path::Path;

use glam::DVec2;
use serde::Deserialize;
use toml::Spanned;

/// The built-in robot description (the E-puck of ../shared/spec/robot-and-world.md).
const EPUCK_TOML: &str = include_str!("../data/epuck.toml");

/// One IR proximity sensor: where it sits on the body and where its ray points.
#[derive(Debug, Clone, PartialEq)]
pub struct IrSensor {
    pub name: String,
    /// Ray direction relative to the heading, radians (counter-clockwise).
    pub angle_rad: f64,
    /// Mount point in the robot frame (x forward, y left), metres.
    pub mount: DVec2,
}

impl IrSensor {
    /// Unit ray direction in the robot frame.
    pub fn direction(&self) -> DVec2 {
        DVec2::from_angle(self.angle_rad)
    }
}

/// The IR response curve: distance along the ray -> raw reading, with the standard
/// deviation of the reading's Gaussian noise as a fraction of the reading. Linear
/// interpolation between rows; 0 beyond the last row.
#[derive(Debug, Clone, PartialEq)]
pub struct ResponseCurve {
    /// (distance m, raw reading, noise fraction), distances strictly increasing, readings
    /// strictly decreasing.
    rows: Vec<(f64, f64, f64)>,
}

impl ResponseCurve {
    /// Builds a curve, checking that it can be inverted.
    pub fn new(rows: Vec<(f64, f64, f64)>) -> Result<Self, String> {
        if rows.len() < 2 {
            return Err("the response curve needs at least two rows".into());
        }
        for (i, w) in rows.windows(2).enumerate() {
            if w[1].0.partial_cmp(&w[0].0) != Some(std::cmp::Ordering::Greater) {
                return Err(format!("row {}: distances must increase", i + 2));
            }
            if w[1].1.partial_cmp(&w[0].1) != Some(std::cmp::Ordering::Less) {
                return Err(format!(
                    "row {}: readings must decrease with distance",
                    i + 2
                ));
            }
        }
        if rows
            .iter()
            .any(|r| !(r.0 >= 0.0 && r.1 > 0.0 && r.2 >= 0.0))
        {
            return Err("distances, readings and noise must be non-negative".into());
        }
        Ok(Self { rows })
    }

    pub fn rows(&self) -> &[(f64, f64, f64)] {
        &self.rows
    }

    /// Largest distance that gives a non-zero reading, metres.
    pub fn max_range(&self) -> f64 {
        self.rows[self.rows.len() - 1].0
    }

    /// Closest the curve knows (its largest reading).
    pub fn max_reading(&self) -> f64 {
        self.rows[0].1
    }

    fn segment(&self, d: f64) -> Option<(usize, f64)> {
        if d.is_nan() || d < self.rows[0].0 || d > self.max_range() {
            return None;
        }
        let i = self
            .rows
            .windows(2)
            .position(|w| d <= w[1].0)
            .unwrap_or(self.rows.len() - 2);
        let (d0, d1) = (self.rows[i].0, self.rows[i + 1].0);
        Some((i, (d - d0) / (d1 - d0)))
    }

    /// Noise-free reading at distance `d` (metres); 0 beyond range.
    pub fn reading(&self, d: f64) -> f64 {
        if d < self.rows[0].0 {
            return self.rows[0].1;
        }
        match self.segment(d) {
            Some((i, t)) => self.rows[i].1 + t * (self.rows[i + 1].1 - self.rows[i].1),
            None => 0.0,
        }
    }

    /// Standard deviation of the reading's noise at distance `d`, in raw units.
    pub fn noise_sigma(&self, d: f64) -> f64 {
        let frac = match self.segment(d.max(self.rows[0].0)) {
            Some((i, t)) => self.rows[i].2 + t * (self.rows[i + 1].2 - self.rows[i].2),
            None => 0.0,
        };
        frac * self.reading(d)
    }

    /// Distance (metres) that gives `raw`, by inverting the curve; `None` for a reading of
    /// 0 or below the last row (nothing in range). Readings above the largest are clamped
    /// to distance 0.
    pub fn distance(&self, raw: f64) -> Option<f64> {
        let last = self.rows[self.rows.len() - 1].1;
        if raw.is_nan() || raw < last {
            return None;
        }
        if raw >= self.rows[0].1 {
            return Some(self.rows[0].0);
        }
        let i = self.rows.windows(2).position(|w| raw >= w[1].1)?;
        let (d0, r0) = (self.rows[i].0, self.rows[i].1);
        let (d1, r1) = (self.rows[i + 1].0, self.rows[i + 1].1);
        Some(d0 + (raw - r0) / (r1 - r0) * (d1 - d0))
    }

    /// Standard deviation of the distance a reading at distance `d` implies: the reading's
    /// noise divided by the curve's slope there (metres).
    pub fn distance_sigma(&self, d: f64) -> f64 {
        match self.segment(d) {
            Some((i, _)) => {
                let slope =
                    (self.rows[i + 1].1 - self.rows[i].1) / (self.rows[i + 1].0 - self.rows[i].0);
                self.noise_sigma(d) / slope.abs()
            }
            None => f64::INFINITY,
        }
    }

    /// Largest distance at which a reading still places a border within `max_sigma` metres
    /// (one standard deviation): the usable range of the sensor for building shapes.
    pub fn usable_range(&self, max_sigma: f64) -> f64 {
        let mut best = 0.0;
        let steps = 700;
        for k in 0..=steps {
            let d = self.max_range() * k as f64 / steps as f64;
            if self.distance_sigma(d) <= max_sigma {
                best = d;
            } else {
                break;
            }
        }
        best
    }
}

/// Everything physics and estimator both need to know about the robot's body and sensors.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotDescription {
    pub name: String,
    pub body_radius: f64,
    pub wheel_radius: f64,
    pub axle_length: f64,
    pub mass: f64,
    pub max_wheel_speed: f64,
    pub ir_rate_hz: f64,
    pub ir_sensors: Vec<IrSensor>,
    pub response: ResponseCurve,
    /// Coulomb coefficient between the tyres and the floor (the finite-force drive's
    /// traction: at most `wheel_friction * mass * G` for the two wheels together).
    pub wheel_friction: f64,
    /// Largest torque a wheel's stepper delivers at the wheel before it loses steps
    /// (pull-out torque after the gearbox), N m. The finite-force drive's motor limit: at
    /// most `wheel_torque / wheel_radius` of pull per wheel.
    pub wheel_torque: f64,
    /// The finite-force drive's motor controller ramps each wheel's speed towards the
    /// command at most this fast, m/s^2 (as stepper drivers do, to keep from losing steps);
    /// odometry counts the ramped steps. The kinematic robot does not ramp.
    pub wheel_accel: f64,
}

/// Why a robot description could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum RobotLoadError {
    #[error("cannot read `{path}`: {source}")]
    Read {
        path: String,
        source: std::io::Error,
    },
    #[error("{path}:{line}: {message}")]
    Parse {
        path: String,
        line: usize,
        message: String,
    },
    #[error("{path}: {message}")]
    Invalid { path: String, message: String },
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RobotFile {
    name: String,
    body_radius_mm: f64,
    wheel_radius_mm: f64,
    axle_length_mm: f64,
    mass_kg: f64,
    max_wheel_speed_mm_s: f64,
    ir_rate_hz: f64,
    wheel_friction: Spanned<f64>,
    #[serde(rename = "wheel_torque_mNm")]
    wheel_torque_mnm: Spanned<f64>,
    wheel_accel_mm_s2: Spanned<f64>,
    ir_sensors: Vec<SensorFile>,
    response: ResponseFile,
}

/// Bounds of the finite-force drive's figures: a tyre's friction coefficient (rubber on a
/// floor is 0.5-1; 2 is beyond any plausible tyre) and a wheel's torque, mN m (the E-puck's
/// is an estimated 25; 1000 would lift a 20 mm wheel's robot off the floor many times).
pub const WHEEL_FRICTION_RANGE: (f64, f64) = (0.01, 2.0);
pub const WHEEL_TORQUE_MNM_RANGE: (f64, f64) = (0.01, 1000.0);
/// Bounds of the wheel's speed ramp, mm/s^2: from a crawl to far beyond any traction.
pub const WHEEL_ACCEL_MM_S2_RANGE: (f64, f64) = (1.0, 1.0e6);

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SensorFile {
    name: String,
    angle_deg: f64,
    mount_mm: [f64; 2],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ResponseFile {
    rows: Vec<[f64; 3]>,
}

impl RobotDescription {
    /// The E-puck, from the description built into the library.
    pub fn epuck() -> Self {
        Self::parse(EPUCK_TOML, "<built-in e-puck>")
            .expect("the built-in e-puck description is valid")
    }

    /// Loads a description from a TOML file of the same form as `data/epuck.toml`.
    pub fn load(path: &Path) -> Result<Self, RobotLoadError> {
        let text = std::fs::read_to_string(path).map_err(|source| RobotLoadError::Read {
            path: path.display().to_string(),
            source,
        })?;
        Self::parse(&text, &path.display().to_string())
    }

    /// Parses a description; `origin` names the source in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Self, RobotLoadError> {
        let file: RobotFile = toml::from_str(text).map_err(|e| RobotLoadError::Parse {
            path: origin.to_owned(),
            line: e.span().map(|s| crate::line_of(text, s.start)).unwrap_or(1),
            message: e.message().to_owned(),
        })?;
        let invalid = |message: String| RobotLoadError::Invalid {
            path: origin.to_owned(),
            message,
        };
        let positive = [
            ("body_radius_mm", file.body_radius_mm),
            ("wheel_radius_mm", file.wheel_radius_mm),
            ("axle_length_mm", file.axle_length_mm),
            ("mass_kg", file.mass_kg),
            ("max_wheel_speed_mm_s", file.max_wheel_speed_mm_s),
            ("ir_rate_hz", file.ir_rate_hz),
        ];
        for (key, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(invalid(format!(
                    "`{key}` must be a positive number, got {v}"
                )));
            }
        }
        if file.ir_sensors.len() != agp_ir_count() {
            return Err(invalid(format!(
                "expected {} IR sensors, found {}",
                agp_ir_count(),
                file.ir_sensors.len()
            )));
        }
        let at_line = |key: &str, v: &Spanned<f64>, (lo, hi): (f64, f64), unit: &str| {
            let x = *v.get_ref();
            if x.is_finite() && x >= lo && x <= hi {
                Ok(x)
            } else {
                Err(RobotLoadError::Parse {
                    path: origin.to_owned(),
                    line: crate::line_of(text, v.span().start),
                    message: format!("`{key}` must be a number from {lo} to {hi}{unit}, got {x}"),
                })
            }
        };
        let wheel_friction = at_line(
            "wheel_friction",
            &file.wheel_friction,
            WHEEL_FRICTION_RANGE,
            "",
        )?;
        let wheel_torque_mnm = at_line(
            "wheel_torque_mNm",
            &file.wheel_torque_mnm,
            WHEEL_TORQUE_MNM_RANGE,
            " mN m",
        )?;
        let wheel_accel_mm_s2 = at_line(
            "wheel_accel_mm_s2",
            &file.wheel_accel_mm_s2,
            WHEEL_ACCEL_MM_S2_RANGE,
            " mm/s^2",
        )?;
        let response = ResponseCurve::new(
            file.response
                .rows
                .iter()
                .map(|r| (r[0] * 1e-3, r[1], r[2]))
                .collect(),
        )
        .map_err(|m| invalid(format!("[response]: {m}")))?;
        Ok(Self {
            name: file.name,
            body_radius: file.body_radius_mm * 1e-3,
            wheel_radius: file.wheel_radius_mm * 1e-3,
            axle_length: file.axle_length_mm * 1e-3,
            mass: file.mass_kg,
            max_wheel_speed: file.max_wheel_speed_mm_s * 1e-3,
            ir_rate_hz: file.ir_rate_hz,
            ir_sensors: file
                .ir_sensors
                .into_iter()
                .map(|s| IrSensor {
                    name: s.name,
                    angle_rad: s.angle_deg.to_radians(),
                    mount: DVec2::new(s.mount_mm[0], s.mount_mm[1]) * 1e-3,
                })
                .collect(),
            response,
            wheel_friction,
            wheel_torque: wheel_torque_mnm * 1e-3,
            wheel_accel: wheel_accel_mm_s2 * 1e-3,
        })
    }

    /// Indices of the four front sensors (rays at ±17 and ±45 degrees), which the paper's
    /// Algorithm 1 uses.
    pub fn front_sensors(&self) -> [usize; 4] {
        [0, 1, 6, 7]
    }
}

const fn agp_ir_count() -> usize {
    8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_builtin_epuck_matches_the_spec() {
        let r = RobotDescription::epuck();
        assert_eq!(r.ir_sensors.len(), 8);
        assert!((r.body_radius - 0.037).abs() < 1e-12);
        assert!((r.ir_sensors[0].angle_rad - 17f64.to_radians()).abs() < 1e-12);
        assert!((r.ir_sensors[7].mount - DVec2::new(0.030, -0.010)).length() < 1e-12);
    }

    #[test]
    fn the_response_curve_interpolates_and_inverts() {
        let c = RobotDescription::epuck().response;
        // Table rows are hit exactly.
        assert!((c.reading(0.010) - 1465.73).abs() < 1e-9);
        // Halfway between 20 mm (383.84) and 30 mm (234.93).
        assert!((c.reading(0.025) - (383.84 + 234.93) / 2.0).abs() < 1e-9);
        assert_eq!(c.reading(0.0701), 0.0);
        for k in 0..=69 {
            let d = k as f64 * 1e-3;
            let back = c.distance(c.reading(d)).expect("in range");
            assert!((back - d).abs() < 1e-9, "{d} -> {back}");
        }
        assert_eq!(c.distance(0.0), None);
    }

    #[test]
    fn the_usable_range_is_where_the_distance_error_stays_small() {
        let c = RobotDescription::epuck().response;
        let range = c.usable_range(0.002);
        // 15..20 mm has 4 % noise on a steep slope: about 0.5 mm. Beyond 40 mm the slope
        // flattens and the error passes 2 mm.
        assert!(range > 0.015 && range < 0.07, "usable range {range}");
        assert!(c.distance_sigma(range * 0.5) <= 0.002);
    }

    #[test]
    fn a_bad_robot_file_names_the_line() {
        let text = EPUCK_TOML.replace("mass_kg = 0.16", "mass_kg = \"heavy\"");
        let e = RobotDescription::parse(&text, "robot.toml").unwrap_err();
        let msg = e.to_string();
        assert!(msg.starts_with("robot.toml:9:"), "{msg}");
    }

    #[test]
    fn the_builtin_epuck_carries_its_traction_and_motor_figures() {
        let r = RobotDescription::epuck();
        assert_eq!(r.wheel_friction, 0.8);
        assert!((r.wheel_torque - 0.025).abs() < 1e-15);
        // Traction binds before the motor: mu m g / 2 per wheel below torque / radius.
        assert!(r.wheel_friction * r.mass * 9.81 / 2.0 < r.wheel_torque / r.wheel_radius);
    }

    #[test]
    fn a_traction_figure_out_of_range_names_its_line() {
        for (from, to, key) in [
            (
                "wheel_friction = 0.8",
                "wheel_friction = -0.8",
                "`wheel_friction`",
            ),
            (
                "wheel_friction = 0.8",
                "wheel_friction = nan",
                "`wheel_friction`",
            ),
            (
                "wheel_torque_mNm = 25.0",
                "wheel_torque_mNm = 1e9",
                "`wheel_torque_mNm`",
            ),
        ] {
            let text = EPUCK_TOML.replace(from, to);
            let line = text
                .lines()
                .position(|l| l.starts_with(to))
                .expect("replaced")
                + 1;
            let msg = RobotDescription::parse(&text, "robot.toml")
                .unwrap_err()
                .to_string();
            assert!(
                msg.starts_with(&format!("robot.toml:{line}: {key} must be a number from")),
                "{msg}"
            );
        }
        let missing = EPUCK_TOML.replace("wheel_torque_mNm = 25.0", "");
        let msg = RobotDescription::parse(&missing, "robot.toml")
            .unwrap_err()
            .to_string();
        assert!(msg.contains("wheel_torque_mNm"), "{msg}");
    }
}
