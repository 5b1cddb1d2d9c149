use agp_shared_types::{GRID_CELLS, GRID_SIDE, GradientGrid, GridHeader, GridKind};
use glam::DVec2;

/// Default side of a grid cell: 2 mm, so a grid spans 256 mm, centred on the object.
pub const DEFAULT_CELL_SIZE_M: f64 = 0.002;

/// A [`GRID_SIDE`] x [`GRID_SIDE`] f32 grid over the object's frame (metres).
///
/// Cells are row-major (`cells[j * GRID_SIDE + i]`, `i` along x, `j` along y), as in
/// [`GradientGrid`]. Cell (i, j) covers `origin + (i, j) * cell_size` to
/// `origin + (i + 1, j + 1) * cell_size`; its value stands for its centre. A grid built with
/// [`Grid::centred`] has the object's centroid (the object frame's origin) at its centre.
#[derive(Debug, Clone, PartialEq)]
pub struct Grid {
    cells: Vec<f32>,
    cell_size_m: f64,
    origin_m: DVec2,
}

/// Why a [`GradientGrid`] payload could not be read as a [`Grid`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GridPayloadReadError {
    /// The header's width or height is not [`GRID_SIDE`].
    #[error("grid payload is {width} x {height} cells, expected {GRID_SIDE} x {GRID_SIDE}")]
    WrongSize {
        /// Width found in the header.
        width: u32,
        /// Height found in the header.
        height: u32,
    },
    /// The header's kind is not a [`GridKind`].
    #[error("grid payload has unknown kind {0}")]
    UnknownKind(u32),
    /// The cell size is not a finite positive number.
    #[error("grid payload has cell size {0} m, expected a finite positive number")]
    BadCellSize(f64),
    /// The origin is not finite.
    #[error("grid payload has a non-finite origin ({0}, {1}) m")]
    BadOrigin(f64, f64),
}

/// The four cells a bilinear sample reads and their weights (zero for cells off the grid).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Bilinear {
    pub(crate) index: [usize; 4],
    pub(crate) weight: [f32; 4],
}

impl Bilinear {
    /// The interpolated value of `cells` (a grid's cell slice).
    #[inline]
    pub(crate) fn apply(&self, cells: &[f32]) -> f32 {
        self.weight[0] * cells[self.index[0]]
            + self.weight[1] * cells[self.index[1]]
            + self.weight[2] * cells[self.index[2]]
            + self.weight[3] * cells[self.index[3]]
    }
}

impl Default for Grid {
    /// A zero grid of [`DEFAULT_CELL_SIZE_M`] cells centred on the object frame's origin.
    fn default() -> Self {
        Self::centred(DEFAULT_CELL_SIZE_M)
    }
}

impl Grid {
    /// Number of cells along x and along y.
    pub const SIDE: usize = GRID_SIDE;

    /// A zero grid of `cell_size_m` cells whose centre is the object frame's origin (the
    /// object's centroid).
    ///
    /// Panics if `cell_size_m` is not finite and positive.
    #[track_caller]
    pub fn centred(cell_size_m: f64) -> Self {
        Self::with_origin(cell_size_m, centred_origin(cell_size_m))
    }

    /// A zero grid of `cell_size_m` cells whose cell (0, 0) has its corner at `origin_m`.
    ///
    /// Panics if `cell_size_m` is not finite and positive or `origin_m` is not finite.
    #[track_caller]
    pub fn with_origin(cell_size_m: f64, origin_m: DVec2) -> Self {
        assert!(
            cell_size_m.is_finite() && cell_size_m > 0.0,
            "cell size must be finite and positive, got {cell_size_m}"
        );
        assert!(origin_m.is_finite(), "grid origin must be finite");
        Self {
            cells: vec![0.0; GRID_CELLS],
            cell_size_m,
            origin_m,
        }
    }

    /// A zero grid with the same cell size and origin as `self`.
    pub fn zeros_like(&self) -> Self {
        Self::with_origin(self.cell_size_m, self.origin_m)
    }

    /// Takes `other`'s cell size and origin, keeping the cells (no allocation).
    pub(crate) fn set_geometry_from(&mut self, other: &Grid) {
        self.cell_size_m = other.cell_size_m;
        self.origin_m = other.origin_m;
    }

    /// Side of a cell, metres.
    pub fn cell_size_m(&self) -> f64 {
        self.cell_size_m
    }

    /// Object-frame coordinates (metres) of the corner of cell (0, 0).
    pub fn origin_m(&self) -> DVec2 {
        self.origin_m
    }

    /// Side of the whole grid, metres.
    pub fn extent_m(&self) -> f64 {
        GRID_SIDE as f64 * self.cell_size_m
    }

    /// Whether `other` has the same cell size and origin.
    pub fn same_geometry(&self, other: &Grid) -> bool {
        self.cell_size_m == other.cell_size_m && self.origin_m == other.origin_m
    }

    /// All cells, row-major (`j * GRID_SIDE + i`).
    pub fn cells(&self) -> &[f32] {
        &self.cells
    }

