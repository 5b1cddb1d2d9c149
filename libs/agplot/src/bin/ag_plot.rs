//! `ag-plot FILE.ag OUT.svg`: plots a saved affordance gradient as an SVG (S, P, R+, R- per alpha).

use std::path::PathBuf;

use agp_affordance::AffordanceGradient;
use anyhow::Context;
use clap::Parser;

/// Plot an affordance gradient file (AG) as an SVG: a row per learned alpha with S, P, R+, R-.
#[derive(Debug, Parser)]
#[command(name = "ag-plot", version)]
struct Args {
    /// The AG file to plot (written by the estimator or `AffordanceGradient::save`).
    input: PathBuf,
    /// The SVG to write (replaced atomically if it exists).
    output: PathBuf,
    /// Title on top of the figure (default: the object's name and the file).
    #[arg(long)]
    title: Option<String>,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let ag = AffordanceGradient::load(&args.input)
        .with_context(|| format!("cannot plot `{}`", args.input.display()))?;
    let title = args.title.unwrap_or_else(|| {
        format!(
            "affordance gradient of `{}` ({})",
            ag.object_name(),
            args.input.display()
        )
    });
    agp_plot::plot_gradient(&ag, &title, &args.output)
        .with_context(|| format!("cannot plot `{}`", args.input.display()))?;
    println!(
        "wrote `{}`: {} alphas of `{}`",
        args.output.display(),
        ag.alphas_deg().count(),
        ag.object_name()
    );
    Ok(())
}
