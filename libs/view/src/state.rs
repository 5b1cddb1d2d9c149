//! What the view knows of a run: the latest of each topic it shows, as the estimator, the
//! robot's senses and the supervisor published them. Never ground truth.

use agp_shared_types::{
    GRID_CELLS, GRID_SIDE, Goal, GradientGrid, GridHeader, GridKind, IrFrame, ObjectEstimate, Task,
    TaskKind,
};

/// The kinds of grid the view keeps of its alpha: the paper's S, P and the signed rotation.
const KEPT: [GridKind; 5] = [
    GridKind::Shape,
    GridKind::PositionX,
    GridKind::PositionY,
    GridKind::Rotation,
    GridKind::PushWeight,
];

/// One alpha's layer of the affordance gradient: the grids the view draws, copied out of
/// the published samples (once per published set).
#[derive(Debug, Clone, PartialEq)]
pub struct AgLayer {
    /// The header of the layer's S grid (cell size, origin in the object frame, alpha).
    pub header: GridHeader,
    /// S, normalised to [0, 1]; row-major, `cells[j * GRID_SIDE + i]`, j along y.
    pub shape: Vec<f32>,
    /// P, where the centroid moves when pushed from a cell (m), x and y.
    pub push_x_m: Vec<f32>,
    pub push_y_m: Vec<f32>,
    /// The signed rotation of a push from a cell (rad, counter-clockwise positive).
    pub rotation_rad: Vec<f32>,
    /// The push weight (about the number of pushes within one sigma of the cell).
    pub push_weight: Vec<f32>,
}

impl AgLayer {
    fn empty(header: GridHeader) -> Self {
        Self {
            header,
            shape: vec![0.0; GRID_CELLS],
            push_x_m: vec![0.0; GRID_CELLS],
            push_y_m: vec![0.0; GRID_CELLS],
            rotation_rad: vec![0.0; GRID_CELLS],
            push_weight: vec![0.0; GRID_CELLS],
        }
    }

    fn cells_mut(&mut self, kind: GridKind) -> Option<&mut Vec<f32>> {
        match kind {
            GridKind::Shape => Some(&mut self.shape),
            GridKind::PositionX => Some(&mut self.push_x_m),
            GridKind::PositionY => Some(&mut self.push_y_m),
            GridKind::Rotation => Some(&mut self.rotation_rad),
            GridKind::PushWeight => Some(&mut self.push_weight),
            _ => None,
        }
    }

    /// The S value of the cell holding `p` (object frame, m), 0 outside the grid.
    pub fn shape_at(&self, p: glam::DVec2) -> f32 {
        let h = &self.header;
        if h.cell_size_m <= 0.0 {
            return 0.0;
        }
        let i = ((p.x - h.origin_x_m) / h.cell_size_m).floor();
        let j = ((p.y - h.origin_y_m) / h.cell_size_m).floor();
        let side = GRID_SIDE as f64;
        if !(0.0..side).contains(&i) || !(0.0..side).contains(&j) {
            return 0.0;
        }
        self.shape[j as usize * GRID_SIDE + i as usize]
    }
}

/// The goal the view draws: a task's or a live session's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GoalView {
    /// The live session's goal id, 0 for a task handed to the planner at start.
    pub id: u64,
    pub task: Task,
}

/// Everything the view shows, the latest of each topic.
#[derive(Debug, Clone, Default)]
pub struct ViewState {
    /// The estimator's latest estimate (robot pose, object pose and its bounds, contact).
    pub estimate: Option<ObjectEstimate>,
    /// The robot's latest IR frame (its readings; the rays are drawn from the estimated pose).
    pub frame: Option<IrFrame>,
    /// The goal under way.
    pub goal: Option<GoalView>,
    /// The AG layer of the chosen alpha, from the newest complete set seen.
    pub layer: Option<AgLayer>,
    /// Bumped each time `layer` changes.
    pub layer_version: u64,
    /// The alpha (degrees) whose layer the view keeps.
    pub alpha_deg: f64,
    /// The layer being gathered: (its grid seq, the layer so far, kinds received).
    gathering: Option<(u64, AgLayer, u32)>,
}

impl ViewState {
    /// A state that keeps the layer of `alpha_deg` (the nearest learned alpha).
    pub fn new(alpha_deg: f64) -> Self {
        Self {
            alpha_deg,
            ..Self::default()
        }
    }

    pub fn on_estimate(&mut self, e: &ObjectEstimate) {
        self.estimate = Some(*e);
    }

    pub fn on_frame(&mut self, f: &IrFrame) {
        self.frame = Some(*f);
    }

