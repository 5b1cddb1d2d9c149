//! The finite-force drive: the E-puck as a dynamic body pulled by two stepper wheels whose
//! force is bounded by traction and by the motors (a scenario's `[robot] drive =
//! "finite-force"`; `libs/world/data/epuck.toml` holds the figures and their sources).
//!
//! # The model
//! Each wheel touches the floor at its mount point, (0, +-axle/2) in the robot frame. A
//! stepper turns its wheel at the commanded speed v_cmd (the clamped command) unless the
//! floor asks for more force than the wheel can give; the floor then lets the tyre slide
//! (or, were the motor the weaker, the stepper would lose steps: the same for the body).
//! Per wheel, along its rolling direction and across it:
//!
//! - pull (rolling direction): the force that keeps the contact point's velocity u at
//!   v_cmd, bounded by F_pull = min(mu_wheel * m * g / 2, wheel_torque / wheel_radius);
//! - grip (across): the force that keeps the contact point from sliding sideways,
//!   bounded by F_grip = mu_wheel * m * g / 2.
//!
//! The weight m g is taken to rest on the two wheels, half each. Both are rapier joint
//! motors, with no locked axis, between the robot and a *carrier* under the wheel: a
//! kinematic body that the simulator puts on the wheel's contact point before each step,
//! turned to the robot's heading, and moves at the commanded wheel velocity v_cmd along
//! it. The motors (target: no velocity relative to the carrier) are hard velocity
//! constraints whose impulse per step is clamped to force * dt; rapier solves them
//! together with the robot-object contact, so a push that needs less than 2 F_pull keeps
//! the commanded speed exactly, and one that needs more makes the wheels slip at full
//! traction (2 F_pull = 1.26 N for the E-puck, against 1.96 N to slide a 0.5 kg object
//! at floor friction 0.4). The joints are never changed after they are built (a changed
//! joint makes rapier allocate on every step); only the carriers move.
//!
//! Pull and grip are bounded separately (a box, not Coulomb's circle): a wheel slipping
//! along its rolling direction still grips sideways with up to mu N, where a real tyre
//! would have only sqrt((mu N)^2 - F_pull^2) left.
//!
//! # The object at rest: static floor friction
//! The floor's Coulomb friction on a sliding object is applied before each rapier step
//! ([`crate::FloorFriction::apply`]), so it cannot hold an object at rest against a
//! contact force found within the step: a robot of finite force pushing a heavy object
//! would move it a little every step (about 3 mm/s for 0.5 kg). With this drive an object
//! at rest at the start of a step (or stopped by the floor's clamp) is therefore also held
//! by a [`FloorHold`]: velocity motors of target 0 relative to the floor, in the solver
//! with the contact, bounded by mu_floor * m_obj * g along and across the robot's heading
//! and by the footprint's torque under pure rotation, sum(mu_floor * load_i * |r_i|),
//! about the centroid. The hold is joints to carriers on the object's centroid, in pairs,
//! each joint with half the bounds: at rest both carriers of a pair stand still and the
//! two motors hold together with the whole bound; while the object slides the carriers
//! run away from it in opposite directions, both motors saturate, and their pulls cancel.
//! One pair holds the force (its carriers slide at +-10 m/s without turning, so both keep
//! the same axes), one the torque (its carriers turn at +-1000 rad/s; an angular motor has
//! no axis to lose). So the joints never change (see above). A push that needs more breaks the
//! object free, and from the next step on it slides under the footprint model. The bounds
//! are a box again, not the footprint's limit surface: a push at up to the contact's
//! friction angle (17 deg at mu 0.3) off the heading frees the object at up to
//! 1 / cos(17 deg) = 1.05 times mu m g, and a force with a torque is held while each stays
//! under its own bound.
//!
//! # Odometry and slip
//! The E-puck counts the steps it commanded, so odometry integrates the commanded wheel
//! travel (v_cmd dt per step), whatever the body did. The slip of a wheel is that
//! commanded travel minus the travel of the wheel's floor contact point along its rolling
//! direction, summed since the last reset: 0 while the wheel rolls, the whole travel when
//! it spins on the spot.

use agp_world::{Pose, RobotDescription};
use glam::DVec2;
use rapier2d::math::{Pose as RPose, Vector as RVec};
use rapier2d::prelude::{
    GenericJointBuilder, ImpulseJointHandle, JointAxesMask, JointAxis, PhysicsWorld,
    RigidBodyBuilder, RigidBodyHandle,
};

use crate::floor_friction::G;

