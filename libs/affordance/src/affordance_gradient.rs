use agp_shared_types::{GradientGrid, GridHeader, GridKind, Pose2};
use glam::DVec2;

use crate::Grid;

/// Least interpolated push weight (sum of unit-peak Gaussians) at a contact point for
/// [`AffordanceGradient::predict`] to answer: about one trial 3.3 sigma (8 mm at the
/// default 2.5 mm push sigma) away.
pub const MIN_PREDICTION_EVIDENCE: f64 = 0.005;

/// Fraction of the largest value of the combined shape gradient above which
/// [`AffordanceGradient::contact_candidates`] takes a cell for the object's border.
pub const CONTACT_BORDER_THRESHOLD: f32 = 0.3;

/// Fraction of a normalised S's peak above which a band along a push's heading line is the
/// object's border: where [`crate::border_crossing`] locates aim points, in learning (the
/// estimator keys each trial by it) and in prediction alike. Lower than
/// [`CONTACT_BORDER_THRESHOLD`]: a concave corner, which the IR sees only obliquely from
/// outside, leaves a band of about a fifth of the peak (the L's inner corner); at 0.3 a
/// push into it was keyed to the face behind, and the L's learned effects there mixed
/// pushes from opposite sides (displacement error 0.26 of the displacement, 0.14 at 0.15).
pub const AIM_BORDER_THRESHOLD: f32 = 0.15;

/// Two alphas closer than this (degrees) are the same alpha.
pub(crate) const ALPHA_EPS_DEG: f64 = 1e-6;

/// A cell whose weight is not above this has no mean (its mean is written as 0).
const MIN_CELL_WEIGHT: f32 = 1e-6;

/// An alpha that is not one of the alphas an affordance gradient was learned for.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("alpha {alpha_deg} deg is not one of the learned alphas")]
pub struct UnknownAlphaError {
    /// The alpha asked for, degrees.
    pub alpha_deg: f64,
}

/// The grids one alpha's layer keeps, in file order. Sums are of Gaussian-weighted values,
/// weights of the Gaussians themselves (unit peak), so `sum / weight` is a weighted mean.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(usize)]
pub(crate) enum LayerGrid {
    /// S before normalisation: the sum of Gaussians at border points.
    ShapeEvidence = 0,
    /// Weight of every push (shared by displacement and signed rotation).
    PushWeight,
    /// Sum of weighted displacement x (m).
    DisplacementX,
    /// Sum of weighted displacement y (m).
    DisplacementY,
    /// Sum of weighted squared displacement length (m^2).
    DisplacementSq,
    /// Sum of weighted signed rotation (rad).
    Rotation,
    /// Sum of weighted squared rotation (rad^2).
    RotationSq,
    /// Sum of weighted counter-clockwise rotations (R+, rad).
    RotationPos,
    /// Weight of the counter-clockwise rotations.
    RotationPosWeight,
    /// Sum of weighted clockwise rotations (R-, rad, negative).
    RotationNeg,
    /// Weight of the clockwise rotations.
    RotationNegWeight,
    /// Weight of every push that meets the border past the centroid (see
    /// [`meets_past_centroid`]); the five below are its weighted sums, as the five after
    /// [`LayerGrid::PushWeight`] are for the pushes that meet it first.
    PastPushWeight,
    /// Past the centroid: sum of weighted displacement x (m).
    PastDisplacementX,
    /// Past the centroid: sum of weighted displacement y (m).
    PastDisplacementY,
    /// Past the centroid: sum of weighted squared displacement length (m^2).
    PastDisplacementSq,
    /// Past the centroid: sum of weighted signed rotation (rad).
    PastRotation,
    /// Past the centroid: sum of weighted squared rotation (rad^2).
    PastRotationSq,
}

/// Number of grids in a layer.
pub(crate) const LAYER_GRIDS: usize = 17;

