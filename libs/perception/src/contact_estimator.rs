use agp_affordance::{AIM_BORDER_THRESHOLD, Grid, border_crossing};
use agp_world::{Pose, RobotDescription, border_range, ir_point_robot, to_frame};
use glam::DVec2;

/// The learned shape as the contact estimates read it, object frame.
#[derive(Debug, Clone, Copy)]
pub struct LearnedShape<'a> {
    /// Ridge points of S (e.g. [`agp_affordance::ShapeMatcher::border_points`]), metres.
    pub border: &'a [DVec2],
    /// S normalised to [0, 1] (e.g. [`agp_affordance::AffordanceGradient::combined_shape`]);
    /// aim points are located on it at [`AIM_BORDER_THRESHOLD`], as the predictor locates
    /// them.
    pub shape: &'a Grid,
}

/// How the contact point of a push is estimated at the moment contact is inferred from IR.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ContactMethod {
    /// The paper's ObjInContact: the mean of the border points the four front sensors
    /// (±17, ±45 deg) place, within the usable range. Needs no shape; lies off the border
    /// when the sensors see two faces (a corner) and drifts with the sensors' geometry.
    FrontIrMean,
    /// Where the robot's disc first touches the learned border when it goes on straight
    /// ahead from its pose at the inferred contact: the physical touch point. Pushes that
    /// meet a corner with different lateral offsets all touch the corner itself, so near a
    /// corner different pushes share one contact point.
    BodySweep,
    /// Where the robot's heading line (through the body centre) crosses the learned border
    /// (the centre of the first band of S above the threshold along the line, as
    /// [`agp_affordance::AffordanceGradient::contact_candidates`] locates the border): the
    /// aim point of the push. Distinct push lines give distinct aim points, also at a
    /// corner, so the gradient keeps apart pushes the touch point would merge. The default.
    #[default]
    HeadingLine,
}

impl ContactMethod {
    /// Every method, in declaration order.
    pub const ALL: [ContactMethod; 3] = [
        ContactMethod::FrontIrMean,
        ContactMethod::BodySweep,
        ContactMethod::HeadingLine,
    ];

    /// A short lowercase name for reports.
    pub fn name(self) -> &'static str {
        match self {
            Self::FrontIrMean => "front-ir-mean",
            Self::BodySweep => "body-sweep",
            Self::HeadingLine => "heading-line",
        }
    }
}

/// The contact point of one push by every [`ContactMethod`], in the object's frame (the
/// object's pose before the push), metres. `None` where a method found nothing: no front
/// reading within range, or no learned border ahead.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactEstimates {
    /// [`ContactMethod::FrontIrMean`].
    pub front_ir_mean: Option<DVec2>,
    /// [`ContactMethod::BodySweep`].
    pub body_sweep: Option<DVec2>,
    /// [`ContactMethod::HeadingLine`].
    pub heading_line: Option<DVec2>,
    /// The robot's pose in the object's frame when contact was inferred.
    pub robot_obj: Pose,
}

impl ContactEstimates {
    /// The estimate of `method`.
    pub fn get(&self, method: ContactMethod) -> Option<DVec2> {
        match method {
            ContactMethod::FrontIrMean => self.front_ir_mean,
            ContactMethod::BodySweep => self.body_sweep,
            ContactMethod::HeadingLine => self.heading_line,
        }
    }
}

/// Estimates contact points from one IR frame, the object's pose and the learned border.
/// Allocates nothing after construction.
#[derive(Debug, Clone)]
pub struct ContactEstimator {
    /// Mount and ray direction of the four front sensors, robot frame.
    front: [usize; 4],
    robot: RobotDescription,
    range: f64,
}

impl ContactEstimator {
    /// An estimator for `robot`, reading border points within its usable IR range
    /// ([`agp_world::border_range`]).
    pub fn new(robot: &RobotDescription) -> Self {
        Self {
            front: robot.front_sensors(),
            robot: robot.clone(),
            range: border_range(robot),
        }
    }

