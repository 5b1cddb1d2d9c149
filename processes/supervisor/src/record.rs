//! `agp record`: every topic of a running instance into an MCAP file (agp-recording's
//! `Recorder`, a subscriber of its own that the ring never waits for). The launch file's
//! `record = "FILE"` key runs it as a child of `agp up`, from before physics starts.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use agp_recording::{RecordStats, Recorder, RecorderOptions, RunInfo};
use agp_shared_types::{ControlKind, read_str};
use anyhow::{Context, Result, bail};

/// `agp record`.
#[derive(Debug, clap::Args)]
pub(crate) struct RecordArgs {
    /// The instance to record (a supervisor must run it).
    #[arg(long, env = "AGP_INSTANCE")]
    instance: String,
    /// Stop after this many seconds; without it, record until Ctrl-C, SIGTERM or the
    /// instance goes down.
    #[arg(long)]
    seconds: Option<f64>,
    /// The run's launch file, kept in the recording (what replay needs).
    #[arg(long)]
    launch: Option<PathBuf>,
    /// The run's scenario (a built-in name or a file), kept in the recording.
    #[arg(long, env = "AGP_SCENARIO")]
    scenario: Option<String>,
    /// The run's clock (`lockstep`, `realtime`), kept in the recording.
    #[arg(long, env = "AGP_CLOCK")]
    clock: Option<String>,
    /// The run's physics rate, steps per second, kept in the recording.
    #[arg(long, env = "AGP_RATE_HZ")]
    rate_hz: Option<f64>,
    /// Physics's noise seed (default: the scenario's), kept in the recording.
    #[arg(long)]
    seed: Option<u64>,
    /// Also write the recorder's account (per topic: received, written, dropped, lost)
    /// as JSON to this file.
    #[arg(long)]
    json: Option<PathBuf>,
    /// The MCAP file to write.
    file: PathBuf,
}

/// How often the recording's end conditions are looked at.
const TICK: Duration = Duration::from_millis(20);

pub(crate) fn run(args: &RecordArgs) -> Result<u8> {
    agp_runtime::install_shutdown_handler();
    if let Some(s) = args.seconds
        && !(s.is_finite() && s > 0.0 && s <= 86_400.0)
    {
        bail!("--seconds must be more than 0 and at most 86400, got {s}");
    }
    let instance = agp_runtime::Instance::running(&args.instance)?;
    let info = run_info(args)?;
    let options = RecorderOptions {
        run: info.to_metadata(),
        ..RecorderOptions::default()
    };
    // The scene in Foxglove's schemas beside the raw channels, built on the recorder's
    // writing thread (agp-view's tap), never on the ring.
    let tap = Box::new(agp_view::FoxgloveTap::default());
    let recorder = Recorder::start_with_tap(&instance, &args.file, options, Some(tap))
        .with_context(|| format!("cannot record instance `{}`", args.instance))?;
    println!(
        "agp: recording instance `{}` into {}{}",
        args.instance,
        args.file.display(),
        args.seconds
            .map(|s| format!(" for {s} s"))
            .unwrap_or_else(|| " until stopped".to_owned())
    );
    let start = Instant::now();
    let deadline = args.seconds.map(|s| start + Duration::from_secs_f64(s));
    let why = loop {
        if agp_runtime::shutdown_requested() {
            break "stopped";
        }
        if deadline.is_some_and(|d| Instant::now() >= d) {
            break "time is up";
        }
        if !instance.control_exists() {
            break "the instance went down";
        }
        std::thread::sleep(TICK);
    };
    let stats = recorder
        .finish()
        .with_context(|| format!("cannot complete {}", args.file.display()))?;
    print_stats(&stats, why);
    if let Some(path) = &args.json {
        std::fs::write(path, format!("{:#}\n", stats_json(&stats)))
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(0)
}

/// What the run's supervisor says of it: the scenario, clock and rate it gave physics (the
/// `AGP_SCENARIO`, `AGP_CLOCK`, `AGP_RATE_HZ` of the physics process it started) and
/// physics's `--seed`.
#[derive(Debug, Default, PartialEq)]
struct SupervisedRun {
    scenario: Option<String>,
    clock: Option<String>,
    rate_hz: Option<f64>,
    seed: Option<u64>,
}

impl SupervisedRun {
    /// Asks the instance's supervisor for its processes and reads its physics process's
    /// environment and arguments (`/proc/PID/environ`, `/proc/PID/cmdline`: same user).
    /// Empty when there is no supervisor or no physics process it started.
    fn ask(instance: &str) -> Self {
        let Ok(status) = agp_runtime::control_client::ask(instance, ControlKind::Status) else {
            return Self::default();
        };
        let count = (status.process_count as usize).min(status.processes.len());
        let Some(physics) = status.processes[..count].iter().find(|p| {
            p.pid != 0
                && (read_str(&p.name) == "physics" || read_str(&p.exec).ends_with("agp-physics"))
        }) else {
            return Self::default();
        };
        let read = |what: &str| std::fs::read(format!("/proc/{}/{what}", physics.pid)).ok();
        Self::parse(
            read("environ").as_deref().unwrap_or_default(),
            read("cmdline").as_deref().unwrap_or_default(),
        )
    }

    /// From a process's NUL-separated environment and command line.
    fn parse(environ: &[u8], cmdline: &[u8]) -> Self {
        let words = |b: &[u8]| -> Vec<String> {
            b.split(|c| *c == 0)
                .filter(|w| !w.is_empty())
                .map(|w| String::from_utf8_lossy(w).into_owned())
                .collect()
        };
        let env = words(environ);
        let get = |key: &str| {
            env.iter()
                .find_map(|kv| kv.strip_prefix(key)?.strip_prefix('=').map(str::to_owned))
                .filter(|v| !v.is_empty())
        };
        let args = words(cmdline);
        let seed = args.iter().enumerate().find_map(|(i, a)| {
            if a == "--seed" {
                args.get(i + 1)?.parse().ok()
            } else {
                a.strip_prefix("--seed=")?.parse().ok()
            }
        });
        Self {
            scenario: get("AGP_SCENARIO"),
            clock: get("AGP_CLOCK"),
            rate_hz: get("AGP_RATE_HZ").and_then(|r| r.parse().ok()),
            seed,
        }
    }
}

/// What the recording keeps of the run: what the arguments say, else what the run's
/// supervisor says (an `agp record --instance NAME` of a run started apart).
fn run_info(args: &RecordArgs) -> Result<RunInfo> {
    let read = |p: &std::path::Path| {
        agp_world::read_regular_text(p, agp_world::MAX_CONFIG_FILE_BYTES)
            .with_context(|| format!("cannot read {}", p.display()))
    };
    let asked = if args.scenario.is_none() || args.clock.is_none() || args.seed.is_none() {
        SupervisedRun::ask(&args.instance)
    } else {
        SupervisedRun::default()
    };
    let scenario = args.scenario.clone().or(asked.scenario).unwrap_or_default();
    let is_file = !scenario.is_empty() && !agp_world::BUILTIN_NAMES.contains(&scenario.as_str());
    let scenario_toml = if is_file {
        Some(read(std::path::Path::new(&scenario))?)
    } else {
        None
    };
    let seed = match args.seed.or(asked.seed) {
        Some(s) => Some(s),
        None if !scenario.is_empty() => Some(
            agp_world::Scenario::resolve(&scenario)
                .with_context(|| format!("cannot load the scenario `{scenario}`"))?
                .task
                .seed,
        ),
        None => None,
    };
    let launch_toml = args.launch.as_deref().map(read).transpose()?;
    Ok(RunInfo {
        agp_version: env!("CARGO_PKG_VERSION").to_owned(),
        instance: args.instance.clone(),
        scenario,
        scenario_toml,
        clock: args.clock.clone().or(asked.clock).unwrap_or_default(),
        rate_hz: args.rate_hz.or(asked.rate_hz),
        seed,
        launch_file: args.launch.as_ref().map(|p| p.display().to_string()),
        launch_toml,
        started_unix_ns: std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos() as u64)
            .unwrap_or(0),
    })
}