/// The grids a push's prediction is read from: weight, displacement x and y, squared
/// displacement, signed rotation, squared rotation, for the pushes that meet the border
/// before the centroid (`past = false`) or past it.
pub(crate) const fn prediction_grids(past: bool) -> [LayerGrid; 6] {
    if past {
        [
            LayerGrid::PastPushWeight,
            LayerGrid::PastDisplacementX,
            LayerGrid::PastDisplacementY,
            LayerGrid::PastDisplacementSq,
            LayerGrid::PastRotation,
            LayerGrid::PastRotationSq,
        ]
    } else {
        [
            LayerGrid::PushWeight,
            LayerGrid::DisplacementX,
            LayerGrid::DisplacementY,
            LayerGrid::DisplacementSq,
            LayerGrid::Rotation,
            LayerGrid::RotationSq,
        ]
    }
}

/// Whether a push heading along `heading_obj` (object frame, any length) meets the border
/// at `contact_point_obj` past the centroid: beyond the point where its heading line passes
/// closest to the centroid. Such a push and one that meets the border first can share an
/// aim point and an alpha and still arrive tens of degrees apart (the two tangents from the
/// aim point to the circle of radius `r sin(alpha)` round the centroid, `r` the start
/// circle's radius): the gradient keeps their effects apart. On the L, whose long face lies
/// nearer the centroid (22.5 mm) than such a line passes it (30 mm at 15 deg), about a
/// fifth of the learning benchmark's unseen pushes meet the border past the centroid;
/// keyed together with the others, the L's median rotation error of unseen pushes was
/// 4.43 deg (mean over seeds 1-10), apart 3.27.
pub fn meets_past_centroid(contact_point_obj: DVec2, heading_obj: DVec2) -> bool {
    contact_point_obj.dot(heading_obj) > 0.0
}

// One published grid per layer grid: a layer is rebuilt from the grids of its alpha.
const _: () = assert!(LAYER_GRIDS == agp_shared_types::GRIDS_PER_ALPHA);

/// How a published grid of a [`GridKind`] holds a layer grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum GridEncoding {
    /// Divided by its largest cell (the layer's shape scale).
    Normalised,
    /// As it is (a weight).
    Plain,
    /// A weighted sum divided by this weight: a weighted mean, 0 where the weight is not
    /// above [`MIN_CELL_WEIGHT`].
    MeanOver(LayerGrid),
}

/// The layer grid a published grid of `kind` holds, and how: the one table the writer
/// ([`AffordanceGradient::write_component`]) and the reader
/// ([`AffordanceGradient::from_grids`]) share.
pub(crate) fn grid_encoding(kind: GridKind) -> (LayerGrid, GridEncoding) {
    use GridEncoding::{MeanOver, Normalised, Plain};
    match kind {
        GridKind::Shape => (LayerGrid::ShapeEvidence, Normalised),
        GridKind::PositionX => (LayerGrid::DisplacementX, MeanOver(LayerGrid::PushWeight)),
        GridKind::PositionY => (LayerGrid::DisplacementY, MeanOver(LayerGrid::PushWeight)),
        GridKind::RotationPos => (
            LayerGrid::RotationPos,
            MeanOver(LayerGrid::RotationPosWeight),
        ),
        GridKind::RotationNeg => (
            LayerGrid::RotationNeg,
            MeanOver(LayerGrid::RotationNegWeight),
        ),
        GridKind::PushWeight => (LayerGrid::PushWeight, Plain),
        GridKind::Rotation => (LayerGrid::Rotation, MeanOver(LayerGrid::PushWeight)),
        GridKind::DisplacementSqMean => {
            (LayerGrid::DisplacementSq, MeanOver(LayerGrid::PushWeight))
        }
        GridKind::RotationSqMean => (LayerGrid::RotationSq, MeanOver(LayerGrid::PushWeight)),
        GridKind::RotationPosWeight => (LayerGrid::RotationPosWeight, Plain),
        GridKind::RotationNegWeight => (LayerGrid::RotationNegWeight, Plain),
        GridKind::PastPushWeight => (LayerGrid::PastPushWeight, Plain),
        GridKind::PastPositionX => (
            LayerGrid::PastDisplacementX,
            MeanOver(LayerGrid::PastPushWeight),
        ),
        GridKind::PastPositionY => (
            LayerGrid::PastDisplacementY,
            MeanOver(LayerGrid::PastPushWeight),
        ),
        GridKind::PastRotation => (LayerGrid::PastRotation, MeanOver(LayerGrid::PastPushWeight)),
        GridKind::PastDisplacementSqMean => (
            LayerGrid::PastDisplacementSq,
            MeanOver(LayerGrid::PastPushWeight),
        ),
        GridKind::PastRotationSqMean => (
            LayerGrid::PastRotationSq,
            MeanOver(LayerGrid::PastPushWeight),
        ),
    }
}