    /// The object-frame pose of a robot at `odometry` when the object sits at
    /// `object_pose` (both in the odometry frame).
    pub fn robot_in_object_frame(odometry: Pose, object_pose: Pose) -> Pose {
        let p = DVec2::from_angle(-object_pose.theta)
            .rotate(odometry.position() - object_pose.position());
        Pose::new(p.x, p.y, odometry.theta - object_pose.theta)
    }

    /// Contact estimates of every method for a robot at `odometry` with readings `ir_raw`,
    /// the object at `object_pose` (both in the odometry frame) and its learned shape.
    /// Allocates nothing.
    pub fn estimate(
        &self,
        odometry: Pose,
        ir_raw: &[f32; 8],
        object_pose: Pose,
        learned: LearnedShape<'_>,
    ) -> ContactEstimates {
        let robot_obj = Self::robot_in_object_frame(odometry, object_pose);
        ContactEstimates {
            front_ir_mean: self.front_ir_mean(robot_obj, ir_raw),
            body_sweep: body_sweep(robot_obj, self.robot.body_radius, learned.border),
            heading_line: border_crossing(
                learned.shape,
                robot_obj.position(),
                DVec2::from_angle(robot_obj.theta),
                AIM_BORDER_THRESHOLD,
            ),
            robot_obj,
        }
    }

    /// The mean of the front sensors' border points (the paper's ObjInContact), in the
    /// frame `robot` is given in.
    fn front_ir_mean(&self, robot: Pose, ir_raw: &[f32; 8]) -> Option<DVec2> {
        let (mut n, mut sum) = (0usize, DVec2::ZERO);
        for &i in &self.front {
            if let Some(p) = ir_point_robot(&self.robot, i, f64::from(ir_raw[i]), self.range) {
                n += 1;
                sum += to_frame(robot, p);
            }
        }
        (n > 0).then(|| sum / n as f64)
    }
}

