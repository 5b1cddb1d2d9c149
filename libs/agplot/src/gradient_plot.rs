use std::io::Write;
use std::path::{Path, PathBuf};

use agp_affordance::{AffordanceGradient, Grid};
use agp_shared_types::{GRID_SIDE, GridKind};
use glam::DVec2;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::colour_map::{diverging_colour, sequential_colour, sequential_level};

/// Side of a panel's plotting area, pixels (square, so the object keeps its shape).
const PLOT_PX: i32 = 300;
/// Margin around a panel's chart, pixels.
const MARGIN_PX: i32 = 6;
/// Height of a panel's title strip, pixels.
const PANEL_TITLE_PX: i32 = 26;
/// Height of the x-axis label area, pixels.
const X_LABEL_PX: i32 = 36;
/// Width of the y-axis label area, pixels.
const Y_LABEL_PX: i32 = 52;
/// Width of a panel, pixels.
const PANEL_W_PX: i32 = MARGIN_PX + Y_LABEL_PX + PLOT_PX + MARGIN_PX;
/// Height of a panel (one row of the figure), pixels.
const PANEL_H_PX: i32 = PANEL_TITLE_PX + MARGIN_PX + PLOT_PX + X_LABEL_PX + MARGIN_PX;
/// Width of the colour bar column, pixels.
const BAR_COLUMN_W_PX: i32 = 120;
/// Height of the figure's title and subtitle, pixels.
const HEAD_PX: i32 = 60;
/// Panels per row: S, P, R+, R-.
const PANELS_PER_ROW: i32 = 4;

/// At most this many heat-map blocks along a side (larger crops average blocks of cells).
const MAX_HEAT_BLOCKS: usize = 80;
/// About this many arrows across a P panel.
const ARROWS_ACROSS: usize = 14;
/// Longest arrow, as a fraction of the spacing between arrows.
const ARROW_FILL: f64 = 0.9;
/// Rays cast for the learned border (see `AffordanceGradient::contact_candidates`).
const BORDER_RAYS: usize = 180;
/// Cells of margin around the data when cropping the grids.
const CROP_MARGIN_CELLS: usize = 3;
/// S below this counts as no border evidence when cropping.
const S_CROP_THRESHOLD: f32 = 0.02;

const FONT: &str = "sans-serif";
const BORDER_COLOUR: RGBColor = RGBColor(40, 40, 40);

/// Why a gradient could not be plotted.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// The gradient has no learned alpha, so there is no row to draw.
    #[error("the affordance gradient of `{0}` has no alpha to plot")]
    NoAlphas(String),
    /// Plotters refused to draw (should not happen with the in-memory SVG backend).
    #[error("cannot draw the plot: {0}")]
    Draw(String),
    /// The SVG could not be written (or moved into place) at `path`.
    #[error("cannot write plot `{}`", path.display())]
    Write {
        /// The SVG file asked for.
        path: PathBuf,
        /// What the file system said.
        #[source]
        source: std::io::Error,
    },
}

fn draw_error(e: impl std::fmt::Display) -> PlotError {
    PlotError::Draw(e.to_string())
}

/// The components of one learned alpha, read once.
struct AlphaView {
    alpha_deg: f64,
    pushes: u64,
    shape: Grid,
    position_x: Grid,
    position_y: Grid,
    rotation_pos: Grid,
    rotation_neg: Grid,
    /// Whether a prediction is made at the cell (enough pushes nearby), row-major.
    evidence: Vec<bool>,
}

impl AlphaView {
    fn new(ag: &AffordanceGradient, alpha_deg: f64) -> Result<Self, PlotError> {
        let component = |kind| ag.component(alpha_deg, kind).map_err(draw_error);
        let shape = component(GridKind::Shape)?;
        let mut evidence = vec![false; GRID_SIDE * GRID_SIDE];
        for j in 0..GRID_SIDE {
            for i in 0..GRID_SIDE {
                evidence[Grid::index(i, j)] =
                    ag.predict(shape.cell_centre_m(i, j), alpha_deg).is_some();
            }
        }
        Ok(Self {
            alpha_deg,
            pushes: ag.push_count(alpha_deg).unwrap_or(0),
            position_x: component(GridKind::PositionX)?,
            position_y: component(GridKind::PositionY)?,
            rotation_pos: component(GridKind::RotationPos)?,
            rotation_neg: component(GridKind::RotationNeg)?,
            shape,
            evidence,
        })
    }

