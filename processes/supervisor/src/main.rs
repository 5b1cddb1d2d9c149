//! `agp`: the supervisor CLI. `agp up` runs a launch file; `agp probe push` measures one push.

mod instance_lock;
mod probe;
mod signals;
mod up;

use std::path::PathBuf;
use std::process::ExitCode;

use agp_supervisor::{LaunchConfig, LaunchOptions};
use anyhow::{Context, Result};
use clap::{Parser, Subcommand};

/// Runs and measures the affordance-gradient pipeline.
#[derive(Debug, Parser)]
#[command(name = "agp", version)]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Debug, Subcommand)]
enum Cmd {
    /// Start the processes of a launch file under one instance, watch them, restart them
    /// as their policy says, and stop them all (leaving no file behind) on Ctrl-C, SIGTERM,
    /// or when a process marked `ends_run` exits with status 0.
    Up(UpArgs),
    /// Measure what the simulated world does.
    Probe {
        #[command(subcommand)]
        what: ProbeCmd,
    },
}

#[derive(Debug, clap::Args)]
struct UpArgs {
    /// The launch file.
    #[arg(default_value = "launch.toml")]
    launch: PathBuf,
    /// Run under this instance name instead of the file's.
    #[arg(long)]
    instance: Option<String>,
}

#[derive(Debug, Subcommand)]
enum ProbeCmd {
    /// Push the object once from a given side and direction, and report how it moved.
    ///
    /// The robot starts on a circle around the object at --angle-deg (0 = the object's +x
    /// side, counter-clockwise, object frame), facing the object's centroid turned by
    /// --alpha-deg. It drives straight until its body touches the object, pushes on for
    /// --duration-ms, stops, and lets the object come to rest. The displacement (world
    /// frame) and rotation come from the simulator's ground truth. The probe runs its own
    /// lockstep `agp-physics` under a private instance and removes its files when done.
    ///
    /// Example: agp probe push --scenario triangle --angle-deg 270 --alpha-deg 15 --json -
    Push(probe::ProbeArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match &cli.command {
        Cmd::Up(args) => up(args),
        Cmd::Probe {
            what: ProbeCmd::Push(args),
        } => probe::run(args).map(|r| match r {
            Some(_) => 0,
            None => probe::INTERRUPTED,
        }),
    };
    match result {
        Ok(code) => ExitCode::from(code),
        Err(e) => {
            eprintln!("agp: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn up(args: &UpArgs) -> Result<u8> {
    let exe = std::env::current_exe().context("cannot find the running `agp` executable")?;
    let options = LaunchOptions {
        instance: args.instance.clone(),
        exe_dir: exe.parent().map(PathBuf::from).unwrap_or_default(),
    };
    let config = match LaunchConfig::load(&args.launch, &options) {
        Ok(c) => c,
        Err(e) => {
            for line in e.to_string().lines() {
                eprintln!("agp: error: {line}");
            }
            eprintln!("agp: nothing was started");
            return Ok(2);
        }
    };
    up::up(&config)
}