/// The border point a disc of `radius` at `robot` (object frame) touches first going
/// straight ahead: for each border point, the travel after which it lies on the disc's
/// rim, `along - sqrt(r^2 - lateral^2)`; the smallest wins.
fn body_sweep(robot: Pose, radius: f64, border: &[DVec2]) -> Option<DVec2> {
    let (c, d) = (robot.position(), DVec2::from_angle(robot.theta));
    let r2 = radius * radius;
    let mut best: Option<(f64, DVec2)> = None;
    for &b in border {
        let v = b - c;
        let lateral = v.perp_dot(d);
        let along = v.dot(d);
        if along <= 0.0 || lateral * lateral > r2 {
            continue;
        }
        let travel = along - (r2 - lateral * lateral).sqrt();
        if best.is_none_or(|(t, _)| travel < t) {
            best = Some((travel, b));
        }
    }
    best.map(|(_, b)| b)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points every 1 mm along the square of half side `h` centred at the origin.
    fn square_border(h: f64) -> Vec<DVec2> {
        let n = (2.0 * h / 0.001).round() as usize;
        let mut out = Vec::new();
        for k in 0..n {
            let t = -h + k as f64 * 0.001;
            out.extend([
                DVec2::new(t, -h),
                DVec2::new(h, t),
                DVec2::new(-t, h),
                DVec2::new(-h, -t),
            ]);
        }
        out
    }

    /// S of that border: a 2.5 mm Gaussian at each point, normalised to a peak of 1.
    fn shape_of(border: &[DVec2]) -> Grid {
        let mut g = Grid::centred(0.002);
        for &p in border {
            g.add_gaussian(p, 0.0025, 1.0);
        }
        let max = g.max();
        g.scale(1.0 / max);
        g
    }

    fn learned<'a>(border: &'a [DVec2], shape: &'a Grid) -> LearnedShape<'a> {
        LearnedShape { border, shape }
    }

    #[test]
    fn a_straight_push_on_a_face_touches_and_aims_at_the_same_point() {
        let robot = RobotDescription::epuck();
        let est = ContactEstimator::new(&robot);
        let border = square_border(0.03);
        let shape = shape_of(&border);
        // Robot 40 mm (3 mm gap) left of the face x = -30 mm, facing +x, 10 mm up.
        let odo = Pose::new(-0.03 - robot.body_radius - 0.003, 0.01, 0.0);
        let e = est.estimate(odo, &[0.0; 8], Pose::default(), learned(&border, &shape));
        let touch = e.body_sweep.expect("ahead");
        let aim = e.heading_line.expect("ahead");
        assert!((touch - DVec2::new(-0.03, 0.01)).length() < 1e-9, "{touch}");
        // The band's centre: within a quarter cell of the face.
        assert!((aim - DVec2::new(-0.03, 0.01)).length() < 5e-4, "{aim}");
        assert_eq!(e.front_ir_mean, None, "no reading, no front estimate");
    }

    #[test]
    fn an_oblique_push_touches_the_face_off_the_heading_line() {
        let robot = RobotDescription::epuck();
        let est = ContactEstimator::new(&robot);
        let border = square_border(0.03);
        let shape = shape_of(&border);
        // Heading 20 deg off the face normal: the disc touches at the foot of the normal
        // through its centre, the heading line meets the face r * tan(20 deg) higher.
        let theta = 20f64.to_radians();
        let odo = Pose::new(-0.03 - robot.body_radius - 0.002, 0.0, theta);
        let e = est.estimate(odo, &[0.0; 8], Pose::default(), learned(&border, &shape));
        let touch = e.body_sweep.expect("ahead");
        let aim = e.heading_line.expect("ahead");
        // The disc slides 2 mm / cos(20) along the heading before touching: its centre
        // then sits at y = 2 tan(20) mm, the touch point beside it on the face.
        let y_touch = 0.002 * theta.tan();
        assert!(
            (touch - DVec2::new(-0.03, y_touch)).length() < 1.1e-3,
            "{touch}"
        );
        let y_aim = (robot.body_radius + 0.002) * theta.tan();
        assert!((aim - DVec2::new(-0.03, y_aim)).length() < 5e-4, "{aim}");
    }

    #[test]
    fn the_front_mean_is_the_mean_of_the_front_sensors_border_points() {
        let robot = RobotDescription::epuck();
        let est = ContactEstimator::new(&robot);
        // A wall 5 mm ahead of the shell, x = 42 mm in the robot frame (all four front rays
        // within the 40 mm usable range); object frame =
        // robot frame here.
        let wall = robot.body_radius + 0.005;
        let mut raw = [0f32; 8];
        let mut expected = DVec2::ZERO;
        for i in robot.front_sensors() {
            let s = &robot.ir_sensors[i];
            let t = (wall - s.mount.x) / s.direction().x;
            raw[i] = robot.response.reading(t) as f32;
            assert!(t <= border_range(&robot), "IR{} is within range", i + 1);
            expected += s.mount + s.direction() * t;
        }
        expected /= 4.0;
        let shape = Grid::centred(0.002);
        let e = est.estimate(Pose::default(), &raw, Pose::default(), learned(&[], &shape));
        assert_eq!(e.heading_line, None, "an empty S has no border");
        let p = e.front_ir_mean.expect("four readings");
        // f32 readings invert to within a few micrometres.
        assert!((p - expected).length() < 2e-5, "{p} vs {expected}");
        assert!((p.x - wall).abs() < 2e-5);
    }

    #[test]
    fn estimates_come_back_in_the_objects_frame() {
        let robot = RobotDescription::epuck();
        let est = ContactEstimator::new(&robot);
        let border = square_border(0.03);
        let shape = shape_of(&border);
        let object = Pose::new(0.5, -0.2, 1.0);
        // The first test's robot, moved with the object.
        let local = Pose::new(-0.03 - robot.body_radius - 0.003, 0.01, 0.0);
        let p = to_frame(object, local.position());
        let odo = Pose::new(p.x, p.y, local.theta + object.theta);
        let e = est.estimate(odo, &[0.0; 8], object, learned(&border, &shape));
        assert!((e.body_sweep.expect("ahead") - DVec2::new(-0.03, 0.01)).length() < 1e-9);
        assert!((e.robot_obj.position() - local.position()).length() < 1e-12);
    }
}