    fn has_data(&self, i: usize, j: usize) -> bool {
        self.evidence[Grid::index(i, j)] || self.shape.get(i, j) >= S_CROP_THRESHOLD
    }

    /// Centroid displacement (metres) of a push from cell (i, j), if one was learned there.
    fn displacement(&self, i: usize, j: usize) -> Option<DVec2> {
        self.evidence[Grid::index(i, j)].then(|| {
            DVec2::new(
                f64::from(self.position_x.get(i, j)),
                f64::from(self.position_y.get(i, j)),
            )
        })
    }
}

/// The square of cells shown in every panel.
#[derive(Debug, Clone, Copy)]
struct Crop {
    i0: usize,
    j0: usize,
    side: usize,
}

impl Crop {
    /// The smallest square holding every cell with data in any view, plus a margin; the
    /// whole grid when there is no data.
    fn around(views: &[AlphaView]) -> Self {
        let (mut lo, mut hi) = ((GRID_SIDE, GRID_SIDE), (0, 0));
        for v in views {
            for j in 0..GRID_SIDE {
                for i in 0..GRID_SIDE {
                    if v.has_data(i, j) {
                        lo = (lo.0.min(i), lo.1.min(j));
                        hi = (hi.0.max(i), hi.1.max(j));
                    }
                }
            }
        }
        if lo.0 > hi.0 {
            return Self {
                i0: 0,
                j0: 0,
                side: GRID_SIDE,
            };
        }
        let side = (hi.0 - lo.0 + 1)
            .max(hi.1 - lo.1 + 1)
            .saturating_add(2 * CROP_MARGIN_CELLS)
            .min(GRID_SIDE);
        let start = |lo: usize, hi: usize| {
            let centre = (lo + hi).div_ceil(2);
            centre.saturating_sub(side / 2).min(GRID_SIDE - side)
        };
        Self {
            i0: start(lo.0, hi.0),
            j0: start(lo.1, hi.1),
            side,
        }
    }

    /// The x and y ranges shown, millimetres.
    fn ranges_mm(&self, grid: &Grid) -> (std::ops::Range<f64>, std::ops::Range<f64>) {
        let c = grid.cell_size_m() * 1000.0;
        let o = grid.origin_m() * 1000.0;
        let (x0, y0) = (o.x + self.i0 as f64 * c, o.y + self.j0 as f64 * c);
        let s = self.side as f64 * c;
        (x0..x0 + s, y0..y0 + s)
    }
}

/// Writes an SVG of `ag` to `path`: `title` on top, then a row per learned alpha (ascending)
/// with the shape gradient S (heat map, normalised per alpha), the position field P (one
/// arrow per few cells, from the contact cell along the centroid's displacement, one scale
/// for the figure), and R+ and R- (diverging map in degrees, counter-clockwise positive,
/// one scale for the figure, with a colour bar), each with the object's learned border
/// (the border found by [`AffordanceGradient::contact_candidates`]) and its centroid.
///
/// Axes are in millimetres in the object frame; all panels show the same square of cells,
/// cropped around the learned data. Cells where nothing was learned (no prediction) are
/// left blank in P, R+ and R-.
///
/// The file is written atomically: to a temporary file beside `path`, then renamed, so a
/// reader never sees half a plot and a failed write leaves no file behind.
pub fn plot_gradient(ag: &AffordanceGradient, title: &str, path: &Path) -> Result<(), PlotError> {
    let alphas: Vec<f64> = ag.alphas_deg().collect();
    if alphas.is_empty() {
        return Err(PlotError::NoAlphas(ag.object_name().to_owned()));
    }
    let views = alphas
        .iter()
        .map(|&a| AlphaView::new(ag, a))
        .collect::<Result<Vec<_>, _>>()?;
    let svg = render(ag, &views, title)?;
    write_atomically(path, svg.as_bytes()).map_err(|source| PlotError::Write {
        path: path.to_owned(),
        source,
    })
}

