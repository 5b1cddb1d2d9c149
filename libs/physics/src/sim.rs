use agp_shared_types::angle::wrap_angle;
use agp_world::{ObjectShape, Pose, RobotDescription, RobotDrive, Scenario, WorldChange};
use glam::DVec2;
use rapier2d::math::{Pose as RPose, Vector as RVec};
use rapier2d::prelude::{
    CoefficientCombineRule, ColliderBuilder, ColliderHandle, MassProperties, PhysicsWorld, Ray,
    RigidBodyBuilder, RigidBodyHandle, SharedShape,
};

use crate::convex_pieces::convex_pieces;
use crate::drive::drive_arc;
use crate::finite_force::{FloorHold, WheelDrive};
use crate::floor_friction::{FloorFriction, FrictionOutcome};
use crate::sensors::{IR_COUNT, SensorModel, SensorState};

/// Scale of the world for rapier's tolerances (its `length_unit`): our objects are a few
/// centimetres across, so rapier's slop (0.005 units) becomes 0.05 mm and its default
/// speculative margin (0.02 units) 0.2 mm, instead of millimetres at the metre scale. It
/// also scales rapier's speed caps: penetrations are pushed out at up to 3 cm/s and bodies
/// move at up to 4 m/s, thirty times the robot's top speed.
const LENGTH_UNIT: f32 = 0.01;

/// Robot and object closer than this (m) count as touching: above the contact solver's
/// slop (0.05 mm) and its rounding, far below anything an IR reading could resolve.
pub const CONTACT_DISTANCE: f64 = 1e-4;

/// The robot-object contact as rapier's solver left it after the last step: ground truth
/// for tests and experiments (the robot has no contact sensor).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactImpulse {
    /// Unit normal from the robot's centre towards the object (world frame).
    pub normal: DVec2,
    /// Where the robot's body touches the object: its centre plus its radius along
    /// `normal` (world frame), m.
    pub point: DVec2,
    /// Impulse along the normal over the last step, N s, summed over the contact points
    /// (and over the object's convex pieces): the push.
    pub normal_impulse: f64,
    /// Friction impulse across the normal over the last step, N s: the sum of the contact
    /// points' magnitudes, so `tangent_impulse <= mu * normal_impulse` is Coulomb's cone.
    pub tangent_impulse: f64,
}

/// How the floor resists an object's motion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FloorModel {
    /// Coulomb friction distributed over the footprint (robot-and-world.md): the default.
    Coulomb {
        /// About how many cells the footprint is cut into.
        cells: usize,
    },
    /// Plain velocity damping, 1/s: cheaper, and wrong in the ways the spec names (objects
    /// coast and turn as no real object does). Never the default.
    Damping { linear: f64, angular: f64 },
}

impl Default for FloorModel {
    fn default() -> Self {
        Self::Coulomb { cells: 64 }
    }
}

/// How to run the simulation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimConfig {
    /// Physics steps per second of simulated time (default 640: ten steps per IR sample).
    pub step_hz: f64,
    /// Seed of the IR, odometry and overhead-fix noise.
    pub seed: u64,
    pub floor: FloorModel,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            step_hz: 640.0,
            seed: 7,
            floor: FloorModel::default(),
        }
    }
}

/// Why a simulation could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimBuildError {
    /// The step rate is not finite, or slower than the IR sampling.
    #[error(
        "the step rate must be finite and at least the IR rate of {ir_rate_hz} Hz, got {step_hz} Hz"
    )]
    StepRate { step_hz: f64, ir_rate_hz: f64 },
    /// `FloorModel::Coulomb` with no cells, or absurdly many.
    #[error("the floor needs between 1 and 10000 footprint cells, got {0}")]
    FootprintCells(usize),
    /// `FloorModel::Damping` with a negative or non-finite rate.
    #[error(
        "floor damping must be finite and non-negative, got linear {linear}, angular {angular}"
    )]
    Damping { linear: f64, angular: f64 },
    /// The robot description does not hold the 8 IR sensors the sensor state carries.
    #[error("the robot has {0} IR sensors; the simulator reads exactly 8")]
    SensorCount(usize),
    /// A size, speed or rate of the robot description is not a positive number.
    #[error("robot description: `{0}` must be a positive finite number")]
    Robot(&'static str),
    /// The polygon's triangulation does not cover its area (should not happen for a
    /// polygon `agp_world::Polygon::new` accepted).
    #[error("the object's polygon cannot be split into convex pieces")]
    Decomposition,
    /// A convex piece too thin for rapier to build a collider from.
    #[error("the object's convex piece {0} is degenerate")]
    DegeneratePiece(usize),
}

