//! `agp replay FILE.mcap`: plays a lockstep recording back into physics and checks that
//! the run comes out the same, frame by frame, to the bit.
//!
//! Physics applies only commands carrying the run's token, so the replay is a launch of its
//! own, run by this supervisor (`up::up`): physics alone, with the recorded scenario, seed
//! and rate on the lockstep clock, and the hidden `agp replay-driver`, which feeds physics
//! each recorded reset and command in the order physics applied them
//! (`agp_recording::ReplayScript`), compares each frame with the recorded one and, at the
//! end, takes the object's final true pose the way the judge does (the harness's
//! `TruthRecorder`). It publishes the recorded task again, so the judge of `agp up` gives
//! the replayed run its verdict as it gave the recorded one.

use std::path::{Path, PathBuf};
use std::time::Duration;

use agp_harness::evaluation::TruthRecorder;
use agp_launch::{LaunchConfig, LaunchOptions};
use agp_recording::{Recording, ReplayAction, ReplayScript, RunInfo, same_sensing};
use agp_runtime::{DriveError, LockstepDriver, TruthAccess};
use agp_shared_types::{GroundTruth, Pose2};
use anyhow::{Context, Result, anyhow, bail};

use crate::up;

/// `agp replay`.
#[derive(Debug, clap::Args)]
pub(crate) struct ReplayArgs {
    /// The recording (`agp record`, or a launch file's `record` key) of a lockstep run.
    file: PathBuf,
    /// The instance the replay runs under.
    #[arg(long, default_value = "replay")]
    instance: String,
    /// Where the judge's verdict goes (default: a temporary folder, removed after).
    #[arg(long)]
    results: Option<PathBuf>,
    /// Write the replay's account (frames compared, the final pose with its bits) as JSON.
    #[arg(long)]
    json: Option<PathBuf>,
}

/// `agp replay-driver` (hidden; `agp replay` starts it under its supervisor).
#[derive(Debug, clap::Args)]
pub(crate) struct DriverArgs {
    /// The recording.
    file: PathBuf,
    /// Where the account goes (JSON).
    #[arg(long)]
    report: PathBuf,
    #[arg(long, env = "AGP_INSTANCE")]
    instance: String,
    #[arg(long, env = "AGP_EPOCH", default_value_t = 0)]
    epoch: u64,
}

/// How long the driver waits for each frame.
const FRAME_TIMEOUT: Duration = Duration::from_secs(20);

/// A TOML string literal.
fn quoted(s: &str) -> String {
    toml::Value::String(s.to_owned()).to_string()
}

