//! `agp view`: a live view of a running instance, or of an MCAP recording, for Foxglove
//! (the logic is `agp_view`'s).

use std::path::PathBuf;

use agp_runtime::Instance;
use agp_view::{ViewError, ViewOptions, Viewer};
use anyhow::{Result, anyhow};

use crate::control;

#[derive(Debug, clap::Args)]
pub struct ViewArgs {
    /// An MCAP recording (`agp record`) to serve instead of a running instance, paced by
    /// its log times.
    pub recording: Option<PathBuf>,
    #[command(flatten)]
    pub target: control::InstanceArg,
    /// The address to listen on (127.0.0.1: this machine only; 0.0.0.0: every interface).
    #[arg(long, default_value = "127.0.0.1")]
    pub host: String,
    /// The port (Foxglove's default 8765; 0 picks a free one, printed).
    #[arg(long, default_value_t = agp_view::DEFAULT_PORT)]
    pub port: u16,
    /// Scene updates per second (0.5 to 200).
    #[arg(long, default_value_t = 20.0)]
    pub rate_hz: f64,
    /// The AG layer shown: the learned alpha nearest this, degrees (0, 15 or -15).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub alpha_deg: f64,
    /// A recording's speed: 2 plays it twice as fast as it was recorded.
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// Play a recording over and over instead of holding its last scene.
    #[arg(long = "loop")]
    pub loop_playback: bool,
}

/// Runs the view until Ctrl-C or SIGTERM (live: or until the instance goes down).
pub fn run(args: &ViewArgs) -> Result<u8> {
    if !(agp_view::RATE_HZ_RANGE.0..=agp_view::RATE_HZ_RANGE.1).contains(&args.rate_hz) {
        return Err(anyhow!(
            "--rate-hz must be from {} to {}, got {}",
            agp_view::RATE_HZ_RANGE.0,
            agp_view::RATE_HZ_RANGE.1,
            args.rate_hz
        ));
    }
    if !(args.speed.is_finite() && args.speed > 0.0) {
        return Err(anyhow!(
            "--speed must be a positive number, got {}",
            args.speed
        ));
    }
    agp_runtime::install_shutdown_handler();
    let options = ViewOptions {
        host: args.host.clone(),
        port: args.port,
        rate_hz: args.rate_hz,
        alpha_deg: args.alpha_deg,
        speed: args.speed,
        loop_playback: args.loop_playback,
        server_name: "agp".to_owned(),
    };
    // Started by `agp up` (`view = true`): a view that cannot listen leaves the run alone.
    let under_up = std::env::var_os("AGP_PROCESS").is_some();
    enum Source {
        Live(Box<Instance>),
        Recording(PathBuf),
    }
    let (what, source) = match &args.recording {
        Some(path) => {
            // Refused before the server starts: a FIFO, a folder, not MCAP.
            drop(agp_view::open_recording(path)?);
            (
                format!("recording {}", path.display()),
                Source::Recording(path.clone()),
            )
        }
        None => {
            let name = args.target.name()?;
            let instance = crate::control::instance_named(&name)?;
            if !instance.control_exists() {
                return Err(ViewError::NotUp(name).into());
            }
            (
                format!("instance `{name}`"),
                Source::Live(Box::new(instance)),
            )
        }
    };
    let replay = matches!(source, Source::Recording(_));
    let mut viewer = match Viewer::start(&options, replay) {
        Ok(v) => v,
        Err(e) if under_up => {
            eprintln!("agp view: {e}; the run goes on without the view");
            return Ok(0);
        }
        Err(e) => return Err(e.into()),
    };
    println!(
        "agp view: serving {what} on ws://{}:{} (Foxglove: Open connection, Foxglove WebSocket)",
        options.host,
        viewer.port()
    );
    let summary = match &source {
        Source::Live(instance) => agp_view::serve_instance(&mut viewer, instance, &options),
        Source::Recording(path) => agp_view::serve_recording(&mut viewer, path, &options, |w| {
            eprintln!("agp view: {w}");
        }),
    };
    viewer.stop();
    let summary = summary?;
    if summary.instance_went_down {
        println!("agp view: {what} went down");
    }
    println!(
        "agp view: read {} estimates, {} IR frames, {} grids; published the scene {} times",
        summary.estimates, summary.frames, summary.grids, summary.published
    );
    if summary.refused > 0 {
        eprintln!(
            "agp view: {} recorded messages were not the size of their payload and were skipped",
            summary.refused
        );
    }
    Ok(0)
}