/// The world of one scenario: the E-puck, one object and the floor, stepped at a fixed
/// rate with rapier2d (zero gravity: seen from above, the floor acts through friction).
///
/// # The robot's body
/// The scenario's `[robot] drive` chooses it. `"finite-force"` makes it a dynamic body
/// pulled by two stepper wheels of bounded force (see [`crate::finite_force`]'s model:
/// it stalls against a heavy object and its wheels slip). The default, `"kinematic"`, is
/// described here.
///
/// The kinematic robot is a position-based kinematic rapier body: each step its pose follows the
/// exact differential-drive arc of the (clamped) wheel speeds, kept in f64 by the
/// simulator, and rapier derives the body's velocity from it for the contact solver. This
/// is the stepper-motor E-puck: velocity-controlled wheels that reach their commanded
/// speed, never slip sideways, and are far stronger than a 0.1 kg object's floor friction
/// (0.4 N), so the object cannot slow the robot down. The robot's mass therefore plays no
/// part; there are no walls to push it against.
///
/// # The floor
/// Before each rapier step the floor friction's velocity change for that step is applied
/// to the object (see [`FloorFriction::apply`]); rapier's solver then resolves the robot's
/// contact on top of it in the same step, so a pushed object settles where the contact
/// wrench balances the floor's, as the quasi-static pushing model has it.
pub struct Sim {
    scenario: Scenario,
    robot: RobotDescription,
    config: SimConfig,
    world: PhysicsWorld,
    robot_body: RigidBodyHandle,
    object_body: RigidBodyHandle,
    /// Convex pieces of the object, one collider each.
    object_pieces: usize,
    /// The object's whole shape (a compound of the pieces when it is not convex), for the
    /// IR rays and the contact test.
    object_shape: SharedShape,
    object_inertia: f64,
    floor: Option<FloorFriction>,
    dt: f64,
    step_count: u64,
    robot_pose: Pose,
    wheels: (f64, f64),
    sensors: SensorModel,
    /// The finite-force drive's wheels; `None` for the kinematic robot.
    wheel_drive: Option<WheelDrive>,
    /// The finite-force drive's static floor friction on the object at rest (with the
    /// Coulomb floor only).
    floor_hold: Option<FloorHold>,
    /// The robot's collider, for its contact with the object.
    robot_collider: ColliderHandle,
    /// The object's first collider, which carries its whole mass and inertia.
    object_mass_collider: Option<ColliderHandle>,
    /// Moment of inertia per unit mass about the centroid, m^2.
    inertia_per_mass: f64,
    /// The scenario's `[[world_change]]`s not applied yet start at this index.
    next_change: usize,
}

fn rpose(p: Pose) -> RPose {
    RPose::new(RVec::new(p.x as f32, p.y as f32), p.theta as f32)
}

/// Refuses a step rate, robot description or floor model the simulator cannot run; returns
/// the object's linear and angular velocity damping (1/s), zero but for the damping floor.
fn check_config(
    scenario: &Scenario,
    robot: &RobotDescription,
    config: SimConfig,
) -> Result<(f64, f64), SimBuildError> {
    if !(config.step_hz.is_finite() && config.step_hz >= robot.ir_rate_hz) {
        return Err(SimBuildError::StepRate {
            step_hz: config.step_hz,
            ir_rate_hz: robot.ir_rate_hz,
        });
    }
    for (name, v) in [
        ("body_radius", robot.body_radius),
        ("axle_length", robot.axle_length),
        ("max_wheel_speed", robot.max_wheel_speed),
        ("ir_rate_hz", robot.ir_rate_hz),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(SimBuildError::Robot(name));
        }
    }
    if scenario.robot.drive == RobotDrive::FiniteForce {
        for (name, v) in [
            ("mass", robot.mass),
            ("wheel_radius", robot.wheel_radius),
            ("wheel_friction", robot.wheel_friction),
            ("wheel_torque", robot.wheel_torque),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(SimBuildError::Robot(name));
            }
        }
    }
    if robot.ir_sensors.len() != IR_COUNT {
        return Err(SimBuildError::SensorCount(robot.ir_sensors.len()));
    }
    match config.floor {
        FloorModel::Coulomb { cells } if !(1..=10_000).contains(&cells) => {
            Err(SimBuildError::FootprintCells(cells))
        }
        FloorModel::Coulomb { .. } => Ok((0.0, 0.0)),
        FloorModel::Damping { linear, angular } => {
            if !(linear.is_finite() && linear >= 0.0 && angular.is_finite() && angular >= 0.0) {
                return Err(SimBuildError::Damping { linear, angular });
            }
            Ok((linear, angular))
        }
    }
}