/// Damping of the velocity motors (rapier's motor `factor`): large enough that a motor is
/// a hard velocity constraint (its softness is 1 / (dt * factor), about 1e-6 of its
/// stiffness at 640 Hz with four substeps), finite so no infinity reaches rapier.
const MOTOR_FACTOR: f32 = 1e9;

/// How fast the hold's carriers run away from a sliding object, m/s and rad/s: far beyond
/// the velocity change its motors can make in a step (mu g dt = 6 mm/s at mu 0.4), so
/// they saturate.
const RUN_AWAY: (f64, f64) = (10.0, 1000.0);

/// A joint of velocity motors on the given axes and bounds, the same for every step.
fn motors(axes: &[(JointAxis, f64)], frame2: RPose) -> GenericJointBuilder {
    let mut joint = GenericJointBuilder::new(JointAxesMask::empty())
        .local_frame2(frame2)
        .contacts_enabled(false);
    for &(axis, bound) in axes {
        joint = joint
            .motor_velocity(axis, 0.0, MOTOR_FACTOR)
            .motor_max_force(axis, bound as f32);
    }
    joint
}

fn set_carrier(
    world: &mut PhysicsWorld,
    carrier: RigidBodyHandle,
    at: DVec2,
    theta: f64,
    v: DVec2,
    w: f64,
) {
    if let Some(b) = world.bodies.get_mut(carrier) {
        b.set_position(
            RPose::new(RVec::new(at.x as f32, at.y as f32), theta as f32),
            false,
        );
        b.set_linvel(RVec::new(v.x as f32, v.y as f32), false);
        b.set_angvel(w as f32, false);
    }
}

/// The finite-force drive of one robot body (see the module's documentation).
#[derive(Debug, Clone)]
pub(crate) struct WheelDrive {
    /// The carriers under the left and right wheel.
    carriers: [RigidBodyHandle; 2],
    /// Wheel contact points in the robot frame: left (0, +axle/2), right (0, -axle/2).
    mounts: [DVec2; 2],
    /// Largest pull of one wheel along its rolling direction, N.
    pull: f64,
    /// Largest grip of one wheel across its rolling direction, N.
    grip: f64,
    /// Commanded minus ground travel of each wheel since the last reset, m.
    slip: (f64, f64),
}

/// The force limits of one wheel of `robot`: (pull, grip), N.
pub(crate) fn wheel_limits(robot: &RobotDescription) -> (f64, f64) {
    let traction = robot.wheel_friction * robot.mass * G / 2.0;
    let motor = robot.wheel_torque / robot.wheel_radius;
    (traction.min(motor), traction)
}

impl WheelDrive {
    /// Inserts the wheels' carriers and joints on `robot_body` (a dynamic body at `pose`).
    pub fn new(
        world: &mut PhysicsWorld,
        robot_body: RigidBodyHandle,
        robot: &RobotDescription,
        pose: Pose,
    ) -> Self {
        let (pull, grip) = wheel_limits(robot);
        let half = robot.axle_length / 2.0;
        let mounts = [DVec2::new(0.0, half), DVec2::new(0.0, -half)];
        let carriers = mounts.map(|m| {
            let p = world_point(pose, m);
            let carrier = world.insert_body(RigidBodyBuilder::kinematic_velocity_based().pose(
                RPose::new(RVec::new(p.x as f32, p.y as f32), pose.theta as f32),
            ));
            let joint = motors(
                &[(JointAxis::LinX, pull), (JointAxis::LinY, grip)],
                RPose::new(RVec::new(m.x as f32, m.y as f32), 0.0),
            );
            world.insert_impulse_joint(carrier, robot_body, joint);
            carrier
        });
        Self {
            carriers,
            mounts,
            pull,
            grip,
            slip: (0.0, 0.0),
        }
    }

    /// Sets the wheels' speeds (m/s, already clamped) for the next step of `dt`, with the
    /// robot at `pose` turning at `omega` (rad/s): each carrier is put on its wheel's
    /// contact point, turned to the heading the robot will have halfway through the step
    /// (a carrier does not turn while rapier solves the step; the mid-step heading halves
    /// the error of the robot turning over it), and moves at its wheel's speed along it.
    pub fn command(
        &self,
        world: &mut PhysicsWorld,
        pose: Pose,
        omega: f64,
        dt: f64,
        (left, right): (f64, f64),
    ) {
        let heading = pose.theta + omega * dt / 2.0;
        let along = DVec2::from_angle(heading);
        for (k, speed) in [left, right].into_iter().enumerate() {
            let at = world_point(pose, self.mounts[k]);
            set_carrier(world, self.carriers[k], at, heading, along * speed, 0.0);
        }
    }

