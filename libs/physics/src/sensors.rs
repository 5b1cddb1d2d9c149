use agp_shared_types::angle::wrap_angle;
use agp_world::{Localization, Pose, ResponseCurve, Rng, RobotDescription, RobotSetup};
use glam::DVec2;

use crate::drive::drive_arc;

/// Number of IR proximity sensors on the robot.
pub const IR_COUNT: usize = 8;

/// Rng stream ids: each sense draws from its own stream of the seed, so one drawing more
/// never shifts the others.
const IR_STREAM: u64 = 1;
const ODOMETRY_STREAM: u64 = 2;
const FIX_STREAM: u64 = 3;

/// Slack when deciding whether a sample time has been reached, in units of the sample
/// period: absorbs the rounding of steps * rate / step_hz (exact multiples must count).
const SCHEDULE_SLACK: f64 = 1e-9;

/// What the robot senses, as of the last sample: the only view of the world a planner
/// may have (with the commands it sent).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorState {
    /// Raw IR readings, 0..=4095 (the response curve's range), IR1..IR8.
    pub ir_raw: [f32; IR_COUNT],
    /// Number of IR samples taken since the simulation was built (also counts the sample
    /// taken at construction and at every reset).
    pub ir_sample: u64,
    /// The robot's own pose estimate from its wheels, updated with every IR sample.
    pub odometry: Pose,
    /// The last overhead fix of the robot's pose (meaningless while `fix_seq` is 0).
    pub fix: Pose,
    /// Number of overhead fixes so far; 0 = none yet, or the scenario turns them off.
    pub fix_seq: u64,
}

/// The robot's senses: IR rays, wheel odometry and the overhead fix, with their noise
/// and their clocks.
#[derive(Debug, Clone)]
pub(crate) struct SensorModel {
    mounts: [DVec2; IR_COUNT],
    dirs: [DVec2; IR_COUNT],
    curve: ResponseCurve,
    max_range: f64,
    max_reading: f64,
    ir_noise_scale: f64,
    ir_rate_hz: f64,
    odometry_noise: f64,
    axle: f64,
    localization: Option<Localization>,
    ir_rng: Rng,
    odometry_rng: Rng,
    fix_rng: Rng,
    /// Wheel travels (left, right) since the last odometry update, metres.
    travel: (f64, f64),
    /// Step count at the last reset (or construction): the clocks of the senses start there.
    epoch_step: u64,
    ir_in_epoch: u64,
    fixes_in_epoch: u64,
    state: SensorState,
}

impl SensorModel {
    /// `robot` must hold exactly [`IR_COUNT`] sensors (checked by the caller).
    pub fn new(robot: &RobotDescription, setup: &RobotSetup, seed: u64) -> Self {
        let mut mounts = [DVec2::ZERO; IR_COUNT];
        let mut dirs = [DVec2::X; IR_COUNT];
        for (k, s) in robot.ir_sensors.iter().take(IR_COUNT).enumerate() {
            mounts[k] = s.mount;
            dirs[k] = s.direction();
        }
        Self {
            mounts,
            dirs,
            curve: robot.response.clone(),
            max_range: robot.response.max_range(),
            max_reading: robot.response.max_reading(),
            ir_noise_scale: setup.ir_noise_scale,
            ir_rate_hz: robot.ir_rate_hz,
            odometry_noise: setup.odometry_noise,
            axle: robot.axle_length,
            localization: setup.localization,
            ir_rng: Rng::stream(seed, IR_STREAM),
            odometry_rng: Rng::stream(seed, ODOMETRY_STREAM),
            fix_rng: Rng::stream(seed, FIX_STREAM),
            travel: (0.0, 0.0),
            epoch_step: 0,
            ir_in_epoch: 0,
            fixes_in_epoch: 0,
            state: SensorState {
                ir_raw: [0.0; IR_COUNT],
                ir_sample: 0,
                odometry: setup.start,
                fix: Pose::default(),
                fix_seq: 0,
            },
        }
    }

    pub fn state(&self) -> &SensorState {
        &self.state
    }