/// A rapier world without gravity, stepping `dt`, with its tolerances at our scale and a
/// speculative margin that covers a step of the robot at full speed.
fn empty_world(robot: &RobotDescription, dt: f64) -> PhysicsWorld {
    let mut world = PhysicsWorld::new();
    world.gravity = RVec::ZERO;
    let params = &mut world.integration_parameters;
    params.dt = dt as f32;
    params.length_unit = LENGTH_UNIT;
    // The speculative margin must cover a step of the robot at full speed, or contacts
    // would be found only after the robot has sunk into the object.
    let travel = (2.0 * robot.max_wheel_speed * dt) as f32 / LENGTH_UNIT;
    params.normalized_prediction_distance = params.normalized_prediction_distance.max(travel);
    // Recycled contacts may be stale by the recycle distance: keep every step exact.
    params.contact_recycling = false;
    world
}

/// Puts the robot's body (dynamic for the finite-force drive, else kinematic) and its round
/// collider at the scenario's start pose; returns their handles.
fn insert_robot(
    world: &mut PhysicsWorld,
    scenario: &Scenario,
    robot: &RobotDescription,
    finite_force: bool,
) -> (RigidBodyHandle, ColliderHandle) {
    let body = world.insert_body(if finite_force {
        RigidBodyBuilder::dynamic()
            .pose(rpose(scenario.robot.start))
            .can_sleep(false)
    } else {
        RigidBodyBuilder::kinematic_position_based().pose(rpose(scenario.robot.start))
    });
    let collider = world.insert_collider(
        ColliderBuilder::ball(robot.body_radius as f32)
            .mass(robot.mass as f32)
            .friction(scenario.object.contact_friction as f32)
            .friction_combine_rule(CoefficientCombineRule::Min)
            .restitution(0.0),
        Some(body),
    );
    (body, collider)
}

/// The object as [`insert_object`] put it into the world.
struct ObjectParts {
    body: RigidBodyHandle,
    /// The first piece's collider, which carries the whole mass and inertia.
    mass_collider: Option<ColliderHandle>,
    /// How many convex pieces (colliders) the object has.
    pieces: usize,
    /// The whole shape: the one piece, or a compound of them.
    shape: SharedShape,
    /// Moment of inertia about the centroid, kg m^2.
    inertia: f64,
    /// Moment of inertia per unit mass about the centroid, m^2.
    inertia_per_mass: f64,
}

/// Puts the object's dynamic body at its start pose, with the given velocity damping, and
/// one collider per convex piece of its shape.
fn insert_object(
    world: &mut PhysicsWorld,
    scenario: &Scenario,
    (linear_damping, angular_damping): (f64, f64),
) -> Result<ObjectParts, SimBuildError> {
    let obj = &scenario.object;
    let (pieces, inertia_per_mass) = object_pieces(&obj.shape)?;
    let inertia = obj.mass * inertia_per_mass;
    let body = world.insert_body(
        RigidBodyBuilder::dynamic()
            .pose(rpose(obj.start))
            .can_sleep(false)
            .linear_damping(linear_damping as f32)
            .angular_damping(angular_damping as f32),
    );
    // One collider per convex piece, all on the object's body, rather than one compound
    // collider: rapier's contacts with a compound shape (parry's composite manifolds)
    // allocate on every step, convex pieces do not. The first piece carries the whole
    // plate's mass and inertia about the centroid, the others none.
    let mut mass_collider = None;
    for (k, piece) in pieces.iter().enumerate() {
        let mass = if k == 0 {
            MassProperties::new(RVec::ZERO, obj.mass as f32, inertia as f32)
        } else {
            MassProperties::new(RVec::ZERO, 0.0, 0.0)
        };
        let handle = world.insert_collider(
            ColliderBuilder::new(piece.clone())
                .mass_properties(mass)
                .friction(obj.contact_friction as f32)
                .friction_combine_rule(CoefficientCombineRule::Min)
                .restitution(0.0),
            Some(body),
        );
        mass_collider.get_or_insert(handle);
    }
    let count = pieces.len();
    let shape = if count == 1 {
        pieces.into_iter().next().expect("one piece")
    } else {
        SharedShape::compound(pieces.into_iter().map(|p| (RPose::IDENTITY, p)).collect())
    };
    Ok(ObjectParts {
        body,
        mass_collider,
        pieces: count,
        shape,
        inertia,
        inertia_per_mass,
    })
}