fn write_atomically(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let mut tmp = tempfile::Builder::new()
        .prefix(".agplot-")
        .suffix(".svg.tmp")
        .tempfile_in(dir)?;
    tmp.write_all(bytes)?;
    tmp.as_file().sync_all()?;
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        tmp.as_file()
            .set_permissions(std::fs::Permissions::from_mode(0o644))?;
    }
    tmp.persist(path).map_err(|e| e.error)?;
    Ok(())
}

/// Scales shared by every row.
struct Scales {
    /// Longest displacement anywhere, metres.
    max_displacement_m: f64,
    /// Half range of the rotation colour map, degrees.
    rotation_range_deg: f64,
}

impl Scales {
    fn of(views: &[AlphaView]) -> Self {
        let (mut d, mut r) = (0.0_f64, 0.0_f64);
        for v in views {
            for j in 0..GRID_SIDE {
                for i in 0..GRID_SIDE {
                    if let Some(disp) = v.displacement(i, j) {
                        d = d.max(disp.length());
                        let rp = f64::from(v.rotation_pos.get(i, j)).abs();
                        let rn = f64::from(v.rotation_neg.get(i, j)).abs();
                        r = r.max(rp.max(rn).to_degrees());
                    }
                }
            }
        }
        Self {
            max_displacement_m: d,
            rotation_range_deg: nice_ceiling(r),
        }
    }
}

/// The smallest of 1, 1.5, 2, 2.5, 3, 4, 5, 6, 8 times a power of ten that is at least `x`
/// (1 for `x` <= 0): a colour scale end with round tick labels that wastes little range.
fn nice_ceiling(x: f64) -> f64 {
    if !(x.is_finite() && x > 0.0) {
        return 1.0;
    }
    let p = 10f64.powf(x.log10().floor());
    [1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0]
        .into_iter()
        .map(|m| m * p)
        .find(|&v| v >= x * (1.0 - 1e-12))
        .unwrap_or(10.0 * p)
}

fn render(ag: &AffordanceGradient, views: &[AlphaView], title: &str) -> Result<String, PlotError> {
    let crop = Crop::around(views);
    let scales = Scales::of(views);
    let border_mm: Vec<(f64, f64)> = {
        let mut pts: Vec<(f64, f64)> = ag
            .contact_candidates(BORDER_RAYS)
            .into_iter()
            .map(|p| (p.x * 1000.0, p.y * 1000.0))
            .collect();
        if let Some(&first) = pts.first() {
            pts.push(first);
        }
        pts
    };
    let rows = views.len() as i32;
    let width = PANELS_PER_ROW * PANEL_W_PX + BAR_COLUMN_W_PX;
    let height = HEAD_PX + rows * PANEL_H_PX;
    let mut svg = String::new();
    {
        let root =
            SVGBackend::with_string(&mut svg, (width as u32, height as u32)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_error)?;
        let (head, body) = root.split_vertically(HEAD_PX);
        draw_head(&head, ag, title, &scales, width)?;
        let breaks: Vec<i32> = (1..rows).map(|k| k * PANEL_H_PX).collect();
        let row_areas = body.split_by_breakpoints::<i32, i32, [i32; 0], _>([], breaks);
        for (row, view) in row_areas.iter().zip(views) {
            let columns: Vec<i32> = (1..=PANELS_PER_ROW).map(|k| k * PANEL_W_PX).collect();
            let cells = row.split_by_breakpoints::<i32, i32, _, [i32; 0]>(columns, []);
            let panel = PanelContext {
                crop: &crop,
                view,
                border_mm: &border_mm,
            };
            panel.draw_shape(&cells[0])?;
            panel.draw_position(&cells[1], &scales)?;
            panel.draw_rotation(&cells[2], &view.rotation_pos, "R+", &scales)?;
            panel.draw_rotation(&cells[3], &view.rotation_neg, "R-", &scales)?;
            draw_rotation_bar(&cells[4], &scales)?;
        }
        root.present().map_err(draw_error)?;
    }
    Ok(svg)
}

