use agp_shared_types::{GRIDS_PER_ALPHA, GradientGrid, GridHeader, GridKind, MAX_GRID_ALPHAS};
use glam::DVec2;

use crate::affordance_gradient::{ALPHA_EPS_DEG, AlphaLayer, GridEncoding, grid_encoding};
use crate::grid::{centred_origin, check_header};
use crate::{AffordanceGradient, Grid, GridPayloadReadError};

/// Why a set of published grids could not be rebuilt into an [`AffordanceGradient`].
///
/// A set is what [`AffordanceGradient::write_component`] writes for one sequence number:
/// every [`GridKind`] of every alpha, once, all with the same cell size and origin.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GradientFromGridsError {
    /// No grid at all.
    #[error("no grid to rebuild from: a set holds {GRIDS_PER_ALPHA} grids per alpha")]
    Empty,
    /// A header fails the checks of every grid payload (size, kind, geometry).
    #[error("a grid has an invalid header: {0}")]
    BadHeader(#[from] GridPayloadReadError),
    /// Grids of two publications.
    #[error(
        "a grid of seq {found} among grids of seq {expected}: rebuild from the grids of one publication"
    )]
    MixedSeq {
        /// The seq of the set's first grid.
        expected: u64,
        /// The seq of the grid refused.
        found: u64,
    },
    /// A grid that belongs to no set (written alone, its alpha count 0).
    #[error(
        "the {kind:?} grid of alpha {alpha_deg} deg belongs to no set (alpha count 0): publish gradients with `write_component`"
    )]
    NotInSet {
        /// The grid's kind.
        kind: GridKind,
        /// The grid's alpha, degrees.
        alpha_deg: f64,
    },
    /// The set announces more alphas than a set may hold.
    #[error("a set of {alpha_count} alphas: at most {MAX_GRID_ALPHAS} fit the grids topic")]
    TooManyAlphas {
        /// The alpha count of the header.
        alpha_count: u32,
    },
    /// Grids announce sets of different sizes.
    #[error(
        "grids of one seq announce sets of {expected} and {found} alphas: two publishers share the seq?"
    )]
    AlphaCountMismatch {
        /// The alpha count of the set's first grid.
        expected: u32,
        /// The alpha count of the grid refused.
        found: u32,
    },
    /// A grid's alpha is not finite.
    #[error("a grid has alpha {alpha_deg} deg, expected a finite angle")]
    BadAlpha {
        /// The alpha found.
        alpha_deg: f64,
    },
    /// A grid of one alpha more than the set announces.
    #[error("a grid of alpha {alpha_deg} deg beyond the {alpha_count} alphas its set announces")]
    ExtraAlpha {
        /// The grid's alpha, degrees.
        alpha_deg: f64,
        /// The alphas the set announces.
        alpha_count: u32,
    },
    /// A grid whose geometry is not the set's.
    #[error(
        "the {kind:?} grid of alpha {alpha_deg} deg has another cell size or origin than the set's first grid"
    )]
    GeometryMismatch {
        /// The grid's kind.
        kind: GridKind,
        /// The grid's alpha, degrees.
        alpha_deg: f64,
    },
    /// The grids are not centred on the object's centroid, as a gradient's are.
    #[error(
        "grids of {cell_size_m} m cells start at ({origin_x_m}, {origin_y_m}) m, not centred on the object's centroid"
    )]
    NotCentred {
        /// Cell size, metres.
        cell_size_m: f64,
        /// Corner of cell (0, 0), metres.
        origin_x_m: f64,
        /// Corner of cell (0, 0), metres.
        origin_y_m: f64,
    },
    /// A kind of one alpha appears twice.
    #[error("two {kind:?} grids of alpha {alpha_deg} deg: a set holds each kind of an alpha once")]
    Duplicate {
        /// The kind repeated.
        kind: GridKind,
        /// The alpha, degrees.
        alpha_deg: f64,
    },
    /// Fewer alphas have grids than the set announces.
    #[error("grids of {found} alphas, the set announces {expected}: the set is incomplete")]
    MissingAlphas {
        /// Alphas with at least one grid.
        found: usize,
        /// Alphas the set announces.
        expected: u32,
    },
    /// A kind of an alpha is missing.
    #[error("no {kind:?} grid of alpha {alpha_deg} deg: the set is incomplete")]
    MissingKind {
        /// The first kind missing.
        kind: GridKind,
        /// The alpha, degrees.
        alpha_deg: f64,
    },
    /// A grid's layer fields (S's scale, the counters) differ from its alpha's other grids.
    #[error(
        "the {kind:?} grid of alpha {alpha_deg} deg disagrees with the alpha's other grids on S's scale or the counters"
    )]
    LayerMismatch {
        /// The grid's kind.
        kind: GridKind,
        /// The alpha, degrees.
        alpha_deg: f64,
    },
    /// S's scale or the largest rotation is negative or not finite.
    #[error(
        "alpha {alpha_deg} deg has S scale {shape_scale} and largest rotation {max_rotation_rad} rad, expected finite and not negative"
    )]
    BadLayer {
        /// The alpha, degrees.
        alpha_deg: f64,
        /// The header's S scale.
        shape_scale: f64,
        /// The header's largest rotation, rad.
        max_rotation_rad: f64,
    },
    /// A cell is not finite.
    #[error("the {kind:?} grid of alpha {alpha_deg} deg holds a non-finite cell")]
    NonFiniteCell {
        /// The grid's kind.
        kind: GridKind,
        /// The alpha, degrees.
        alpha_deg: f64,
    },
}