impl Sim {
    /// Builds the world of `scenario` with `robot` at their start poses, and takes the
    /// first sensor sample.
    pub fn new(
        scenario: &Scenario,
        robot: &RobotDescription,
        config: SimConfig,
    ) -> Result<Sim, SimBuildError> {
        let (linear_damping, angular_damping) = check_config(scenario, robot, config)?;
        let dt = 1.0 / config.step_hz;
        let obj = &scenario.object;
        let mut world = empty_world(robot, dt);
        let finite_force = scenario.robot.drive == RobotDrive::FiniteForce;
        let (robot_body, robot_collider) = insert_robot(&mut world, scenario, robot, finite_force);
        let object = insert_object(&mut world, scenario, (linear_damping, angular_damping))?;
        let floor = match config.floor {
            FloorModel::Coulomb { cells } => Some(FloorFriction::new(
                &obj.shape,
                obj.mass,
                obj.floor_friction,
                cells,
            )),
            FloorModel::Damping { .. } => None,
        };

        let (wheel_drive, floor_hold) = if finite_force {
            let drive = WheelDrive::new(&mut world, robot_body, robot, scenario.robot.start);
            let hold = floor.as_ref().map(|f| {
                FloorHold::new(
                    &mut world,
                    object.body,
                    obj.start,
                    f.max_force(),
                    f.max_torque(),
                )
            });
            (Some(drive), hold)
        } else {
            (None, None)
        };

        let mut sim = Sim {
            scenario: scenario.clone(),
            robot: robot.clone(),
            config,
            world,
            robot_body,
            object_body: object.body,
            object_pieces: object.pieces,
            object_shape: object.shape,
            object_inertia: object.inertia,
            floor,
            dt,
            step_count: 0,
            robot_pose: scenario.robot.start,
            wheels: (0.0, 0.0),
            sensors: SensorModel::new(robot, &scenario.robot, config.seed),
            wheel_drive,
            floor_hold,
            robot_collider,
            object_mass_collider: object.mass_collider,
            inertia_per_mass: object.inertia_per_mass,
            next_change: 0,
        };
        let (robot_pose, object_pose) = (sim.robot_pose, sim.object_pose());
        let (shape, range) = (&sim.object_shape, sim.sensors.max_range());
        sim.sensors.restart(0, robot_pose, |o, d| {
            cast_object(shape, object_pose, o, d, range)
        });
        Ok(sim)
    }

    /// One physics step of 1/step_hz with the given wheel speeds (m/s), each clamped to the
    /// robot's maximum (a non-finite speed counts as 0). Allocates nothing unless a contact
    /// begins or ends (rapier then allocates for the pair; see vendor/rapier2d/PATCHES.md).
    pub fn step(&mut self, left_mps: f64, right_mps: f64) {
        self.apply_due_changes();
        let travel = self.before_rapier(left_mps, right_mps);
        self.world.step();
        self.after_rapier(travel);
    }

