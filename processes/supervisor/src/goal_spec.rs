//! The goals `agp goal` sends to a live session: what a user types, checked and turned into
//! the `Task` the serving planner pursues, before anything is sent.

use agp_shared_types::{Goal, MAX_PATH_POINTS, Pose2, TaskKind};

/// A goal as typed: a placement or a path, in millimetres and degrees (world frame).
#[derive(Debug, Clone, PartialEq)]
pub enum GoalSpec {
    /// `--place X Y THETA`.
    Place {
        x_mm: f64,
        y_mm: f64,
        theta_deg: f64,
    },
    /// `--path X,Y X,Y ...`: the object's centroid pushed along this polyline; with
    /// `--keep-heading DEG`, its heading kept tangent to it within that.
    Path {
        points_mm: Vec<[f64; 2]>,
        keep_heading_deg: Option<f64>,
    },
}

/// Why a goal was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GoalSpecError {
    #[error("`{0}` is not a point: expected X,Y in millimetres, e.g. 100,-50")]
    BadPoint(String),
    #[error("a path needs at least 2 points, got {0}")]
    ShortPath(usize),
    #[error("a path holds at most {MAX_PATH_POINTS} points, got {0}")]
    LongPath(usize),
    #[error("every coordinate must be a finite number within 10 m of the origin, got {0}")]
    OutOfRange(f64),
    #[error("a heading tolerance is in (0, 180] degrees, got {0}")]
    BadHeading(f64),
}

/// Coordinates beyond this (mm) are refused: the arena is a few tens of centimetres.
const MAX_COORDINATE_MM: f64 = 10_000.0;

fn checked(v: f64) -> Result<f64, GoalSpecError> {
    if v.is_finite() && v.abs() <= MAX_COORDINATE_MM {
        Ok(v)
    } else {
        Err(GoalSpecError::OutOfRange(v))
    }
}

impl GoalSpec {
    /// `X,Y` words of `--path`, and `--keep-heading`'s degrees.
    pub fn path(words: &[String], keep_heading_deg: Option<f64>) -> Result<Self, GoalSpecError> {
        if let Some(h) = keep_heading_deg
            && !(h > 0.0 && h <= 180.0)
        {
            return Err(GoalSpecError::BadHeading(h));
        }
        if words.len() < 2 {
            return Err(GoalSpecError::ShortPath(words.len()));
        }
        if words.len() > MAX_PATH_POINTS {
            return Err(GoalSpecError::LongPath(words.len()));
        }
        let points_mm = words
            .iter()
            .map(|w| {
                let (x, y) = w
                    .split_once(',')
                    .ok_or_else(|| GoalSpecError::BadPoint(w.clone()))?;
                let parse = |s: &str| {
                    s.trim()
                        .parse::<f64>()
                        .map_err(|_| GoalSpecError::BadPoint(w.clone()))
                };
                Ok([checked(parse(x)?)?, checked(parse(y)?)?])
            })
            .collect::<Result<Vec<_>, GoalSpecError>>()?;
        Ok(Self::Path {
            points_mm,
            keep_heading_deg,
        })
    }

    /// `--place X Y THETA`.
    pub fn place(x_mm: f64, y_mm: f64, theta_deg: f64) -> Result<Self, GoalSpecError> {
        Ok(Self::Place {
            x_mm: checked(x_mm)?,
            y_mm: checked(y_mm)?,
            theta_deg: checked(theta_deg)?,
        })
    }

    /// The goal as the control service carries it (id 0: the supervisor numbers it; the
    /// tolerances and the push limit are the session scenario's, set by the supervisor).
    pub fn to_goal(&self) -> Goal {
        let mut goal = Goal::default();
        match self {
            Self::Place {
                x_mm,
                y_mm,
                theta_deg,
            } => {
                goal.task.kind = TaskKind::Place as u32;
                goal.task.goal = Pose2::new(x_mm * 1e-3, y_mm * 1e-3, theta_deg.to_radians());
            }
            Self::Path {
                points_mm,
                keep_heading_deg,
            } => {
                goal.task.kind = TaskKind::Trajectory as u32;
                goal.task.heading_tolerance_rad = keep_heading_deg.map_or(0.0, f64::to_radians);
                goal.task.path_len = points_mm.len() as u32;
                for (slot, p) in goal.task.path.iter_mut().zip(points_mm) {
                    *slot = [p[0] * 1e-3, p[1] * 1e-3];
                }
            }
        }
        goal
    }
}