    /// A task handed to the planner. A learning task has no goal to draw. A serving planner
    /// publishes the live goal it pursues as its task too: that one keeps the goal's id.
    pub fn on_task(&mut self, t: &Task) {
        let same = |g: &Task| {
            let n = (t.path_len as usize).min(t.path.len());
            g.kind == t.kind
                && g.goal == t.goal
                && g.path_len == t.path_len
                && g.path[..n] == t.path[..n]
        };
        let id = match &self.goal {
            Some(g) if same(&g.task) => g.id,
            _ => 0,
        };
        self.goal = (t.kind != TaskKind::Learn as u32).then_some(GoalView { id, task: *t });
    }

    /// A live session's goal; id 0 means none.
    pub fn on_goal(&mut self, g: &Goal) {
        self.goal = (g.id != 0).then_some(GoalView {
            id: g.id,
            task: g.task,
        });
    }

    /// One published grid. The grids of one set arrive in order; the layer is replaced
    /// once every kept kind of the chosen alpha of a set arrived.
    pub fn on_grid(&mut self, g: &GradientGrid) {
        let h = g.header;
        if h.width as usize != GRID_SIDE || h.height as usize != GRID_SIDE {
            return;
        }
        let Some(kind) = GridKind::from_u32(h.kind) else {
            return;
        };
        if !KEPT.contains(&kind) {
            return;
        }
        // The nearest alpha to the chosen one among the alphas seen: the learned alphas
        // are 0 and +-15 deg, and 0 is the default.
        if (h.alpha_deg - self.alpha_deg).abs() > 7.5 {
            return;
        }
        let restart = !matches!(&self.gathering, Some((seq, _, _)) if *seq == h.seq);
        if restart {
            self.gathering = Some((h.seq, AgLayer::empty(h), 0));
        }
        let Some((_, layer, got)) = self.gathering.as_mut() else {
            return;
        };
        if kind == GridKind::Shape {
            layer.header = h;
        }
        if let Some(cells) = layer.cells_mut(kind) {
            cells.copy_from_slice(&g.cells);
            *got |= 1 << (kind as u32);
        }
        let all = KEPT.iter().fold(0u32, |m, k| m | 1 << (*k as u32));
        if *got == all
            && let Some((_, layer, _)) = self.gathering.take()
        {
            self.layer = Some(layer);
            self.layer_version += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(seq: u64, kind: GridKind, alpha_deg: f64, value: f32) -> Box<GradientGrid> {
        Box::new(GradientGrid {
            header: GridHeader {
                seq,
                kind: kind as u32,
                alpha_count: 3,
                width: GRID_SIDE as u32,
                height: GRID_SIDE as u32,
                alpha_deg,
                cell_size_m: 0.002,
                ..GridHeader::default()
            },
            cells: [value; GRID_CELLS],
        })
    }

    #[test]
    fn the_layer_of_the_chosen_alpha_is_taken_once_each_kept_kind_of_one_set_arrived() {
        let mut state = ViewState::new(0.0);
        for (k, kind) in GridKind::ALL.into_iter().enumerate() {
            state.on_grid(&grid(1, kind, 15.0, 9.0));
            state.on_grid(&grid(1, kind, 0.0, k as f32));
            if k < GridKind::ALL.len() - 1 {
                // PushWeight (5) and Rotation (6) are kept: the layer is whole after 6.
                assert_eq!(state.layer.is_some(), k >= 6, "after kind {k}");
            }
        }
        let layer = state.layer.as_ref().expect("a layer");
        assert_eq!(state.layer_version, 1);
        assert_eq!(layer.header.alpha_deg, 0.0);
        assert_eq!(layer.shape[0], 0.0);
        assert_eq!(layer.push_y_m[0], 2.0);
        assert_eq!(layer.rotation_rad[0], 6.0);
        // A new set replaces it only once whole.
        state.on_grid(&grid(2, GridKind::Shape, 0.0, 0.5));
        assert_eq!(state.layer_version, 1);
    }

    #[test]
    fn a_learning_task_has_no_goal_and_goal_zero_is_none() {
        let mut state = ViewState::new(0.0);
        state.on_goal(&Goal::default());
        assert!(state.goal.is_none());
        let g = Goal {
            id: 3,
            ..Goal::default()
        };
        state.on_goal(&g);
        assert_eq!(state.goal.map(|g| g.id), Some(3));
        let mut t = g.task;
        t.kind = TaskKind::Learn as u32;
        state.on_task(&t);
        assert!(state.goal.is_none());
    }
}