    /// Drives the robot and applies the floor friction; returns the wheel travels.
    fn before_rapier(&mut self, left_mps: f64, right_mps: f64) -> (f64, f64) {
        let max = self.robot.max_wheel_speed;
        let clamp = |v: f64| {
            if v.is_finite() {
                v.clamp(-max, max)
            } else {
                0.0
            }
        };
        let (mut l, mut r) = (clamp(left_mps), clamp(right_mps));
        if self.wheel_drive.is_some() {
            // The finite-force robot's motor controller ramps each wheel towards the
            // command (`wheel_accel` of the robot file); odometry counts the ramped steps.
            let dv = self.robot.wheel_accel * self.dt;
            l = self.wheels.0 + (l - self.wheels.0).clamp(-dv, dv);
            r = self.wheels.1 + (r - self.wheels.1).clamp(-dv, dv);
        }
        self.wheels = (l, r);
        // Odometry counts these commanded travels, whatever the body does.
        let travel = (l * self.dt, r * self.dt);
        if let Some(drive) = &self.wheel_drive {
            let omega = self
                .world
                .bodies
                .get(self.robot_body)
                .map_or(0.0, |b| b.angvel() as f64);
            drive.command(&mut self.world, self.robot_pose, omega, self.dt, (l, r));
        } else {
            self.robot_pose =
                drive_arc(self.robot_pose, travel.0, travel.1, self.robot.axle_length);
            let next = rpose(self.robot_pose);
            if let Some(body) = self.world.bodies.get_mut(self.robot_body) {
                body.set_next_kinematic_position(next);
            }
        }
        if let Some(floor) = &self.floor
            && let Some(body) = self.world.bodies.get_mut(self.object_body)
        {
            let lv = body.linvel();
            let mut v = DVec2::new(lv.x as f64, lv.y as f64);
            let mut w = body.angvel() as f64;
            let theta = body.rotation().angle() as f64;
            let outcome = floor.apply(
                &mut v,
                &mut w,
                theta,
                self.scenario.object.mass,
                self.object_inertia,
                self.dt,
            );
            body.set_linvel(RVec::new(v.x as f32, v.y as f32), false);
            body.set_angvel(w as f32, false);
            if let Some(hold) = &self.floor_hold {
                let p = body.position();
                let object = Pose::new(p.translation.x as f64, p.translation.y as f64, theta);
                let at_rest = matches!(outcome, FrictionOutcome::AtRest | FrictionOutcome::Stopped);
                hold.command(&mut self.world, object, self.robot_pose.theta, at_rest);
            }
        }
        travel
    }

    /// Applies the scenario's world changes whose time has come (at the first step at or
    /// after their `at_s`). Allocates nothing while none is due.
    fn apply_due_changes(&mut self) {
        while let Some(&change) = self.scenario.world_changes.get(self.next_change) {
            if self.sim_time() + 0.5 * self.dt < change.at_s {
                break;
            }
            self.next_change += 1;
            self.apply_world_change(change);
        }
    }

    /// Changes the world now, whatever the change's `at_s`: the floor's friction under the
    /// object and/or the object's mass (its inertia with it, and the floor's load).
    /// [`Sim::step`] applies the scenario's `[[world_change]]`s by itself; this is for a
    /// harness that changes the world by hand. [`Sim::scenario`] reflects the change.
    pub fn apply_world_change(&mut self, change: WorldChange) {
        let object = &mut self.scenario.object;
        if let Some(mu) = change.floor_friction {
            object.floor_friction = mu;
        }
        if let Some(mass) = change.mass_kg {
            object.mass = mass;
            self.object_inertia = mass * self.inertia_per_mass;
            if let Some(c) = self
                .object_mass_collider
                .and_then(|h| self.world.colliders.get_mut(h))
            {
                c.set_mass_properties(MassProperties::new(
                    RVec::ZERO,
                    mass as f32,
                    self.object_inertia as f32,
                ));
            }
        }
        let (mass, mu) = (object.mass, object.floor_friction);
        if let Some(floor) = &mut self.floor {
            floor.set_mass_and_mu(mass, mu);
            if let Some(hold) = &self.floor_hold {
                hold.set_bounds(&mut self.world, floor.max_force(), floor.max_torque());
            }
        }
    }

    /// How many of the scenario's `[[world_change]]`s were applied so far.
    pub fn world_changes_applied(&self) -> usize {
        self.next_change
    }

    /// Counts the step and takes the samples that fall due.
    fn after_rapier(&mut self, travel: (f64, f64)) {
        self.step_count += 1;
        if let Some(drive) = &mut self.wheel_drive
            && let Some(b) = self.world.bodies.get(self.robot_body)
        {
            let p = b.position();
            let before = self.robot_pose;
            self.robot_pose = Pose::new(
                p.translation.x as f64,
                p.translation.y as f64,
                p.rotation.angle() as f64,
            );
            drive.account(before, self.robot_pose, travel);
        }
        let (robot_pose, object_pose) = (self.robot_pose, self.object_pose());
        let (shape, range) = (&self.object_shape, self.sensors.max_range());
        self.sensors
            .after_step(self.step_count, self.dt, travel, robot_pose, |o, d| {
                cast_object(shape, object_pose, o, d, range)
            });
    }

    /// Steps taken since construction (resets do not rewind it).
    pub fn step_count(&self) -> u64 {
        self.step_count
    }

    /// Simulated time since construction, s.
    pub fn sim_time(&self) -> f64 {
        self.step_count as f64 * self.dt
    }