fn draw_head(
    head: &DrawingArea<SVGBackend<'_>, Shift>,
    ag: &AffordanceGradient,
    title: &str,
    scales: &Scales,
    width: i32,
) -> Result<(), PlotError> {
    let centre = Pos::new(HPos::Center, VPos::Center);
    head.draw(&Text::new(
        title.to_owned(),
        (width / 2, 20),
        TextStyle::from((FONT, 22).into_font()).pos(centre),
    ))
    .map_err(draw_error)?;
    let subtitle = format!(
        "object `{}`, {:.1} mm cells, axes in mm (object frame, + centroid, line learned border); \
         S normalised per alpha; P arrows: centroid displacement of a push from the arrow's \
         cell, longest {:.1} mm; R+ / R-: rotation in degrees, counter-clockwise positive",
        ag.object_name(),
        ag.cell_size_m() * 1000.0,
        scales.max_displacement_m * 1000.0,
    );
    head.draw(&Text::new(
        subtitle,
        (width / 2, 46),
        TextStyle::from((FONT, 13).into_font()).pos(centre),
    ))
    .map_err(draw_error)
}

type Chart<'a, 'b> = ChartContext<
    'a,
    SVGBackend<'b>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

struct PanelContext<'v> {
    crop: &'v Crop,
    view: &'v AlphaView,
    border_mm: &'v [(f64, f64)],
}