pub(crate) fn run(args: &ReplayArgs) -> Result<u8> {
    let file = std::path::absolute(&args.file)
        .with_context(|| format!("cannot locate {}", args.file.display()))?;
    let recording = Recording::open(&file)?;
    // Refused here, before anything starts, when it cannot replay.
    let script = ReplayScript::from_recording(&recording)?;
    let info = RunInfo::from_metadata(&recording.run());
    let tmp = tempfile::tempdir().context("cannot make a temporary folder")?;
    let scenario = match &info.scenario_toml {
        Some(text) => {
            let path = tmp.path().join("scenario.toml");
            std::fs::write(&path, text).context("cannot write the recorded scenario")?;
            path.display().to_string()
        }
        None if agp_world::BUILTIN_NAMES.contains(&info.scenario.as_str()) => info.scenario.clone(),
        None => bail!(
            "the recording names scenario `{}`, which is not a built-in, and holds no scenario file",
            info.scenario
        ),
    };
    let seed = info
        .seed
        .ok_or_else(|| anyhow!("the recording holds no seed"))?;
    let rate = info.rate_hz.unwrap_or(agp_shared_types::DEFAULT_RATE_HZ);
    let results = match &args.results {
        Some(r) => std::path::absolute(r).context("cannot locate the results folder")?,
        None => tmp.path().join("results"),
    };
    let report = tmp.path().join("replay.json");
    let exe = std::env::current_exe().context("cannot find the running `agp` executable")?;
    let launch = format!(
        "# A replay of {recording} (agp {version}, instance `{inst}`).\n\
         instance = {instance}\nscenario = {scenario}\nresults = {results}\n\n\
         [clock]\nmode = \"lockstep\"\nrate_hz = {rate:?}\n\n\
         [[process]]\nname = \"physics\"\nexec = \"agp-physics\"\nargs = [\"--seed\", \"{seed}\"]\n\
         restart = {{ policy = \"never\" }}\n\n\
         [[process]]\nname = \"replay\"\nexec = {exe}\nargs = [\"replay-driver\", {file}, \"--report\", {report}]\n\
         restart = {{ policy = \"never\" }}\nends_run = true\n",
        recording = file.display(),
        version = info.agp_version,
        inst = info.instance,
        instance = quoted(&args.instance),
        scenario = quoted(&scenario),
        results = quoted(&results.display().to_string()),
        exe = quoted(&exe.display().to_string()),
        file = quoted(&file.display().to_string()),
        report = quoted(&report.display().to_string()),
    );
    let launch_path = tmp.path().join("launch.toml");
    std::fs::write(&launch_path, launch).context("cannot write the replay's launch file")?;
    let options = LaunchOptions {
        instance: None,
        exe_dir: exe.parent().map(Path::to_path_buf).unwrap_or_default(),
        remote_checks: Some(agp_supervisor::BRIDGE_CHECKS),
    };
    let config = LaunchConfig::load(&launch_path, &options).map_err(|e| anyhow!("{e}"))?;
    println!(
        "agp: replaying {} ({} actions: {} commands, {} resets; recorded by agp {} from instance `{}`, scenario {}, seed {seed})",
        file.display(),
        script.actions.len(),
        script
            .actions
            .iter()
            .filter(|a| matches!(a, ReplayAction::Command { .. }))
            .count(),
        script
            .actions
            .iter()
            .filter(|a| matches!(a, ReplayAction::Reset { .. }))
            .count(),
        info.agp_version,
        info.instance,
        info.scenario
    );
    let code = up::up(&config)?;
    let text = std::fs::read_to_string(&report).with_context(|| {
        format!("the replay driver wrote no account (agp up ended with {code})")
    })?;
    let account: serde_json::Value =
        serde_json::from_str(&text).context("the replay driver's account is not JSON")?;
    let equal = account["frames_equal"].as_u64().unwrap_or(0);
    let compared = account["frames_compared"].as_u64().unwrap_or(0);
    let f = &account["final"]["object"];
    println!(
        "agp: replay: {equal} of {compared} recorded frames reproduced to the bit ({} frames not in the recording)",
        account["frames_unrecorded"].as_u64().unwrap_or(0)
    );
    println!(
        "agp: replay: final object pose (ground truth, step {}): x {} mm, y {} mm, theta {} deg; bits x {} y {} theta {}",
        account["final"]["step"],
        f["x_m"].as_f64().unwrap_or(f64::NAN) * 1e3,
        f["y_m"].as_f64().unwrap_or(f64::NAN) * 1e3,
        f["theta_rad"].as_f64().unwrap_or(f64::NAN).to_degrees(),
        f["x_bits"],
        f["y_bits"],
        f["theta_bits"]
    );
    if let Some(path) = &args.json {
        std::fs::write(path, &text).with_context(|| format!("cannot write {}", path.display()))?;
    }
    if code != 0 {
        return Ok(code);
    }
    if equal != compared || account["complete"] != serde_json::Value::Bool(true) {
        println!("agp: replay: the replayed run differs from the recorded one");
        return Ok(crate::run_end::exit::ERROR);
    }
    Ok(0)
}

fn pose_json(p: &Pose2) -> serde_json::Value {
    serde_json::json!({
        "x_m": p.x, "y_m": p.y, "theta_rad": p.theta,
        "x_bits": format!("{:#018x}", p.x.to_bits()),
        "y_bits": format!("{:#018x}", p.y.to_bits()),
        "theta_bits": format!("{:#018x}", p.theta.to_bits()),
    })
}