    /// Length of one step, s.
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// True pose of the robot, world frame.
    pub fn robot_pose(&self) -> Pose {
        self.robot_pose
    }

    /// True pose of the object, world frame: its centroid and orientation in (-pi, pi].
    pub fn object_pose(&self) -> Pose {
        match self.world.bodies.get(self.object_body) {
            Some(b) => {
                let p = b.position();
                Pose::new(
                    p.translation.x as f64,
                    p.translation.y as f64,
                    p.rotation.angle() as f64,
                )
            }
            None => self.scenario.object.start,
        }
    }

    /// Velocity of the object's centroid (world frame, m/s) and its angular velocity (rad/s).
    pub fn object_velocity(&self) -> (DVec2, f64) {
        match self.world.bodies.get(self.object_body) {
            Some(b) => {
                let v = b.linvel();
                (DVec2::new(v.x as f64, v.y as f64), b.angvel() as f64)
            }
            None => (DVec2::ZERO, 0.0),
        }
    }

    /// The robot-object contact of the last step, if the solver held one (see
    /// [`ContactImpulse`]). Walks rapier's contact pairs: for tests and experiments, not
    /// for a hot loop.
    pub fn contact_impulse(&self) -> Option<ContactImpulse> {
        let mut out: Option<ContactImpulse> = None;
        for pair in self
            .world
            .narrow_phase
            .contact_pairs_with(self.robot_collider)
        {
            if !pair.has_any_active_contact() {
                continue;
            }
            let flip = if pair.collider1 == self.robot_collider {
                1.0
            } else {
                -1.0
            };
            for m in pair.manifolds() {
                let (n, t) = m.points.iter().fold((0.0, 0.0), |(n, t), p| {
                    (
                        n + p.data.impulse as f64,
                        t + (p.data.tangent_impulse.x as f64).abs(),
                    )
                });
                if n <= 0.0 {
                    continue;
                }
                let normal = DVec2::new(m.data.normal.x as f64, m.data.normal.y as f64) * flip;
                let c = out.get_or_insert(ContactImpulse {
                    normal,
                    point: self.robot_pose.position() + normal * self.robot.body_radius,
                    normal_impulse: 0.0,
                    tangent_impulse: 0.0,
                });
                c.normal_impulse += n;
                c.tangent_impulse += t;
            }
        }
        out
    }

    /// Sets the object's velocity (world frame, m/s and rad/s), as a kick would: for
    /// experiments and tests of the floor friction.
    pub fn set_object_velocity(&mut self, v: DVec2, omega: f64) {
        if let Some(b) = self.world.bodies.get_mut(self.object_body) {
            b.set_linvel(RVec::new(v.x as f32, v.y as f32), true);
            b.set_angvel(omega as f32, true);
        }
    }

    /// Whether the robot's body touches the object (closer than [`CONTACT_DISTANCE`]), in
    /// the current poses. Ground truth: the robot itself has no contact sensor.
    pub fn in_contact(&self) -> bool {
        let o = self.object_pose();
        let local = o.to_local(self.robot_pose.position());
        let d = self
            .object_shape
            .distance_to_local_point(RVec::new(local.x as f32, local.y as f32), true)
            as f64;
        d - self.robot.body_radius <= CONTACT_DISTANCE
    }

    /// The last sensor sample (held between samples).
    pub fn sensors(&self) -> &SensorState {
        self.sensors.state()
    }

    /// The wheel speeds commanded at the last step, after clamping (and, for the
    /// finite-force robot, the motor controller's ramp) (m/s): what the steppers turn at
    /// and odometry counts. The finite-force robot's body may move slower
    /// (see [`Sim::wheel_slip`]).
    pub fn wheel_speeds(&self) -> (f64, f64) {
        self.wheels
    }

    /// How physics moves the robot (the scenario's `[robot] drive`).
    pub fn drive(&self) -> RobotDrive {
        if self.wheel_drive.is_some() {
            RobotDrive::FiniteForce
        } else {
            RobotDrive::Kinematic
        }
    }

    /// Slip of the (left, right) wheel since the last reset (or construction), m: the
    /// commanded travel, which odometry counts, minus the travel of the wheel's floor
    /// contact point along the robot's heading. Positive when the wheel spun forwards
    /// faster than the robot moved. Always (0, 0) for the kinematic robot.
    pub fn wheel_slip(&self) -> (f64, f64) {
        self.wheel_drive
            .as_ref()
            .map(WheelDrive::slip)
            .unwrap_or((0.0, 0.0))
    }

