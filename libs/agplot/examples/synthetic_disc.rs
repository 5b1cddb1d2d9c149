//! Learns a synthetic disc (40 mm radius unless given, 60 pushes per alpha) and plots it:
//! `cargo run -p agp-plot --example synthetic_disc -- OUT.svg [RADIUS_MM]`.

use std::f64::consts::{PI, TAU};
use std::path::PathBuf;

use agp_affordance::{AffordanceLearner, LearnerConfig, PushOutcome};
use anyhow::Context;
use glam::DVec2;

fn main() -> anyhow::Result<()> {
    let out = PathBuf::from(
        std::env::args()
            .nth(1)
            .context("usage: synthetic_disc OUT.svg [RADIUS_MM]")?,
    );
    let radius_m = match std::env::args().nth(2) {
        Some(r) => r.parse::<f64>().context("RADIUS_MM is not a number")? / 1000.0,
        None => 0.04,
    };
    let config = LearnerConfig::default();
    let mut learner = AffordanceLearner::new("synthetic disc", &config)?;
    for &alpha in &config.alphas_deg {
        let a = f64::to_radians(alpha);
        for k in 0..60 {
            let phi = TAU * f64::from(k) / 60.0;
            let push = PushOutcome {
                contact_point_obj: DVec2::from_angle(phi) * radius_m,
                displacement_obj: DVec2::from_angle(phi + PI + 0.5 * a)
                    * (0.02 + 0.004 * phi.cos()),
                rotation_rad: 0.3 * phi.sin() + 0.8 * a,
                heading_obj: -DVec2::from_angle(phi),
            };
            learner.add_push(alpha, &push)?;
            for s in 0..4 {
                let border = DVec2::from_angle(phi + TAU * f64::from(s) / 240.0) * radius_m;
                learner.add_border_point(alpha, border)?;
            }
        }
    }
    let ag = learner.into_gradient();
    agp_plot::plot_gradient(&ag, "synthetic disc, 60 pushes per alpha", &out)?;
    println!("wrote `{}`", out.display());
    Ok(())
}