/// What one alpha's pushes taught.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct AlphaLayer {
    pub(crate) alpha_deg: f64,
    pub(crate) grids: [Grid; LAYER_GRIDS],
    /// Largest |rotation| of a single push, rad.
    pub(crate) max_rotation_rad: f64,
    pub(crate) pushes: u64,
    pub(crate) border_points: u64,
}

impl AlphaLayer {
    pub(crate) fn new(alpha_deg: f64, cell_size_m: f64) -> Self {
        Self {
            alpha_deg,
            grids: std::array::from_fn(|_| Grid::centred(cell_size_m)),
            max_rotation_rad: 0.0,
            pushes: 0,
            border_points: 0,
        }
    }

    pub(crate) fn grid(&self, g: LayerGrid) -> &Grid {
        &self.grids[g as usize]
    }

    /// The prediction at aim point `p` from the pushes that meet the border first, or
    /// (`past`) from those that meet it past the centroid.
    pub(crate) fn predict(&self, p: DVec2, past: bool) -> Option<Prediction> {
        let [weight, dx, dy, dsq, rot, rsq] = prediction_grids(past);
        let b = self.grid(weight).bilinear(p)?;
        let at = |g: LayerGrid| f64::from(b.apply(self.grid(g).cells()));
        let w = at(weight);
        if w < MIN_PREDICTION_EVIDENCE {
            return None;
        }
        let displacement = DVec2::new(at(dx), at(dy)) / w;
        let displacement_var = at(dsq) / w - displacement.length_squared();
        let rotation_rad = at(rot) / w;
        let rotation_var = at(rsq) / w - rotation_rad * rotation_rad;
        Some(Prediction {
            displacement,
            rotation_rad,
            confidence: 1.0 - (-w).exp(),
            displacement_spread_m: displacement_var.max(0.0).sqrt(),
            rotation_spread_rad: rotation_var.max(0.0).sqrt(),
        })
    }

    /// Writes the cells of component `kind` (normalised S, a weight or a weighted mean, see
    /// [`grid_encoding`]) into `out`.
    fn write_cells(&self, kind: GridKind, out: &mut [f32]) {
        let (grid, encoding) = grid_encoding(kind);
        let cells = self.grid(grid).cells();
        match encoding {
            GridEncoding::Normalised => normalised_into(cells, out),
            GridEncoding::Plain => out.copy_from_slice(cells),
            GridEncoding::MeanOver(weight) => {
                let w = self.grid(weight).cells();
                for ((o, &s), &w) in out.iter_mut().zip(cells).zip(w) {
                    *o = if w > MIN_CELL_WEIGHT { s / w } else { 0.0 };
                }
            }
        }
    }

    /// What the shape evidence is divided by in [`GridKind::Shape`]: its largest cell.
    pub(crate) fn shape_scale(&self) -> f32 {
        max_cell(self.grid(LayerGrid::ShapeEvidence).cells())
    }
}

/// The largest cell, at least 0 (NaN cells are ignored).
fn max_cell(cells: &[f32]) -> f32 {
    cells.iter().copied().fold(0.0_f32, f32::max)
}

/// `out = cells / max(cells)` (all zeros when the max is not positive).
fn normalised_into(cells: &[f32], out: &mut [f32]) {
    let max = max_cell(cells);
    if max > 0.0 {
        let inv = 1.0 / max;
        out.iter_mut().zip(cells).for_each(|(o, &c)| *o = c * inv);
    } else {
        out.fill(0.0);
    }
}