    /// The finite-force drive's force limits per wheel, N: (pull along the rolling
    /// direction, grip across it); `None` for the kinematic robot.
    pub fn wheel_force_limits(&self) -> Option<(f64, f64)> {
        self.wheel_drive.as_ref().map(WheelDrive::limits)
    }

    /// Velocity of the robot's centre (world frame, m/s) and its angular velocity (rad/s).
    pub fn robot_velocity(&self) -> (DVec2, f64) {
        match self.world.bodies.get(self.robot_body) {
            Some(b) => {
                let v = b.linvel();
                (DVec2::new(v.x as f64, v.y as f64), b.angvel() as f64)
            }
            None => (DVec2::ZERO, 0.0),
        }
    }

    /// Puts the object and the robot at the given poses at rest, sets the odometry to the
    /// robot's pose and takes an IR sample at once; the sensor clocks restart from here.
    /// The step count and simulated time go on.
    /// Restarts the sensors' noise streams from `seed`, as a world built with
    /// `SimConfig::seed = seed` draws them; with [`Sim::reset`] after it, the world's noise
    /// from then on is that of a fresh world of that seed.
    pub fn reseed(&mut self, seed: u64) {
        self.sensors.reseed(seed);
    }

    pub fn reset(&mut self, object: Pose, robot: Pose) {
        let robot = Pose::new(robot.x, robot.y, wrap_angle(robot.theta));
        self.robot_pose = robot;
        self.wheels = (0.0, 0.0);
        if let Some(b) = self.world.bodies.get_mut(self.robot_body) {
            b.set_position(rpose(robot), true);
            if self.wheel_drive.is_some() {
                b.set_linvel(RVec::ZERO, true);
                b.set_angvel(0.0, true);
            }
        }
        if let Some(drive) = &mut self.wheel_drive {
            drive.reset();
        }
        if let Some(b) = self.world.bodies.get_mut(self.object_body) {
            b.set_position(rpose(object), true);
            b.set_linvel(RVec::ZERO, true);
            b.set_angvel(0.0, true);
            b.reset_forces(true);
            b.reset_torques(true);
        }
        let object_pose = self.object_pose();
        let (shape, range) = (&self.object_shape, self.sensors.max_range());
        self.sensors.restart(self.step_count, robot, |o, d| {
            cast_object(shape, object_pose, o, d, range)
        });
    }

    /// The robot description the world was built with.
    pub fn robot(&self) -> &RobotDescription {
        &self.robot
    }

    /// The scenario the world was built from.
    pub fn scenario(&self) -> &Scenario {
        &self.scenario
    }

    /// The configuration the world was built with.
    pub fn config(&self) -> &SimConfig {
        &self.config
    }

    /// The footprint's friction model, when the floor is [`FloorModel::Coulomb`].
    pub fn floor_friction(&self) -> Option<&FloorFriction> {
        self.floor.as_ref()
    }

    /// Moment of inertia of the object about its centroid, kg m^2 (uniform plate).
    pub fn object_inertia(&self) -> f64 {
        self.object_inertia
    }

    /// Number of convex pieces of the object, each its own collider (1 for a convex shape).
    pub fn object_pieces(&self) -> usize {
        self.object_pieces
    }
}

/// Distance along a world ray (unit `dir`) from `origin` to the object at `pose`, if within
/// `range`. The ray is moved into the object's frame in f64 first, so rapier's f32
/// geometry only ever sees centimetre-sized coordinates.
fn cast_object(
    shape: &SharedShape,
    pose: Pose,
    origin: DVec2,
    dir: DVec2,
    range: f64,
) -> Option<f64> {
    let inv = DVec2::from_angle(-pose.theta);
    let o = inv.rotate(origin - pose.position());
    let d = inv.rotate(dir);
    let ray = Ray::new(
        RVec::new(o.x as f32, o.y as f32),
        RVec::new(d.x as f32, d.y as f32),
    );
    shape
        .cast_local_ray(&ray, range as f32, true)
        .map(|t| t as f64)
}

