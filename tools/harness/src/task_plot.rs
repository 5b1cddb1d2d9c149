//! The plot of task runs (`agp bench place`, `trajectory` and the judge of `agp up`):
//! panels side by side, each the centroid's path and the object's outline over the goal or
//! the path.

use std::path::Path;

use agp_planning::PoseSample;
use agp_shared_types::Pose2;
use agp_world::ObjectShape;
use anyhow::{Context, Result, bail};
use glam::DVec2;
use plotters::coord::Shift;
use plotters::prelude::*;

/// One panel of a plot: a run's recorded poses.
pub(crate) struct Panel<'a> {
    pub title: String,
    pub samples: &'a [PoseSample],
}

/// What is drawn under every panel in red.
pub(crate) enum Overlay<'a> {
    Goal(Pose2),
    Path(&'a [DVec2]),
}

/// The object's outline at `pose`, mm, closed.
fn outline_mm(shape: &ObjectShape, pose: Pose2) -> Vec<(f64, f64)> {
    let rot = DVec2::from_angle(pose.theta);
    let c = DVec2::new(pose.x, pose.y);
    let local: Vec<DVec2> = match shape {
        ObjectShape::Polygon(p) => p.vertices().to_vec(),
        ObjectShape::Circle { radius } => (0..36)
            .map(|k| *radius * DVec2::from_angle(f64::from(k) * std::f64::consts::TAU / 36.0))
            .collect(),
    };
    let mut out: Vec<(f64, f64)> = local
        .iter()
        .map(|v| {
            let w = c + rot.rotate(*v);
            (w.x * 1e3, w.y * 1e3)
        })
        .collect();
    if let Some(&first) = out.first() {
        out.push(first);
    }
    out
}

fn plot_error(e: impl std::fmt::Display) -> anyhow::Error {
    anyhow::anyhow!("cannot draw the plot: {e}")
}

/// Draws the panels side by side: under each the overlay in red, the centroid's path in
/// blue and the object's outline every few recorded poses (at most about 40 per panel).
pub(crate) fn plot_runs(
    path: &Path,
    title: &str,
    shape: &ObjectShape,
    panels: &[Panel<'_>],
    overlay: Overlay<'_>,
) -> Result<()> {
    const PANEL_PX: u32 = 560;
    if panels.is_empty() {
        bail!("nothing to plot");
    }
    // One square view for all panels: every pose, the overlay, and a margin.
    let mut xs: Vec<f64> = Vec::new();
    let mut ys: Vec<f64> = Vec::new();
    for p in panels {
        for s in p.samples {
            xs.push(s.pose.x * 1e3);
            ys.push(s.pose.y * 1e3);
        }
    }
    match &overlay {
        Overlay::Goal(g) => {
            xs.push(g.x * 1e3);
            ys.push(g.y * 1e3);
        }
        Overlay::Path(points) => {
            for p in *points {
                xs.push(p.x * 1e3);
                ys.push(p.y * 1e3);
            }
        }
    }
    let margin = shape.radius() * 1e3 + 20.0;
    let fold = |v: &[f64], f: fn(f64, f64) -> f64, init: f64| v.iter().copied().fold(init, f);
    let (x0, x1) = (
        fold(&xs, f64::min, f64::INFINITY),
        fold(&xs, f64::max, f64::NEG_INFINITY),
    );
    let (y0, y1) = (
        fold(&ys, f64::min, f64::INFINITY),
        fold(&ys, f64::max, f64::NEG_INFINITY),
    );
    let half = 0.5 * (x1 - x0).max(y1 - y0) + margin;
    let (cx, cy) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
    let x_range = (cx - half)..(cx + half);
    let y_range = (cy - half)..(cy + half);

    let width = PANEL_PX * panels.len() as u32;
    let height = PANEL_PX + 40;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_error)?;
        let (head, body) = root.split_vertically(40);
        head.draw(&Text::new(
            title.to_owned(),
            (10, 12),
            ("sans-serif", 15).into_font(),
        ))
        .map_err(plot_error)?;
        let areas: Vec<DrawingArea<SVGBackend<'_>, Shift>> = body.split_evenly((1, panels.len()));
        for (area, panel) in areas.iter().zip(panels) {
            let mut chart = ChartBuilder::on(area)
                .caption(&panel.title, ("sans-serif", 13))
                .margin(8)
                .x_label_area_size(30)
                .y_label_area_size(45)
                .build_cartesian_2d(x_range.clone(), y_range.clone())
                .map_err(plot_error)?;
            chart
                .configure_mesh()
                .disable_mesh()
                .x_desc("x (mm)")
                .y_desc("y (mm)")
                .label_style(("sans-serif", 11))
                .draw()
                .map_err(plot_error)?;
            let red = RGBColor(200, 30, 30);
            match &overlay {
                Overlay::Goal(g) => {
                    chart
                        .draw_series(std::iter::once(PathElement::new(
                            outline_mm(shape, *g),
                            red.stroke_width(2),
                        )))
                        .map_err(plot_error)?;
                }
                Overlay::Path(points) => {
                    let line: Vec<(f64, f64)> =
                        points.iter().map(|p| (p.x * 1e3, p.y * 1e3)).collect();
                    chart
                        .draw_series(std::iter::once(PathElement::new(line, red.stroke_width(2))))
                        .map_err(plot_error)?;
                }
            }
            let every = panel.samples.len().div_ceil(40).max(1);
            let grey = RGBColor(90, 90, 90);
            chart
                .draw_series(
                    panel
                        .samples
                        .iter()
                        .step_by(every)
                        .chain(panel.samples.last())
                        .map(|s| PathElement::new(outline_mm(shape, s.pose), grey.stroke_width(1))),
                )
                .map_err(plot_error)?;
            let centroid: Vec<(f64, f64)> = panel
                .samples
                .iter()
                .map(|s| (s.pose.x * 1e3, s.pose.y * 1e3))
                .collect();
            chart
                .draw_series(std::iter::once(PathElement::new(
                    centroid,
                    BLUE.stroke_width(1),
                )))
                .map_err(plot_error)?;
        }
        root.present().map_err(plot_error)?;
    }
    std::fs::write(path, svg).with_context(|| format!("cannot write `{}`", path.display()))
}