/// What a push from a contact point is predicted to do to the object.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prediction {
    /// Displacement of the centroid, metres, in the object's frame as it was before the push.
    pub displacement: DVec2,
    /// Signed rotation, radians, counter-clockwise positive.
    pub rotation_rad: f64,
    /// `1 - exp(-w)` with `w` the interpolated push weight (about the number of trials
    /// within one sigma), scaled by the alpha interpolation when only one side has data:
    /// about 0.63 on top of a single trial, towards 1 with more.
    pub confidence: f64,
    /// Weighted standard deviation of the displacements that went into the prediction, m.
    pub displacement_spread_m: f64,
    /// Weighted standard deviation of the rotations that went into the prediction, rad.
    pub rotation_spread_rad: f64,
}

impl Prediction {
    /// The object's pose after the push, from its pose `before` (any frame).
    pub fn apply_to(&self, before: Pose2) -> Pose2 {
        let c = DVec2::new(before.x, before.y)
            + DVec2::from_angle(before.theta).rotate(self.displacement);
        Pose2::new(c.x, c.y, before.theta + self.rotation_rad)
    }

    fn lerp(&self, other: &Prediction, t: f64) -> Prediction {
        let l = |a: f64, b: f64| a + (b - a) * t;
        Prediction {
            displacement: self.displacement.lerp(other.displacement, t),
            rotation_rad: l(self.rotation_rad, other.rotation_rad),
            confidence: l(self.confidence, other.confidence),
            displacement_spread_m: l(self.displacement_spread_m, other.displacement_spread_m),
            rotation_spread_rad: l(self.rotation_spread_rad, other.rotation_spread_rad),
        }
    }
}

/// An object's affordance gradients: for each learned alpha (the push direction's deviation
/// from the centroid, degrees) the tuple (S, P, R+, R-) of the paper, kept as weighted sums
/// and weights so that values are Gaussian-weighted means of the trials.
///
/// All grids are in the object frame (centroid at the origin, default orientation), built
/// by [`AffordanceLearner`](crate::AffordanceLearner) and saved with
/// [`AffordanceGradient::save`].
///
/// # Rotation: R+, R- and the signed prediction
/// The paper files each push's rotation under R+ (counter-clockwise) or R- (clockwise) by
/// its sign and shows the two. Here they are kept for that display
/// ([`GridKind::RotationPos`], [`GridKind::RotationNeg`]: each a weighted mean of the
/// rotations of its sign only), but predictions use a third grid: the weighted mean of the
/// *signed* rotations of all pushes near the contact (published as [`GridKind::Rotation`]).
/// Where both signs occur (near a corner, where a push turns the object one way or the
/// other depending on which side of the corner it lands) the signed mean passes
/// continuously through zero as the contact moves across the corner, as the physics does,
/// instead of jumping between two magnitudes; how much the pushes there disagree is
/// reported as [`Prediction::rotation_spread_rad`].
#[derive(Debug, Clone, PartialEq)]
pub struct AffordanceGradient {
    pub(crate) object_name: String,
    pub(crate) cell_size_m: f64,
    /// Sorted by ascending alpha.
    pub(crate) layers: Vec<AlphaLayer>,
}

impl AffordanceGradient {
    /// An empty gradient. `alphas_deg` must be finite and distinct (checked by the callers).
    pub(crate) fn new(object_name: &str, alphas_deg: &[f64], cell_size_m: f64) -> Self {
        let mut layers: Vec<AlphaLayer> = alphas_deg
            .iter()
            .map(|&a| AlphaLayer::new(a, cell_size_m))
            .collect();
        layers.sort_by(|a, b| a.alpha_deg.total_cmp(&b.alpha_deg));
        Self {
            object_name: object_name.to_owned(),
            cell_size_m,
            layers,
        }
    }

    /// Name of the object the gradient was learned on.
    pub fn object_name(&self) -> &str {
        &self.object_name
    }

    /// Side of a grid cell, metres.
    pub fn cell_size_m(&self) -> f64 {
        self.cell_size_m
    }