/// The driver: the recorded actions into physics, each frame held against the recorded one.
pub(crate) fn drive(args: &DriverArgs) -> Result<u8> {
    agp_runtime::install_shutdown_handler();
    let recording = Recording::open(&args.file)?;
    let script = ReplayScript::from_recording(&recording)?;
    let instance = crate::control::instance_named(&args.instance)?;
    // The judge's own means: its truth recorder, on a node of its own, subscribed before
    // the first command.
    let judge_node = instance
        .node("agp-replay-judge", false)
        .map_err(|e| anyhow!("cannot create the replay judge's node: {e:?}"))?;
    let mut truth = TruthRecorder::open(&instance, &judge_node, u64::MAX)?;
    let _task = match &script.task {
        Some(task) => {
            let publisher = instance
                .task(&judge_node)
                .map_err(|e| anyhow!("cannot open the task: {e}"))?
                .data
                .publisher_builder()
                .create()
                .map_err(|e| anyhow!("cannot publish the task: {e:?}"))?;
            let sample = publisher
                .loan_uninit()
                .map_err(|e| anyhow!("cannot loan a task: {e:?}"))?;
            sample
                .write_payload(*task)
                .send()
                .map_err(|e| anyhow!("cannot send the task: {e:?}"))?;
            Some(publisher)
        }
        None => None,
    };
    let mut driver = match LockstepDriver::connect(
        &instance,
        "agp-replay",
        args.epoch,
        TruthAccess::SensesOnly,
        FRAME_TIMEOUT,
    ) {
        Ok(d) => d,
        Err(DriveError::Shutdown) => return Ok(0),
        Err(e) => return Err(e).context("cannot reach physics"),
    };
    let mut compared = 1u64;
    let mut equal = u64::from(same_sensing(driver.frame(), &script.first_frame));
    let mut unrecorded = 0u64;
    let mut first_difference = (equal == 0).then_some(0usize);
    let mut done = 0usize;
    for (k, (action, expected)) in script.actions.iter().zip(&script.expected).enumerate() {
        let frame = match *action {
            ReplayAction::Reset {
                object,
                robot,
                seed,
                ..
            } => driver.reset_seeded(object, robot, seed),
            ReplayAction::Command {
                step,
                left_mps,
                right_mps,
            } => {
                if driver.frame().step != step {
                    first_difference.get_or_insert(k);
                    break;
                }
                driver.step(left_mps, right_mps)
            }
        };
        let frame = match frame {
            Ok(f) => *f,
            Err(DriveError::Shutdown) => break,
            Err(e) => {
                return Err(e).context(format!("replay action {k} of {}", script.actions.len()));
            }
        };
        match expected {
            Some(e) => {
                compared += 1;
                if same_sensing(&frame, e) {
                    equal += 1;
                } else {
                    first_difference.get_or_insert(k + 1);
                }
            }
            None => unrecorded += 1,
        }
        done += 1;
        if done.is_multiple_of(2048) {
            truth.drain()?;
        }
    }
    let last: Option<GroundTruth> = truth.finish()?;
    let account = serde_json::json!({
        "recording": args.file.display().to_string(),
        "actions": script.actions.len(),
        "actions_done": done,
        "complete": done == script.actions.len(),
        "frames_recorded": script.frames_recorded,
        "frames_compared": compared,
        "frames_equal": equal,
        "frames_unrecorded": unrecorded,
        "first_difference_at_action": first_difference,
        "resets_not_applied": script.resets_not_applied,
        "commands_not_applied": script.commands_not_applied,
        "final": last.map(|t| serde_json::json!({
            "step": t.step,
            "sim_time_s": t.sim_time_s,
            "object": pose_json(&t.object),
            "robot": pose_json(&t.robot),
        })),
    });
    std::fs::write(&args.report, format!("{account:#}\n"))
        .with_context(|| format!("cannot write {}", args.report.display()))?;
    Ok(0)
}