/// Every kind received.
const ALL_KINDS: u32 = (1 << GRIDS_PER_ALPHA) - 1;

/// What every grid of a set shares.
#[derive(Debug, Clone, Copy, PartialEq)]
struct SetHeader {
    seq: u64,
    alpha_count: u32,
    cell_size_m: f64,
    origin_m: DVec2,
}

/// One alpha's layer as its grids arrive: the weighted means are kept as received until
/// [`GridSetAssembler::finish`] multiplies them by their weights.
#[derive(Debug)]
struct PartialLayer {
    layer: AlphaLayer,
    shape_scale: f64,
    /// Bit `kind as u32` set once that kind arrived.
    received: u32,
}

impl PartialLayer {
    fn matches(&self, h: &GridHeader) -> bool {
        self.shape_scale == h.shape_scale
            && self.layer.max_rotation_rad == h.max_rotation_rad
            && self.layer.pushes == h.pushes
            && self.layer.border_points == h.border_points
    }

    fn first_missing(&self) -> Option<GridKind> {
        GridKind::ALL
            .into_iter()
            .find(|&k| self.received & (1 << k as u32) == 0)
    }

    /// The layer, each weighted sum rebuilt as its received mean times its weight.
    fn into_layer(self) -> AlphaLayer {
        let mut layer = self.layer;
        for kind in GridKind::ALL {
            if let (sum, GridEncoding::MeanOver(weight)) = grid_encoding(kind) {
                let (sum, weight) = sum_and_weight(&mut layer.grids, sum as usize, weight as usize);
                sum.cells_mut()
                    .iter_mut()
                    .zip(weight.cells())
                    .for_each(|(s, &w)| *s *= w);
            }
        }
        layer
    }
}

/// Grid `sum` mutable beside grid `weight` of the same layer.
fn sum_and_weight(grids: &mut [Grid], sum: usize, weight: usize) -> (&mut Grid, &Grid) {
    assert_ne!(sum, weight, "a mean is not over its own grid");
    if sum < weight {
        let (lo, hi) = grids.split_at_mut(weight);
        (&mut lo[sum], &hi[0])
    } else {
        let (lo, hi) = grids.split_at_mut(sum);
        (&mut hi[0], &lo[weight])
    }
}

/// Rebuilds an [`AffordanceGradient`] from the grids of one published set, one grid at a
/// time, as they arrive: each grid's cells go straight into the gradient being rebuilt, so
/// a reader of shared memory can release each sample at once.
///
/// [`AffordanceGradient::from_grids`] is this over a whole set at once. A reader that
/// follows republications checks [`GridSetAssembler::seq`] before adding and calls
/// [`GridSetAssembler::clear`] when a grid of another seq comes.
#[derive(Debug, Default)]
pub struct GridSetAssembler {
    set: Option<SetHeader>,
    layers: Vec<PartialLayer>,
}