    /// The learned alphas, degrees, ascending.
    pub fn alphas_deg(&self) -> impl Iterator<Item = f64> + '_ {
        self.layers.iter().map(|l| l.alpha_deg)
    }

    pub(crate) fn layer_index(&self, alpha_deg: f64) -> Option<usize> {
        self.layers
            .iter()
            .position(|l| (l.alpha_deg - alpha_deg).abs() < ALPHA_EPS_DEG)
    }

    fn layer(&self, alpha_deg: f64) -> Result<&AlphaLayer, UnknownAlphaError> {
        self.layer_index(alpha_deg)
            .map(|k| &self.layers[k])
            .ok_or(UnknownAlphaError { alpha_deg })
    }

    /// Number of pushes learned at `alpha_deg` (`None` if it is not a learned alpha).
    pub fn push_count(&self, alpha_deg: f64) -> Option<u64> {
        self.layer(alpha_deg).ok().map(|l| l.pushes)
    }

    /// Number of border points learned at `alpha_deg` (`None` if it is not a learned alpha).
    pub fn border_point_count(&self, alpha_deg: f64) -> Option<u64> {
        self.layer(alpha_deg).ok().map(|l| l.border_points)
    }

    /// Largest rotation (absolute, degrees) a single push produced at `alpha_deg`; `None` if
    /// it is not a learned alpha or no push was learned there.
    pub fn max_rotation_deg(&self, alpha_deg: f64) -> Option<f64> {
        let layer = self.layer(alpha_deg).ok()?;
        (layer.pushes > 0).then(|| layer.max_rotation_rad.to_degrees())
    }

    /// Predicts the effect of a push at `contact_point_obj` (object frame, metres) with the
    /// push direction deviated by `alpha_deg` from the centroid, for any contact point and
    /// any alpha between the smallest and largest learned ones.
    ///
    /// The push is one that meets the border before its heading line passes the centroid
    /// (see [`meets_past_centroid`]), as every push from the start circle's nearest point
    /// does. [`PushPredictor`](crate::PushPredictor) interpolates between alphas along the
    /// pushes of one start instead, which follows the physics better, and predicts the
    /// pushes that meet the border past the centroid too.
    ///
    /// In space: bilinear interpolation of the weighted sums and of the weights, then their
    /// ratio, i.e. a bilinear interpolation of the four cells' weighted means, each cell
    /// counting by its weight. In alpha: linear between the two learned alphas around
    /// `alpha_deg`; if only one of them has data at the point, its prediction with the
    /// confidence scaled by its interpolation weight.
    ///
    /// `None` when alpha is outside the learned range, an input is not finite, or no learned
    /// alpha around it has at least [`MIN_PREDICTION_EVIDENCE`] at the point.
    pub fn predict(&self, contact_point_obj: DVec2, alpha_deg: f64) -> Option<Prediction> {
        self.predict_branch(contact_point_obj, alpha_deg, false)
    }

    /// [`AffordanceGradient::predict`] for the pushes that meet the border before the
    /// centroid, or (`past`) past it.
    pub(crate) fn predict_branch(
        &self,
        contact_point_obj: DVec2,
        alpha_deg: f64,
        past: bool,
    ) -> Option<Prediction> {
        if !contact_point_obj.is_finite() || !alpha_deg.is_finite() {
            return None;
        }
        let first = self.layers.first()?;
        let last = self.layers.last()?;
        if alpha_deg < first.alpha_deg - ALPHA_EPS_DEG || alpha_deg > last.alpha_deg + ALPHA_EPS_DEG
        {
            return None;
        }
        if let Some(k) = self.layer_index(alpha_deg) {
            return self.layers[k].predict(contact_point_obj, past);
        }
        let hi = self.layers.iter().position(|l| l.alpha_deg > alpha_deg)?;
        let (a, b) = (&self.layers[hi - 1], &self.layers[hi]);
        let t = (alpha_deg - a.alpha_deg) / (b.alpha_deg - a.alpha_deg);
        Self::blend(
            a.predict(contact_point_obj, past),
            b.predict(contact_point_obj, past),
            t,
        )
    }

    /// Blends the predictions of two neighbouring alphas at interpolation weight `t` (0: the
    /// first): linear when both answer, else the one that does with its confidence scaled
    /// by its weight.
    pub(crate) fn blend(
        a: Option<Prediction>,
        b: Option<Prediction>,
        t: f64,
    ) -> Option<Prediction> {
        match (a, b) {
            (Some(pa), Some(pb)) => Some(pa.lerp(&pb, t)),
            (Some(pa), None) => Some(Prediction {
                confidence: pa.confidence * (1.0 - t),
                ..pa
            }),
            (None, Some(pb)) => Some(Prediction {
                confidence: pb.confidence * t,
                ..pb
            }),
            (None, None) => None,
        }
    }

    /// Writes component `kind` of alpha `alpha_deg` straight into `out` (typically a loaned
    /// shared-memory sample): S normalised to [0, 1], P, R+ / R- and the statistics as
    /// weighted means (0 where no push was learned), the weights as they are (see
    /// [`GridKind`]). No intermediate grid.
    ///
    /// The header describes the grid and its place in the set of sequence number `seq`
    /// (every kind of every alpha: [`AffordanceGradient::from_grids`] rebuilds the gradient
    /// from it): the number of alphas, S's scale and the alpha's counters.
    pub fn write_component(
        &self,
        alpha_deg: f64,
        kind: GridKind,
        seq: u64,
        out: &mut GradientGrid,
    ) -> Result<(), UnknownAlphaError> {
        let layer = self.layer(alpha_deg)?;
        let g = layer.grid(LayerGrid::ShapeEvidence);
        out.header = GridHeader {
            alpha_count: self.layers.len() as u32,
            shape_scale: f64::from(layer.shape_scale()),
            max_rotation_rad: layer.max_rotation_rad,
            pushes: layer.pushes,
            border_points: layer.border_points,
            ..g.header(kind, layer.alpha_deg, seq)
        };
        layer.write_cells(kind, &mut out.cells);
        Ok(())
    }

    /// Component `kind` of alpha `alpha_deg` as a new grid (see
    /// [`AffordanceGradient::write_component`] for the values).
    pub fn component(&self, alpha_deg: f64, kind: GridKind) -> Result<Grid, UnknownAlphaError> {
        let layer = self.layer(alpha_deg)?;
        let mut grid = layer.grid(LayerGrid::ShapeEvidence).zeros_like();
        layer.write_cells(kind, grid.cells_mut());
        Ok(grid)
    }

    /// The shape gradient S learned over all alphas together, normalised to [0, 1]: what
    /// [`ShapeMatcher`](crate::ShapeMatcher) matches against.
    pub fn combined_shape(&self) -> Grid {
        let mut sum = Grid::centred(self.cell_size_m);
        for layer in &self.layers {
            sum.add_grid(layer.grid(LayerGrid::ShapeEvidence));
        }
        let mut out = sum.zeros_like();
        normalised_into(sum.cells(), out.cells_mut());
        out
    }

    /// Candidate contact points (object frame, metres) for a push search: `count` rays from
    /// the centroid at even angles (ray k at `2 pi k / count` from +x); on each, walking in
    /// from the grid's edge, the first band of the combined S above
    /// [`CONTACT_BORDER_THRESHOLD`], located at its centroid (the weight of a sample being
    /// its excess over the threshold; unlike the band's maximum, unbiased by the bilinear
    /// interpolation between cells). Rays that meet no border are skipped, so fewer than
    /// `count` points may come back, in angle order. Allocates (the combined S and the
    /// result): compute once per gradient, not per push.
    pub fn contact_candidates(&self, count: usize) -> Vec<DVec2> {
        let shape = self.combined_shape();
        let mut out = Vec::with_capacity(count);
        let step = 0.25 * shape.cell_size_m();
        let r_max = 0.5 * shape.extent_m() - shape.cell_size_m();
        for k in 0..count {
            let u = DVec2::from_angle(std::f64::consts::TAU * k as f64 / count as f64);
            let mut r = r_max;
            let mut s = shape.sample(u * r);
            while r > 0.0 && s < CONTACT_BORDER_THRESHOLD {
                r -= step;
                s = shape.sample(u * r);
            }
            let (mut weight, mut moment) = (0.0_f64, 0.0_f64);
            while r > 0.0 && s >= CONTACT_BORDER_THRESHOLD {
                let w = f64::from(s - CONTACT_BORDER_THRESHOLD);
                weight += w;
                moment += w * r;
                r -= step;
                s = shape.sample(u * r);
            }
            if weight > 0.0 {
                out.push(u * (moment / weight));
            }
        }
        out
    }
}