impl PanelContext<'_> {
    /// Title strip and axes; returns the chart to draw in.
    fn chart<'a, 'b>(
        &self,
        area: &'a DrawingArea<SVGBackend<'b>, Shift>,
        name: &str,
    ) -> Result<Chart<'a, 'b>, PlotError> {
        let title = panel_title(name, self.view.alpha_deg, self.view.pushes);
        area.draw(&Text::new(
            title,
            (MARGIN_PX + Y_LABEL_PX + PLOT_PX / 2, PANEL_TITLE_PX / 2 + 2),
            TextStyle::from((FONT, 16).into_font()).pos(Pos::new(HPos::Center, VPos::Center)),
        ))
        .map_err(draw_error)?;
        let (x, y) = self.crop.ranges_mm(&self.view.shape);
        let mut chart = ChartBuilder::on(area)
            .margin(MARGIN_PX)
            .margin_top(PANEL_TITLE_PX + MARGIN_PX)
            .x_label_area_size(X_LABEL_PX)
            .y_label_area_size(Y_LABEL_PX)
            .build_cartesian_2d(x, y)
            .map_err(draw_error)?;
        debug_assert_eq!(
            chart.plotting_area().dim_in_pixel(),
            (PLOT_PX as u32, PLOT_PX as u32),
            "panel plotting area is not the planned square"
        );
        chart
            .configure_mesh()
            .disable_mesh()
            .x_labels(5)
            .y_labels(5)
            .x_desc("x (mm)")
            .y_desc("y (mm)")
            .label_style((FONT, 11))
            .axis_desc_style((FONT, 12))
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| format!("{v:.0}"))
            .draw()
            .map_err(draw_error)?;
        Ok(chart)
    }

    /// The learned border and the centroid, in `colour`.
    fn draw_outline(&self, chart: &mut Chart<'_, '_>, colour: RGBColor) -> Result<(), PlotError> {
        if self.border_mm.len() > 2 {
            chart
                .draw_series(std::iter::once(PathElement::new(
                    self.border_mm.to_vec(),
                    colour.stroke_width(2),
                )))
                .map_err(draw_error)?;
        }
        let arm = 0.03 * (chart.x_range().end - chart.x_range().start);
        chart
            .draw_series([
                PathElement::new(vec![(-arm, 0.0), (arm, 0.0)], colour.stroke_width(1)),
                PathElement::new(vec![(0.0, -arm), (0.0, arm)], colour.stroke_width(1)),
            ])
            .map_err(draw_error)?;
        Ok(())
    }

    fn draw_shape(&self, area: &DrawingArea<SVGBackend<'_>, Shift>) -> Result<(), PlotError> {
        let mut chart = self.chart(area, "S")?;
        let (x, y) = (chart.x_range(), chart.y_range());
        let background = sequential_colour(0);
        chart
            .draw_series(std::iter::once(Rectangle::new(
                [(x.start, y.start), (x.end, y.end)],
                background.filled(),
            )))
            .map_err(draw_error)?;
        let shape = &self.view.shape;
        let rects = heat_rects(self.crop, shape, |i, j| {
            let level = sequential_level(f64::from(shape.get(i, j)));
            (level > 0).then_some(level)
        });
        chart
            .draw_series(
                rects
                    .into_iter()
                    .map(|(r, level)| Rectangle::new(r, sequential_colour(level).filled())),
            )
            .map_err(draw_error)?;
        self.draw_outline(&mut chart, WHITE)
    }

    fn draw_position(
        &self,
        area: &DrawingArea<SVGBackend<'_>, Shift>,
        scales: &Scales,
    ) -> Result<(), PlotError> {
        let mut chart = self.chart(area, "P")?;
        self.draw_outline(&mut chart, RGBColor(150, 150, 150))?;
        let grid = &self.view.shape;
        let cell_mm = grid.cell_size_m() * 1000.0;
        let stride = self.crop.side.div_ceil(ARROWS_ACROSS).max(1);
        let scale = if scales.max_displacement_m > 0.0 {
            ARROW_FILL * stride as f64 * cell_mm / (scales.max_displacement_m * 1000.0)
        } else {
            0.0
        };
        let mut arrows = Vec::new();
        let end = self.crop.side;
        for bj in (stride / 2..end).step_by(stride) {
            for bi in (stride / 2..end).step_by(stride) {
                let (i, j) = (self.crop.i0 + bi, self.crop.j0 + bj);
                let Some(d) = self.view.displacement(i, j) else {
                    continue;
                };
                let from = grid.cell_centre_m(i, j) * 1000.0;
                let v = d * 1000.0 * scale;
                if v.length() > 1e-3 * cell_mm {
                    arrows.push((from, v));
                }
            }
        }
        let colour = BLACK;
        chart
            .draw_series(arrows.iter().map(|&(from, v)| {
                let to = from + v;
                PathElement::new(vec![(from.x, from.y), (to.x, to.y)], colour.stroke_width(1))
            }))
            .map_err(draw_error)?;
        chart
            .draw_series(arrows.iter().map(|&(from, v)| {
                let to = from + v;
                let back = to - v * 0.35;
                let side = v.perp() * 0.18;
                Polygon::new(
                    vec![
                        (to.x, to.y),
                        (back.x + side.x, back.y + side.y),
                        (back.x - side.x, back.y - side.y),
                    ],
                    colour.filled(),
                )
            }))
            .map_err(draw_error)?;
        Ok(())
    }

    fn draw_rotation(
        &self,
        area: &DrawingArea<SVGBackend<'_>, Shift>,
        grid: &Grid,
        name: &str,
        scales: &Scales,
    ) -> Result<(), PlotError> {
        let mut chart = self.chart(area, name)?;
        let range = scales.rotation_range_deg;
        let view = self.view;
        let rects = heat_rects(self.crop, grid, |i, j| {
            view.evidence[Grid::index(i, j)].then(|| {
                let t = f64::from(grid.get(i, j)).to_degrees() / range;
                let c = diverging_colour(t);
                (c.0, c.1, c.2)
            })
        });
        chart
            .draw_series(
                rects
                    .into_iter()
                    .map(|(r, (cr, cg, cb))| Rectangle::new(r, RGBColor(cr, cg, cb).filled())),
            )
            .map_err(draw_error)?;
        self.draw_outline(&mut chart, BORDER_COLOUR)
    }
}

fn panel_title(name: &str, alpha_deg: f64, pushes: u64) -> String {
    format!("{name}, α = {alpha_deg}° ({pushes} pushes)")
}