impl GridSetAssembler {
    /// An assembler holding no grid.
    pub fn new() -> Self {
        Self::default()
    }

    /// The seq of the set being assembled (`None` before its first grid).
    pub fn seq(&self) -> Option<u64> {
        self.set.map(|s| s.seq)
    }

    /// Grids added to the set so far.
    pub fn grid_count(&self) -> usize {
        self.layers
            .iter()
            .map(|l| l.received.count_ones() as usize)
            .sum()
    }

    /// Grids of the whole set, as its grids announce (`None` before its first grid).
    pub fn expected_grid_count(&self) -> Option<usize> {
        self.set.map(|s| s.alpha_count as usize * GRIDS_PER_ALPHA)
    }

    /// Whether every kind of every alpha the set announces arrived.
    pub fn is_complete(&self) -> bool {
        self.set.is_some_and(|s| {
            self.layers.len() == s.alpha_count as usize
                && self.layers.iter().all(|l| l.received == ALL_KINDS)
        })
    }

    /// Forgets the set under way.
    pub fn clear(&mut self) {
        self.set = None;
        self.layers.clear();
    }

    /// Adds one grid of the set: checks its header against the set's (seq, geometry, alpha
    /// count, its alpha's S scale and counters), then copies its cells in (S scaled back to
    /// its evidence). A grid refused leaves the assembler as it was.
    pub fn add(&mut self, grid: &GradientGrid) -> Result<(), GradientFromGridsError> {
        let h = &grid.header;
        let kind = check_header(h)?;
        let alpha_deg = h.alpha_deg;
        if !alpha_deg.is_finite() {
            return Err(GradientFromGridsError::BadAlpha { alpha_deg });
        }
        if h.alpha_count == 0 {
            return Err(GradientFromGridsError::NotInSet { kind, alpha_deg });
        }
        if h.alpha_count as usize > MAX_GRID_ALPHAS {
            return Err(GradientFromGridsError::TooManyAlphas {
                alpha_count: h.alpha_count,
            });
        }
        if !(h.shape_scale.is_finite()
            && h.shape_scale >= 0.0
            && h.max_rotation_rad.is_finite()
            && h.max_rotation_rad >= 0.0)
        {
            return Err(GradientFromGridsError::BadLayer {
                alpha_deg,
                shape_scale: h.shape_scale,
                max_rotation_rad: h.max_rotation_rad,
            });
        }
        let origin_m = DVec2::new(h.origin_x_m, h.origin_y_m);
        match self.set {
            None if origin_m != centred_origin(h.cell_size_m) => {
                return Err(GradientFromGridsError::NotCentred {
                    cell_size_m: h.cell_size_m,
                    origin_x_m: h.origin_x_m,
                    origin_y_m: h.origin_y_m,
                });
            }
            None => {}
            Some(set) => {
                if h.seq != set.seq {
                    return Err(GradientFromGridsError::MixedSeq {
                        expected: set.seq,
                        found: h.seq,
                    });
                }
                if h.cell_size_m != set.cell_size_m || origin_m != set.origin_m {
                    return Err(GradientFromGridsError::GeometryMismatch { kind, alpha_deg });
                }
                if h.alpha_count != set.alpha_count {
                    return Err(GradientFromGridsError::AlphaCountMismatch {
                        expected: set.alpha_count,
                        found: h.alpha_count,
                    });
                }
            }
        }
        let bit = 1 << kind as u32;
        let index = self
            .layers
            .iter()
            .position(|l| (l.layer.alpha_deg - alpha_deg).abs() < ALPHA_EPS_DEG);
        match index {
            Some(k) if self.layers[k].received & bit != 0 => {
                return Err(GradientFromGridsError::Duplicate { kind, alpha_deg });
            }
            Some(k) if !self.layers[k].matches(h) => {
                return Err(GradientFromGridsError::LayerMismatch { kind, alpha_deg });
            }
            Some(_) => {}
            None if self.layers.len() >= h.alpha_count as usize => {
                return Err(GradientFromGridsError::ExtraAlpha {
                    alpha_deg,
                    alpha_count: h.alpha_count,
                });
            }
            None => {}
        }
        if grid.cells.iter().any(|c| !c.is_finite()) {
            return Err(GradientFromGridsError::NonFiniteCell { kind, alpha_deg });
        }

        // Accepted: from here on nothing fails.
        self.set.get_or_insert(SetHeader {
            seq: h.seq,
            alpha_count: h.alpha_count,
            cell_size_m: h.cell_size_m,
            origin_m,
        });
        let k = index.unwrap_or_else(|| {
            let mut layer = AlphaLayer::new(alpha_deg, h.cell_size_m);
            layer.max_rotation_rad = h.max_rotation_rad;
            layer.pushes = h.pushes;
            layer.border_points = h.border_points;
            self.layers.push(PartialLayer {
                layer,
                shape_scale: h.shape_scale,
                received: 0,
            });
            self.layers.len() - 1
        });
        let partial = &mut self.layers[k];
        let (target, encoding) = grid_encoding(kind);
        let out = partial.layer.grids[target as usize].cells_mut();
        match encoding {
            GridEncoding::Normalised => {
                // The writer widened an f32 scale: this is that f32.
                let scale = partial.shape_scale as f32;
                out.iter_mut()
                    .zip(&grid.cells)
                    .for_each(|(o, &c)| *o = c * scale);
            }
            GridEncoding::Plain | GridEncoding::MeanOver(_) => out.copy_from_slice(&grid.cells),
        }
        partial.received |= bit;
        Ok(())
    }