    pub fn max_range(&self) -> f64 {
        self.max_range
    }

    /// Restarts the noise streams from `seed`, as [`SensorModel::new`] seeds them.
    pub fn reseed(&mut self, seed: u64) {
        self.ir_rng = Rng::stream(seed, IR_STREAM);
        self.odometry_rng = Rng::stream(seed, ODOMETRY_STREAM);
        self.fix_rng = Rng::stream(seed, FIX_STREAM);
    }

    /// Starts a new epoch at `step`: odometry at `robot`, clocks restarted, and an IR
    /// sample taken at once. `cast(origin, dir)` gives the distance along a world ray to the
    /// object, if within `max_range`.
    pub fn restart(&mut self, step: u64, robot: Pose, cast: impl Fn(DVec2, DVec2) -> Option<f64>) {
        self.epoch_step = step;
        self.ir_in_epoch = 0;
        self.fixes_in_epoch = 0;
        self.travel = (0.0, 0.0);
        self.state.odometry = robot;
        self.sample_ir(robot, &cast);
    }

    /// Accounts for one physics step: wheel travel, and the samples that fall due at
    /// `step` (the step count after it) with step length `dt`.
    pub fn after_step(
        &mut self,
        step: u64,
        dt: f64,
        wheel_travel: (f64, f64),
        robot: Pose,
        cast: impl Fn(DVec2, DVec2) -> Option<f64>,
    ) {
        self.travel.0 += wheel_travel.0;
        self.travel.1 += wheel_travel.1;
        let elapsed = (step - self.epoch_step) as f64 * dt;
        let ir_due = (elapsed * self.ir_rate_hz + SCHEDULE_SLACK).floor() as u64;
        if ir_due > self.ir_in_epoch {
            self.ir_in_epoch = ir_due;
            self.update_odometry();
            self.sample_ir(robot, &cast);
        }
        if let Some(loc) = self.localization {
            let fix_due = (elapsed / loc.period_s + SCHEDULE_SLACK).floor() as u64;
            if fix_due > self.fixes_in_epoch {
                self.fixes_in_epoch = fix_due;
                let r = &mut self.fix_rng;
                self.state.fix = Pose::new(
                    robot.x + loc.noise_m * r.gaussian(),
                    robot.y + loc.noise_m * r.gaussian(),
                    wrap_angle(robot.theta + loc.noise_rad * r.gaussian()),
                );
                self.state.fix_seq += 1;
            }
        }
    }

    /// Each wheel's travel since the last update times (1 + e), e ~ N(0, noise^2),
    /// integrated as an arc.
    fn update_odometry(&mut self) {
        let el = self.odometry_noise * self.odometry_rng.gaussian();
        let er = self.odometry_noise * self.odometry_rng.gaussian();
        let (l, r) = self.travel;
        self.state.odometry = drive_arc(
            self.state.odometry,
            l * (1.0 + el),
            r * (1.0 + er),
            self.axle,
        );
        self.travel = (0.0, 0.0);
    }

    /// One reading per sensor: the response curve at the ray's distance to the object plus
    /// Gaussian noise of the table's sigma times the scenario's scale, clamped to the
    /// curve's range; 0 when nothing is in range. Every sensor draws one number per
    /// sample, in range or not, so the noise stream does not depend on the geometry.
    fn sample_ir(&mut self, robot: Pose, cast: &impl Fn(DVec2, DVec2) -> Option<f64>) {
        let rot = DVec2::from_angle(robot.theta);
        let pos = robot.position();
        for k in 0..IR_COUNT {
            let noise = self.ir_rng.gaussian();
            let origin = pos + rot.rotate(self.mounts[k]);
            let dir = rot.rotate(self.dirs[k]);
            self.state.ir_raw[k] = match cast(origin, dir) {
                Some(d) if d <= self.max_range => {
                    let sigma = self.curve.noise_sigma(d) * self.ir_noise_scale;
                    (self.curve.reading(d) + sigma * noise).clamp(0.0, self.max_reading) as f32
                }
                _ => 0.0,
            };
        }
        self.state.ir_sample += 1;
    }
}