    /// Adds one step's slip: the commanded travel of each wheel minus its contact point's
    /// travel along the robot's mean heading over the step, from pose `before` to `after`.
    pub fn account(&mut self, before: Pose, after: Pose, commanded: (f64, f64)) {
        let [l, r] = self.ground_travel(before, after);
        self.slip.0 += commanded.0 - l;
        self.slip.1 += commanded.1 - r;
    }

    /// Travel of each wheel's contact point along the mean heading from `before` to `after`.
    fn ground_travel(&self, before: Pose, after: Pose) -> [f64; 2] {
        let turn = agp_shared_types::angle::wrap_angle(after.theta - before.theta);
        let along = DVec2::from_angle(before.theta + turn / 2.0);
        self.mounts
            .map(|m| (world_point(after, m) - world_point(before, m)).dot(along))
    }

    /// Slip of the (left, right) wheel since the last reset, m.
    pub fn slip(&self) -> (f64, f64) {
        self.slip
    }

    /// Forgets the slip (the robot was put somewhere).
    pub fn reset(&mut self) {
        self.slip = (0.0, 0.0);
    }

    /// Largest pull and grip of one wheel, N.
    pub fn limits(&self) -> (f64, f64) {
        (self.pull, self.grip)
    }
}

/// Static floor friction on the object while it rests (see the module's documentation).
#[derive(Debug, Clone)]
pub(crate) struct FloorHold {
    /// The force pair's carriers, then the torque pair's.
    carriers: [RigidBodyHandle; 4],
    /// Their joints, in the same order.
    joints: [ImpulseJointHandle; 4],
}

impl FloorHold {
    /// Joins `object` (at `pose`) to the hold's two carriers, each with half of `force`
    /// (N, along and across) and `torque` (N m).
    pub fn new(
        world: &mut PhysicsWorld,
        object: RigidBodyHandle,
        pose: Pose,
        force: f64,
        torque: f64,
    ) -> Self {
        let linear = [
            (JointAxis::LinX, force / 2.0),
            (JointAxis::LinY, force / 2.0),
        ];
        let angular = [(JointAxis::AngX, torque / 2.0)];
        let built = [&linear[..], &linear[..], &angular[..], &angular[..]].map(|axes| {
            let carrier = world.insert_body(RigidBodyBuilder::kinematic_velocity_based().pose(
                RPose::new(RVec::new(pose.x as f32, pose.y as f32), pose.theta as f32),
            ));
            let joint = world.insert_impulse_joint(carrier, object, motors(axes, RPose::IDENTITY));
            (carrier, joint)
        });
        Self {
            carriers: built.map(|b| b.0),
            joints: built.map(|b| b.1),
        }
    }

    /// Sets new bounds, `force` (N, along and across) and `torque` (N m), each pair's
    /// joints holding half (the floor's friction or the object's mass changed). Changes
    /// the joints: rapier recomputes its joint selection at the next step (a world change
    /// is rare; the hot loop never calls this).
    pub fn set_bounds(&self, world: &mut PhysicsWorld, force: f64, torque: f64) {
        for (k, handle) in self.joints.into_iter().enumerate() {
            if let Some(joint) = world.impulse_joints.get_mut(handle, true) {
                if k < 2 {
                    joint
                        .data
                        .set_motor_max_force(JointAxis::LinX, (force / 2.0) as f32);
                    joint
                        .data
                        .set_motor_max_force(JointAxis::LinY, (force / 2.0) as f32);
                } else {
                    joint
                        .data
                        .set_motor_max_force(JointAxis::AngX, (torque / 2.0) as f32);
                }
            }
        }
    }

    /// Puts the carriers on the object's centroid (`object`, its pose), turned to
    /// `heading` (the robot's): standing still when the object is `at_rest`, so the object
    /// is held through the next step; else running away from it in opposite directions, so
    /// the hold pulls it nowhere.
    pub fn command(&self, world: &mut PhysicsWorld, object: Pose, heading: f64, at_rest: bool) {
        let (v, w) = if at_rest {
            (DVec2::ZERO, 0.0)
        } else {
            (DVec2::splat(RUN_AWAY.0), RUN_AWAY.1)
        };
        let at = object.position();
        set_carrier(world, self.carriers[0], at, heading, v, 0.0);
        set_carrier(world, self.carriers[1], at, heading, -v, 0.0);
        set_carrier(world, self.carriers[2], at, heading, DVec2::ZERO, w);
        set_carrier(world, self.carriers[3], at, heading, DVec2::ZERO, -w);
    }
}

fn world_point(pose: Pose, local: DVec2) -> DVec2 {
    pose.position() + DVec2::from_angle(pose.theta).rotate(local)
}