    /// [`GridSetAssembler::add`], except that a grid the set under way already holds
    /// starts the set over from it: its publisher is sending the set again (a bridge
    /// resends the latest grids when its far end comes back), and the partial set from
    /// before would refuse every grid of the new one.
    pub fn add_or_start_over(&mut self, grid: &GradientGrid) -> Result<(), GradientFromGridsError> {
        match self.add(grid) {
            Err(GradientFromGridsError::Duplicate { .. }) => {
                self.clear();
                self.add(grid)
            }
            other => other,
        }
    }

    /// The rebuilt gradient of `object_name`, once the set is complete; the assembler is
    /// then empty, ready for the next set. An incomplete set stays as it is and says what
    /// it lacks.
    pub fn finish(
        &mut self,
        object_name: &str,
    ) -> Result<AffordanceGradient, GradientFromGridsError> {
        let set = self.set.ok_or(GradientFromGridsError::Empty)?;
        if self.layers.len() < set.alpha_count as usize {
            return Err(GradientFromGridsError::MissingAlphas {
                found: self.layers.len(),
                expected: set.alpha_count,
            });
        }
        for l in &self.layers {
            if let Some(kind) = l.first_missing() {
                return Err(GradientFromGridsError::MissingKind {
                    kind,
                    alpha_deg: l.layer.alpha_deg,
                });
            }
        }
        self.set = None;
        let mut layers: Vec<AlphaLayer> = self
            .layers
            .drain(..)
            .map(PartialLayer::into_layer)
            .collect();
        layers.sort_by(|a, b| a.alpha_deg.total_cmp(&b.alpha_deg));
        Ok(AffordanceGradient {
            object_name: object_name.to_owned(),
            cell_size_m: set.cell_size_m,
            layers,
        })
    }
}

impl AffordanceGradient {
    /// Rebuilds the gradient of `object_name` from one complete set of published grids (as
    /// [`AffordanceGradient::write_component`] writes them: the same seq, cell size and
    /// centred origin, every [`GridKind`] of every alpha exactly once, in any order).
    ///
    /// The rebuilt gradient predicts as the one that wrote the grids, up to f32 rounding:
    /// each weighted sum comes back as its mean times its weight, S's evidence as S times
    /// the header's scale, the counters from the header. (A cell whose weight was 1e-6 or
    /// less had no mean: its sums come back as 0; a learned gradient has none, a push
    /// adding at least exp(-4.5) within its 3 sigma and nothing beyond.)
    ///
    /// Reads the grids in place; allocates the gradient only. To rebuild while the grids
    /// arrive, one at a time, use [`GridSetAssembler`].
    pub fn from_grids<'g>(
        object_name: &str,
        grids: impl IntoIterator<Item = &'g GradientGrid>,
    ) -> Result<Self, GradientFromGridsError> {
        let mut set = GridSetAssembler::new();
        for grid in grids {
            set.add(grid)?;
        }
        set.finish(object_name)
    }
}