fn print_stats(stats: &RecordStats, why: &str) {
    println!(
        "agp: recorded {:.1} s ({why}): {} messages, {:.1} MB in {}",
        stats.duration.as_secs_f64(),
        stats.written(),
        stats.file_bytes as f64 / 1e6,
        stats.path.display()
    );
    println!(
        "  {:<20} {:<26} {:>10} {:>8} {:>8}",
        "topic", "schema", "messages", "dropped", "lost"
    );
    for t in &stats.topics {
        println!(
            "  {:<20} {:<26} {:>10} {:>8} {:>8}",
            t.topic, t.type_name, t.written, t.dropped, t.lost
        );
    }
    if stats.dropped() > 0 {
        println!(
            "agp: {} message(s) dropped: the disk did not keep up (the pipeline did not wait)",
            stats.dropped()
        );
    }
    if stats.lost() > 0 {
        println!(
            "agp: {} message(s) lost: overwritten in the recorder's iceoryx2 buffer before it read them (the pipeline did not wait)",
            stats.lost()
        );
    }
}

fn stats_json(stats: &RecordStats) -> serde_json::Value {
    serde_json::json!({
        "file": stats.path.display().to_string(),
        "duration_s": stats.duration.as_secs_f64(),
        "file_bytes": stats.file_bytes,
        "topics": stats.topics.iter().map(|t| serde_json::json!({
            "topic": t.topic,
            "schema": t.type_name,
            "received": t.received,
            "written": t.written,
            "dropped": t.dropped,
            "lost": t.lost,
        })).collect::<Vec<_>>(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_run_is_read_from_physicss_environment_and_its_seed_argument() {
        let environ = b"PATH=/bin\0AGP_SCENARIO=triangle\0AGP_CLOCK=lockstep\0AGP_RATE_HZ=640\0";
        let cmdline = b"/x/agp-physics\0--seed\x007\0";
        assert_eq!(
            SupervisedRun::parse(environ, cmdline),
            SupervisedRun {
                scenario: Some("triangle".into()),
                clock: Some("lockstep".into()),
                rate_hz: Some(640.0),
                seed: Some(7),
            }
        );
        let none = SupervisedRun::parse(b"AGP_SCENARIO=\0", b"agp-physics\0--seed=3\0");
        assert_eq!((none.scenario, none.seed), (None, Some(3)));
    }
}