    /// All cells, row-major (`j * GRID_SIDE + i`), mutable.
    pub fn cells_mut(&mut self) -> &mut [f32] {
        &mut self.cells
    }

    /// Index into [`Grid::cells`] of cell (i, j).
    #[inline]
    pub fn index(i: usize, j: usize) -> usize {
        j * GRID_SIDE + i
    }

    /// Value of cell (i, j). Panics if the cell is off the grid.
    #[track_caller]
    #[inline]
    pub fn get(&self, i: usize, j: usize) -> f32 {
        assert!(
            i < GRID_SIDE && j < GRID_SIDE,
            "cell ({i}, {j}) is off the grid"
        );
        self.cells[Self::index(i, j)]
    }

    /// Sets cell (i, j). Panics if the cell is off the grid.
    #[track_caller]
    #[inline]
    pub fn set(&mut self, i: usize, j: usize, value: f32) {
        assert!(
            i < GRID_SIDE && j < GRID_SIDE,
            "cell ({i}, {j}) is off the grid"
        );
        self.cells[Self::index(i, j)] = value;
    }

    /// Sets every cell to `value`.
    pub fn fill(&mut self, value: f32) {
        self.cells.fill(value);
    }

    /// Multiplies every cell by `factor`.
    pub fn scale(&mut self, factor: f32) {
        self.cells.iter_mut().for_each(|c| *c *= factor);
    }

    /// Adds `other` cell by cell. Panics if the geometries differ.
    #[track_caller]
    pub fn add_grid(&mut self, other: &Grid) {
        assert!(self.same_geometry(other), "grids have different geometry");
        self.cells
            .iter_mut()
            .zip(&other.cells)
            .for_each(|(a, b)| *a += b);
    }

    /// Largest cell value (0 for an empty grid of zeros; NaN cells are ignored).
    pub fn max(&self) -> f32 {
        self.cells.iter().copied().fold(0.0_f32, f32::max)
    }

    /// Sum of all cells, accumulated in f64.
    pub fn sum(&self) -> f64 {
        self.cells.iter().map(|&c| f64::from(c)).sum()
    }

    /// Object-frame position (metres) of the centre of cell (i, j).
    pub fn cell_centre_m(&self, i: usize, j: usize) -> DVec2 {
        self.origin_m + (DVec2::new(i as f64, j as f64) + 0.5) * self.cell_size_m
    }

    /// Continuous cell coordinates of `p` (object frame, metres): cell centres sit at
    /// integers, so `(i, j)` is the centre of cell (i, j).
    #[inline]
    pub fn to_cell_coords(&self, p: DVec2) -> DVec2 {
        (p - self.origin_m) / self.cell_size_m - 0.5
    }

    /// Object-frame position (metres) of continuous cell coordinates `c`
    /// (the inverse of [`Grid::to_cell_coords`]).
    #[inline]
    pub fn from_cell_coords(&self, c: DVec2) -> DVec2 {
        self.origin_m + (c + 0.5) * self.cell_size_m
    }

    /// The cell containing `p` (object frame, metres), if it is on the grid.
    pub fn cell_at(&self, p: DVec2) -> Option<(usize, usize)> {
        let c = (p - self.origin_m) / self.cell_size_m;
        let side = GRID_SIDE as f64;
        if c.x >= 0.0 && c.y >= 0.0 && c.x < side && c.y < side {
            Some((c.x as usize, c.y as usize))
        } else {
            None
        }
    }

    /// Bilinear interpolation between cell centres at `p` (object frame, metres); cells off
    /// the grid count as zero, so the value fades to zero over the outer half cell.
    pub fn sample(&self, p: DVec2) -> f32 {
        match self.bilinear(p) {
            Some(b) => b.apply(&self.cells),
            None => 0.0,
        }
    }

    /// The cells and weights of a bilinear sample at `p`; `None` when no cell is touched.
    #[inline]
    pub(crate) fn bilinear(&self, p: DVec2) -> Option<Bilinear> {
        let c = self.to_cell_coords(p);
        if !c.is_finite() {
            return None;
        }
        let side = GRID_SIDE as f64;
        if c.x <= -1.0 || c.y <= -1.0 || c.x >= side || c.y >= side {
            return None;
        }
        let f = c.floor();
        let (fx, fy) = ((c.x - f.x) as f32, (c.y - f.y) as f32);
        let (i0, j0) = (f.x as i64, f.y as i64);
        let mut out = Bilinear {
            index: [0; 4],
            weight: [0.0; 4],
        };
        let corners = [
            (i0, j0, (1.0 - fx) * (1.0 - fy)),
            (i0 + 1, j0, fx * (1.0 - fy)),
            (i0, j0 + 1, (1.0 - fx) * fy),
            (i0 + 1, j0 + 1, fx * fy),
        ];
        let n = GRID_SIDE as i64;
        for (k, (i, j, w)) in corners.into_iter().enumerate() {
            if (0..n).contains(&i) && (0..n).contains(&j) {
                out.index[k] = Self::index(i as usize, j as usize);
                out.weight[k] = w;
            }
        }
        Some(out)
    }