/// The convex pieces of an object (centred on its centroid; one piece when it is convex)
/// and its moment of inertia per unit mass about the centroid, for a uniform plate.
fn object_pieces(shape: &ObjectShape) -> Result<(Vec<SharedShape>, f64), SimBuildError> {
    match shape {
        ObjectShape::Circle { radius } => Ok((
            vec![SharedShape::ball(*radius as f32)],
            radius * radius / 2.0,
        )),
        ObjectShape::Polygon(poly) => {
            let pieces = convex_pieces(poly).ok_or(SimBuildError::Decomposition)?;
            let mut shapes = Vec::with_capacity(pieces.len());
            for (k, piece) in pieces.iter().enumerate() {
                let points = piece
                    .iter()
                    .map(|v| RVec::new(v.x as f32, v.y as f32))
                    .collect();
                let s = SharedShape::convex_polyline(points)
                    .ok_or(SimBuildError::DegeneratePiece(k + 1))?;
                shapes.push(s);
            }
            Ok((shapes, poly.inertia_per_mass()))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use agp_runtime::alloc_count;

    #[global_allocator]
    static ALLOCATOR: alloc_count::Counting = alloc_count::Counting;

    /// Allocations made by this thread: tests run in parallel, each counts its own.
    fn allocations() -> u64 {
        alloc_count::thread_allocations()
    }

    /// Which collider pairs rapier's narrow phase holds and which of them touch: a step
    /// that leaves this unchanged changed no contact.
    fn contact_signature(sim: &Sim) -> (usize, u64) {
        sim.world
            .narrow_phase
            .contact_pairs()
            .fold((0, 0u64), |(n, h), p| {
                let a = p.collider1.into_raw_parts().0 as u64;
                let b = p.collider2.into_raw_parts().0 as u64;
                let touching = p.has_any_active_contact() as u64;
                (n + 1, h.rotate_left(7) ^ (a << 33 | b << 1 | touching))
            })
    }

    #[test]
    fn a_repeated_push_allocates_nothing() {
        alloc_count::enable();
        let drives = [RobotDrive::Kinematic, RobotDrive::FiniteForce];
        for (name, drive) in agp_world::BUILTIN_NAMES
            .into_iter()
            .flat_map(|n| drives.map(|d| (n, d)))
        {
            let mut scenario = Scenario::builtin(name).expect("built-in");
            scenario.robot.drive = drive;
            let mut sim = Sim::new(&scenario, &RobotDescription::epuck(), SimConfig::default())
                .expect("builds");
            // Three passes of the same trial from the same start: drive up to the object,
            // push it while turning (128 IR and odometry samples, 2 fixes), back off until
            // the contact ends. The first two are the warm-up, in which every buffer (ours
            // and rapier's, which grows its workspaces the first time it needs them: a pair
            // leaves the broad phase only at the second reset) reaches its working size; the
            // third is counted, contacts beginning and ending included.
            let (approach, push, back_off) = (400, 1280, 400);
            let (mut own, mut rapier, mut contact_changes) = (0, 0, 0);
            for pass in 0..3 {
                sim.reset(Pose::default(), Pose::new(-0.08, 0.005, 0.0));
                for k in 0..approach + push + back_off {
                    if k == approach {
                        assert!(sim.in_contact(), "the {name} is being pushed");
                    }
                    // Straight on for the approach and half the push, then turning.
                    let (l, r) = if k < approach + push / 2 {
                        (0.1, 0.1)
                    } else if k < approach + push {
                        (0.08, 0.12)
                    } else {
                        (-0.1, -0.1)
                    };
                    let contacts = contact_signature(&sim);
                    let b = allocations();
                    let travel = sim.before_rapier(l, r);
                    let c = allocations();
                    sim.world.step();
                    let d = allocations();
                    sim.after_rapier(travel);
                    let _ = sim.in_contact();
                    if pass == 2 {
                        own += (c - b) + (allocations() - d);
                        rapier += d - c;
                        contact_changes += usize::from(contact_signature(&sim) != contacts);
                    }
                }
            }
            eprintln!(
                "{name} ({drive:?}): rapier allocated {rapier} times in a pass with {contact_changes} contact changes"
            );
            assert_eq!(
                own, 0,
                "the {name}: the simulator's own work allocated {own} times"
            );
            assert!(
                contact_changes >= 2,
                "the {name}: the pass began and ended no contact ({contact_changes} changes)"
            );
            // Our patched rapier (vendor/rapier2d/PATCHES.md; item 6 for the finite-force
            // drive's joints) and one collider per convex piece.
            assert_eq!(
                rapier, 0,
                "the {name} ({drive:?}): rapier allocated {rapier} times in the third pass"
            );
        }
    }
}