/// Rectangles (millimetres) of equal `key`, merging runs along x; `key(i, j)` of `None`
/// leaves a cell blank. Crops wider than [`MAX_HEAT_BLOCKS`] show blocks of cells, each
/// taking the key of its centre cell.
fn heat_rects<K: PartialEq + Copy>(
    crop: &Crop,
    grid: &Grid,
    key: impl Fn(usize, usize) -> Option<K>,
) -> Vec<([(f64, f64); 2], K)> {
    let b = crop.side.div_ceil(MAX_HEAT_BLOCKS).max(1);
    let n = crop.side.div_ceil(b);
    let cell_mm = grid.cell_size_m() * 1000.0;
    let o = grid.origin_m() * 1000.0;
    let x_of = |block: usize| o.x + ((crop.i0 + (block * b).min(crop.side)) as f64) * cell_mm;
    let y_of = |block: usize| o.y + ((crop.j0 + (block * b).min(crop.side)) as f64) * cell_mm;
    let block_key = |bi: usize, bj: usize| {
        let i = (crop.i0 + bi * b + b / 2).min(crop.i0 + crop.side - 1);
        let j = (crop.j0 + bj * b + b / 2).min(crop.j0 + crop.side - 1);
        key(i, j)
    };
    let mut out = Vec::new();
    for bj in 0..n {
        let mut run: Option<(usize, K)> = None;
        for bi in 0..=n {
            let k = if bi < n { block_key(bi, bj) } else { None };
            match (run, k) {
                (Some((_, rk)), Some(k)) if rk == k => {}
                _ => {
                    if let Some((start, rk)) = run {
                        out.push(([(x_of(start), y_of(bj)), (x_of(bi), y_of(bj + 1))], rk));
                    }
                    run = k.map(|k| (bi, k));
                }
            }
        }
    }
    out
}

/// The colour bar of R+ and R-, degrees, beside a row.
fn draw_rotation_bar(
    area: &DrawingArea<SVGBackend<'_>, Shift>,
    scales: &Scales,
) -> Result<(), PlotError> {
    let r = scales.rotation_range_deg;
    let mut chart = ChartBuilder::on(area)
        .margin_top(PANEL_TITLE_PX + MARGIN_PX)
        .margin_bottom(X_LABEL_PX + MARGIN_PX)
        .margin_left(8)
        .margin_right(MARGIN_PX)
        .set_label_area_size(LabelAreaPosition::Right, 52)
        .build_cartesian_2d(0.0..1.0, -r..r)
        .map_err(draw_error)?;
    let decimals = if r >= 10.0 { 0 } else { 1 };
    chart
        .configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_labels(9)
        .y_desc("R (deg)")
        .label_style((FONT, 11))
        .axis_desc_style((FONT, 12))
        .y_label_formatter(&|v| format!("{v:.decimals$}"))
        .draw()
        .map_err(draw_error)?;
    let steps = 64;
    chart
        .draw_series((0..steps).map(|k| {
            let lo = -r + 2.0 * r * f64::from(k) / f64::from(steps);
            let hi = -r + 2.0 * r * f64::from(k + 1) / f64::from(steps);
            let c = diverging_colour((lo + hi) / (2.0 * r));
            Rectangle::new([(0.0, lo), (1.0, hi)], c.filled())
        }))
        .map_err(draw_error)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::nice_ceiling;

    #[test]
    fn nice_ceiling_rounds_up_to_a_round_number() {
        assert_eq!(nice_ceiling(0.0), 1.0);
        assert_eq!(nice_ceiling(17.0), 20.0);
        assert_eq!(nice_ceiling(20.0), 20.0);
        assert_eq!(nice_ceiling(21.0), 25.0);
        assert_eq!(nice_ceiling(29.2), 30.0);
        assert_eq!(nice_ceiling(3.2), 4.0);
        assert_eq!(nice_ceiling(0.7), 0.8);
        assert_eq!(nice_ceiling(61.0), 80.0);
        assert_eq!(nice_ceiling(90.0), 100.0);
    }
}