    /// Adds `weight * exp(-|x - p|^2 / (2 sigma^2))` to every cell whose centre `x` lies
    /// within 3 sigma of `p` (object frame, metres); other cells are untouched.
    ///
    /// Panics if `sigma_m` is not finite and positive. A non-finite `p` adds nothing.
    #[track_caller]
    pub fn add_gaussian(&mut self, p: DVec2, sigma_m: f64, weight: f32) {
        let cells = &mut self.cells;
        gaussian_cells(self.cell_size_m, self.origin_m, p, sigma_m, |k, g| {
            cells[k] += weight * g;
        });
    }

    /// Writes the header (`kind`, `alpha_deg`, `seq`, this grid's geometry) and the cells
    /// straight into `out`, typically a loaned shared-memory sample: no intermediate copy.
    /// A lone grid belongs to no set: `alpha_count` and the layer's fields are 0.
    pub fn write_into(&self, kind: GridKind, alpha_deg: f64, seq: u64, out: &mut GradientGrid) {
        out.header = self.header(kind, alpha_deg, seq);
        out.cells.copy_from_slice(&self.cells);
    }

    /// The payload header describing this grid, its set and layer fields 0.
    pub(crate) fn header(&self, kind: GridKind, alpha_deg: f64, seq: u64) -> GridHeader {
        GridHeader {
            seq,
            kind: kind as u32,
            alpha_count: 0,
            width: GRID_SIDE as u32,
            height: GRID_SIDE as u32,
            alpha_deg,
            cell_size_m: self.cell_size_m,
            origin_x_m: self.origin_m.x,
            origin_y_m: self.origin_m.y,
            shape_scale: 0.0,
            max_rotation_rad: 0.0,
            pushes: 0,
            border_points: 0,
        }
    }

    /// A grid read from a payload, after checking its header (size, kind, geometry).
    pub fn from_payload(payload: &GradientGrid) -> Result<Grid, GridPayloadReadError> {
        let h = &payload.header;
        check_header(h)?;
        Ok(Grid {
            cells: payload.cells.to_vec(),
            cell_size_m: h.cell_size_m,
            origin_m: DVec2::new(h.origin_x_m, h.origin_y_m),
        })
    }
}

/// The origin of a grid of `cell_size_m` cells centred on the object frame's origin.
pub(crate) fn centred_origin(cell_size_m: f64) -> DVec2 {
    DVec2::splat(-(GRID_SIDE as f64 * cell_size_m / 2.0))
}

/// Checks what every grid payload must satisfy (size, kind, geometry); returns its kind.
pub(crate) fn check_header(h: &GridHeader) -> Result<GridKind, GridPayloadReadError> {
    if h.width as usize != GRID_SIDE || h.height as usize != GRID_SIDE {
        return Err(GridPayloadReadError::WrongSize {
            width: h.width,
            height: h.height,
        });
    }
    let kind = GridKind::from_u32(h.kind).ok_or(GridPayloadReadError::UnknownKind(h.kind))?;
    if !(h.cell_size_m.is_finite() && h.cell_size_m > 0.0) {
        return Err(GridPayloadReadError::BadCellSize(h.cell_size_m));
    }
    if !(h.origin_x_m.is_finite() && h.origin_y_m.is_finite()) {
        return Err(GridPayloadReadError::BadOrigin(h.origin_x_m, h.origin_y_m));
    }
    Ok(kind)
}

/// Calls `f(index, g)` for every cell (of a grid of `cell_size_m` cells with corner
/// `origin_m`) whose centre lies within 3 sigma of `p`, `g` the unit-peak Gaussian there.
#[track_caller]
pub(crate) fn gaussian_cells(
    cell_size_m: f64,
    origin_m: DVec2,
    p: DVec2,
    sigma_m: f64,
    mut f: impl FnMut(usize, f32),
) {
    assert!(
        sigma_m.is_finite() && sigma_m > 0.0,
        "sigma must be finite and positive, got {sigma_m}"
    );
    let c = (p - origin_m) / cell_size_m - 0.5;
    if !c.is_finite() {
        return;
    }
    let r = 3.0 * sigma_m / cell_size_m;
    let max = GRID_SIDE as f64 - 1.0;
    let lo = (c - r).ceil().max(DVec2::ZERO);
    let hi = (c + r).floor().min(DVec2::splat(max));
    if lo.x > hi.x || lo.y > hi.y {
        return;
    }
    let inv_two_var = 1.0 / (2.0 * (sigma_m / cell_size_m).powi(2));
    let r2 = r * r;
    for j in lo.y as usize..=hi.y as usize {
        let dy = j as f64 - c.y;
        for i in lo.x as usize..=hi.x as usize {
            let dx = i as f64 - c.x;
            let d2 = dx * dx + dy * dy;
            if d2 <= r2 {
                f(Grid::index(i, j), (-d2 * inv_two_var).exp() as f32);
            }
        }
    }
}