/// Checks a goal that arrived over the control service (a client other than `agp goal`
/// may have sent it): its kind and its path.
pub fn check_goal(goal: &Goal) -> Result<(), String> {
    let t = &goal.task;
    let finite = |v: f64| v.is_finite() && v.abs() <= MAX_COORDINATE_MM * 1e-3;
    match t.kind {
        k if k == TaskKind::Place as u32 => {
            if !(finite(t.goal.x) && finite(t.goal.y) && t.goal.theta.is_finite()) {
                return Err("the goal pose is not finite or lies beyond 10 m".to_owned());
            }
        }
        k if k == TaskKind::Trajectory as u32 => {
            let n = t.path_len as usize;
            if !(2..=MAX_PATH_POINTS).contains(&n) {
                return Err(format!(
                    "a path needs 2 to {MAX_PATH_POINTS} points, got {n}"
                ));
            }
            if !t.path[..n].iter().flatten().all(|&v| finite(v)) {
                return Err("a path point is not finite or lies beyond 10 m".to_owned());
            }
            let h = t.heading_tolerance_rad;
            if !(h.is_finite() && (0.0..=std::f64::consts::PI).contains(&h)) {
                return Err(format!(
                    "the heading tolerance must be 0 (none) to 180 degrees, got {h} rad"
                ));
            }
        }
        k => return Err(format!("unknown task kind {k}")),
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn words(w: &[&str]) -> Vec<String> {
        w.iter().map(|s| (*s).to_owned()).collect()
    }

    #[test]
    fn a_placement_goal_carries_metres_and_radians() {
        let g = GoalSpec::place(300.0, -150.0, 90.0).unwrap().to_goal();
        assert_eq!(g.task.kind, TaskKind::Place as u32);
        assert!((g.task.goal.x - 0.3).abs() < 1e-12);
        assert!((g.task.goal.y + 0.15).abs() < 1e-12);
        assert!((g.task.goal.theta - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert_eq!(check_goal(&g), Ok(()));
    }

    #[test]
    fn a_path_goal_keeps_its_points_in_order() {
        let g = GoalSpec::path(&words(&["0,0", "100, 20", "-5.5,300"]), None)
            .unwrap()
            .to_goal();
        assert_eq!(g.task.kind, TaskKind::Trajectory as u32);
        assert_eq!(g.task.path_len, 3);
        assert_eq!(g.task.path[1], [0.1, 0.02]);
        assert_eq!(g.task.path[2], [-0.0055, 0.3]);
        assert_eq!(g.task.heading_tolerance_rad, 0.0, "the heading is free");
        assert_eq!(check_goal(&g), Ok(()));
        let kept = GoalSpec::path(&words(&["0,0", "100,0"]), Some(15.0))
            .unwrap()
            .to_goal();
        assert!((kept.task.heading_tolerance_rad - 15f64.to_radians()).abs() < 1e-15);
        assert_eq!(check_goal(&kept), Ok(()));
    }

    #[test]
    fn bad_goals_are_refused_with_what_is_wrong() {
        assert_eq!(
            GoalSpec::path(&words(&["0,0"]), None),
            Err(GoalSpecError::ShortPath(1))
        );
        assert_eq!(
            GoalSpec::path(&words(&["0,0", "12"]), None),
            Err(GoalSpecError::BadPoint("12".into()))
        );
        assert_eq!(
            GoalSpec::path(&words(&["0,0", "1,x"]), None),
            Err(GoalSpecError::BadPoint("1,x".into()))
        );
        let long: Vec<String> = (0..=MAX_PATH_POINTS).map(|i| format!("{i},0")).collect();
        assert_eq!(
            GoalSpec::path(&long, None),
            Err(GoalSpecError::LongPath(MAX_PATH_POINTS + 1))
        );
        for h in [0.0, -5.0, 181.0, f64::NAN] {
            assert!(matches!(
                GoalSpec::path(&words(&["0,0", "1,1"]), Some(h)),
                Err(GoalSpecError::BadHeading(_))
            ));
        }
        assert!(matches!(
            GoalSpec::place(f64::NAN, 0.0, 0.0),
            Err(GoalSpecError::OutOfRange(_))
        ));
        assert!(matches!(
            GoalSpec::place(0.0, 1e9, 0.0),
            Err(GoalSpecError::OutOfRange(_))
        ));
    }

    #[test]
    fn a_goal_from_another_client_is_checked_too() {
        let mut g = GoalSpec::place(0.0, 0.0, 0.0).unwrap().to_goal();
        g.task.kind = 7;
        assert!(check_goal(&g).is_err());
        let mut g = GoalSpec::path(&words(&["0,0", "1,1"]), None)
            .unwrap()
            .to_goal();
        g.task.path_len = 40;
        assert!(check_goal(&g).is_err());
        g.task.path_len = 2;
        g.task.heading_tolerance_rad = -0.1;
        assert!(check_goal(&g).is_err());
        g.task.heading_tolerance_rad = 0.0;
        g.task.path[1][0] = f64::INFINITY;
        assert!(check_goal(&g).is_err());
    }
}
