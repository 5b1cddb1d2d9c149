//! `agp`: the supervisor CLI. `agp up` runs a launch file; `agp probe push` measures one push.

use agp_harness::{
    bench_adapt, bench_learn, bench_merge, bench_paper, bench_tasks, bench_trajectory, probe,
};

mod bridge;
mod console;
mod control;
mod control_plane;
mod export;
mod goals;
mod profile;
mod rates;
mod record;
mod replay;
mod run_end;
mod signals;
mod slot;
mod up;
mod view;

use std::path::PathBuf;
use std::process::ExitCode;

use agp_launch::{LaunchConfig, LaunchOptions};
use agp_runtime::{InstanceLock, control_client};
use agp_supervisor::{BRIDGE_CHECKS, CheckProcesses, GoalSpec};
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
    ///
    /// Any stop signal (SIGINT, SIGTERM, SIGHUP, SIGQUIT, SIGUSR1, SIGUSR2, SIGPIPE, ...)
    /// stops the run cleanly; so does a closed stdout (`agp up | head -1`: SIGPIPE).
    ///
    /// Exit status: 0 the run ended as asked (its `ends_run` process finished, or `agp
    /// down`) and its task, if any, succeeded; 1 the run ended in error (a process failed
    /// past its restart policy, the verdict could not be judged or written, files of the
    /// instance remain) or could not start; 2 nothing was started: the launch file or the
    /// environment is invalid, or the instance is already up; 3 the task failed (the judge's `NOT placed`, or the
    /// path's end not reached); 128 + N stopped by signal N (130 Ctrl-C, 143 SIGTERM).
    Up(UpArgs),
    /// Show each process of a running instance: state, pid, restarts, uptime.
    Status(StatusArgs),
    /// Stop a running instance: every process, then every file of it.
    Down(DownArgs),
    /// Hot-swap a process of a running instance, make before break: the new one starts
    /// beside the old, takes the latest state, and drives only once it is ready; the old
    /// one stops after the new one's first command was applied. A new process that fails
    /// to start, to become ready or to drive in time is killed and the old one drives on.
    ///
    /// The process must speak the swap protocol (`AGP_EPOCH`, `Ready`, `Driving`), as
    /// `agp-planner` does. Example: agp swap planner --exec target/debug/agp-planner
    ///
    /// With --watch PATH it swaps in PATH each time the file changes (after a `cargo
    /// build`), until Ctrl-C or the instance goes down: the edit-build-swap loop of a
    /// planner author. A build that does not become ready is rolled back, and the watch
    /// goes on.
    Swap(SwapArgs),
    /// Give a live session a goal. Its serving planner (`agp-planner --mode serve`, as in
    /// launch-live.toml) pursues the goals one after the other, in the order given; the
    /// judge scores each by ground truth as it ends, and `agp status` lists them with
    /// their verdicts (`--json`: under `goals`).
    ///
    /// Example: agp goal --instance live --place 300 150 90
    ///
    /// Example: agp goal --instance live --path 0,0 200,0 300,100
    Goal(GoalArgs),
    /// Measure where the time of a control step goes on a running instance: each hop, each
    /// stage and end to end (IR frame published -> the motor command it caused applied),
    /// beside the floor of a bare iceoryx2 ping-pong with the same waiting strategy.
    ///
    /// Example: agp profile --seconds 5 --json profile.json --plot profile.svg
    Profile(profile::ProfileArgs),
    /// Serve a live view of a running instance to Foxglove (a Foxglove WebSocket server):
    /// the robot, the object as the estimator believes it with its uncertainty, the goal,
    /// the IR rays and the affordance-gradient layer. With FILE.mcap it serves a recording
    /// instead, paced by its log times. `view = true` in launch.toml runs it with the run.
    ///
    /// Example: agp view --instance live     (then in Foxglove: Open connection, ws://localhost:8765)
    ///
    /// Example: agp view run.mcap --speed 2
    View(view::ViewArgs),
    /// Record every topic of a running instance (ground truth excepted) into an MCAP file:
    /// one channel per iceoryx2 topic, each message the payload's raw bytes, each schema a
    /// text of its layout. The recorder is a subscriber of its own: the pipeline never waits
    /// for it; what it could not take is counted and said. A launch file's `record =
    /// "FILE"` records a run from its start.
    ///
    /// Example: agp record --instance live --seconds 10 live.mcap
    Record(record::RecordArgs),
    /// Add the scene in Foxglove's protobuf schemas (what `agp record` now writes beside
    /// the raw channels) to a recording made before: IN is copied to OUT with them.
    ///
    /// Example: agp export old.mcap old-foxglove.mcap
    Export(export::ExportArgs),
    /// Play a recorded lockstep run back into physics (its scenario, seed and clock, from
    /// the recording) and check it comes out the same: every recorded frame to the bit, and
    /// the object's final true pose.
    ///
    /// Example: agp replay run.mcap --json replay.json
    Replay(replay::ReplayArgs),
    /// Forward chosen topics of a running instance to a Zenoh session and back, so the
    /// planner of one instance drives the physics and estimator of another that shares no
    /// memory with it (another computer, or another instance on this one). One end listens,
    /// the other connects; nothing is scouted. The link is mutual TLS with the keys of
    /// `agp bridge keygen DIR`, or plain TCP with `--insecure`. A launch file's
    /// `remote = { ... }` process runs it with the run.
    ///
    /// Example: agp bridge keygen results/bridge-keys
    ///
    /// Example: agp bridge --instance lab --side robot --listen tls/127.0.0.1:7447 --tls results/bridge-keys
    ///
    /// Example: agp bridge --instance desk --side planner --connect tls/127.0.0.1:7447 --tls results/bridge-keys
    Bridge(bridge::BridgeArgs),
    #[command(name = "replay-driver", hide = true)]
    ReplayDriver(replay::DriverArgs),
    #[command(name = "profile-floor-pong", hide = true)]
    ProfileFloorPong(profile::FloorPongArgs),
    /// Measure what the simulated world does.
    Probe {
        #[command(subcommand)]
        what: ProbeCmd,
    },
    /// Run a benchmark of the paper (../shared/spec/benchmarks.md) and print our figures
    /// beside the paper's; `--json FILE` writes them for scripts.
    Bench {
        #[command(subcommand)]
        what: BenchCmd,
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
    /// Return once every process is past start-up (running for 2 s, none restarted),
    /// leaving the supervisor in the background (its output goes to
    /// `agp-up-<instance>.log` in the results folder); stop it with `agp down`. A process
    /// that fails at start-up stops the run, and its error line is printed (exit 1).
    #[arg(long)]
    detach: bool,
}

#[derive(Debug, clap::Args)]
struct StatusArgs {
    #[command(flatten)]
    target: control::InstanceArg,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
}

#[derive(Debug, clap::Args)]
#[command(group(clap::ArgGroup::new("what").required(true).args(["place", "path"])))]
struct GoalArgs {
    /// Place the object at X_MM Y_MM (world frame, millimetres) turned THETA_DEG degrees.
    #[arg(long, num_args = 3, value_names = ["X_MM", "Y_MM", "THETA_DEG"], allow_hyphen_values = true)]
    place: Option<Vec<f64>>,
    /// Push the object's centroid along this path: 2 to 32 points X,Y in millimetres.
    #[arg(long, num_args = 2.., value_name = "X,Y", allow_hyphen_values = true)]
    path: Option<Vec<String>>,
    /// With --path: keep the object's heading (its frame's x axis) tangent to the path
    /// within DEG degrees, in (0, 180]; the affordance planner weighs it in every push.
    #[arg(long, value_name = "DEG", requires = "path")]
    keep_heading: Option<f64>,
    #[command(flatten)]
    target: control::InstanceArg,
    /// Print JSON: the goal's id and the goals so far.
    #[arg(long)]
    json: bool,
}

#[derive(Debug, clap::Args)]
struct SwapArgs {
    /// The process of the launch file to swap.
    process: String,
    /// The new executable (default: the one running now).
    #[arg(long, conflicts_with = "watch")]
    exec: Option<PathBuf>,
    /// Swap in this executable now and each time it changes on disk, until Ctrl-C.
    #[arg(long, value_name = "PATH")]
    watch: Option<PathBuf>,
    /// Seconds the new process may take to become ready, and then to drive.
    #[arg(long, default_value_t = 10.0)]
    timeout_s: f64,
    #[command(flatten)]
    target: control::InstanceArg,
    /// Print JSON.
    #[arg(long)]
    json: bool,
    /// The new process's arguments (default: the ones running now).
    #[arg(last = true)]
    args: Option<Vec<String>>,
}

#[derive(Debug, clap::Args)]
struct DownArgs {
    #[command(flatten)]
    target: control::InstanceArg,
    /// Give up waiting for the stop after this many seconds.
    #[arg(long, default_value_t = 60)]
    timeout_s: u64,
    /// Instead, remove the leftovers of benchmarks that died without cleaning (`kill -9`):
    /// every instance `bench-<pid>-*` of this user whose pid no process runs any more (what
    /// every `agp bench` does when it starts).
    #[arg(long, conflicts_with = "instance")]
    stale: bool,
}

#[derive(Debug, Subcommand)]
enum BenchCmd {
    /// The learning phase (benchmarks.md section 1) for each object: the trials of the
    /// paper's protocol, then unseen pushes to test the learned gradients' predictions, and
    /// the pose from one circling, against ground truth. Writes each object's AG file and a
    /// plot of its gradients (like the paper's Fig. 2). The physics runs in-process (the
    /// rapier simulator linked as a library), not as the physics process.
    ///
    /// Example: agp bench learn --scenario triangle --json learn.json
    Learn(bench_learn::BenchLearnArgs),
    /// Put the object at goals (benchmarks.md section 3): random goals 250 to 500 mm from
    /// the start, any orientation, each planner on the same goals; success within the
    /// scenario's tolerance (orientation modulo the object's symmetry), errors, pushes,
    /// simulated and wall time. Runs over the pipeline: lockstep `agp-physics`,
    /// `agp-estimator` serving the AG file, one `agp-planner` process per episode; only
    /// the benchmark (and the `oracle`, which says so) reads ground truth.
    ///
    /// Example: agp bench place --scenario lshape --episodes 20 --json place.json --plot place.svg
    Place(bench_tasks::BenchPlaceArgs),
    /// Push the object along paths (benchmarks.md section 2): a straight line, bends of 45
    /// and 90 deg, an S-curve and a circle arc, each from the object's start; the
    /// affordance and the baseline planner on each path over the seeds, the same seed for
    /// both; the mean distance of the recorded centroid positions to the path, per path
    /// and overall, and the ratio beside the paper's 7.82 / 10.71 (one straight line).
    ///
    /// Example: agp bench trajectory --scenario lshape --paths straight,bend90 --json trajectory.json --plot trajectory.svg
    Trajectory(bench_trajectory::BenchTrajectoryArgs),
    /// All three benchmarks on the paper's objects (learning: triangle, square, lshape,
    /// circle; trajectory: lshape; placement: triangle and lshape with every planner), then
    /// our figures beside the paper's and the project's targets, met or missed. Everything
    /// goes to `--out` (default `results/paper`).
    ///
    /// Example: agp bench paper --json paper.json
    Paper(bench_paper::BenchPaperArgs),
    /// Merge the partial JSONs of a run split with `--shard I/N` (each of one benchmark and
    /// one run: same scenario, same seed list, every seed once) into the JSON one run over
    /// every seed writes; only `wall_time_s` differs (the longest part's).
    ///
    /// Example: agp bench merge part-1.json part-2.json --json place.json --plot seeds.svg
    Merge(bench_merge::BenchMergeArgs),
    /// An AG that keeps learning: learned at the scenario's floor friction, it places the
    /// object at a few goals, then the floor's friction (default 0.25) and/or the object's
    /// mass change and it places it at 20 more, frozen and learning on from every push;
    /// prediction error per push against ground truth, success and recovery per run.
    ///
    /// Example: agp bench adapt --scenario triangle --friction 0.25 --json adapt.json
    Adapt(bench_adapt::BenchAdaptArgs),
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
    agp_runtime::quiet_iceoryx2();
    let cli = Cli::parse();
    if matches!(
        cli.command,
        Cmd::Status(_) | Cmd::Down(_) | Cmd::Swap(_) | Cmd::Goal(_)
    ) {
        // A reader that stops early (`agp status | head -1`) ends these quickly-done
        // commands quietly, as it ends `ls`. The others own children and shared memory to
        // clean up, and keep Rust's default (a write error instead of the signal).
        // SAFETY: signal(2) restoring a default disposition, before any thread exists.
        unsafe { libc::signal(libc::SIGPIPE, libc::SIG_DFL) };
    }
    let result = match &cli.command {
        Cmd::Up(args) => up(args),
        Cmd::Status(args) => status(args),
        Cmd::Down(args) => down(args),
        Cmd::Swap(args) => swap(args),
        Cmd::Goal(args) => goal(args),
        Cmd::Profile(args) => profile::run(args),
        Cmd::Record(args) => record::run(args),
        Cmd::Export(args) => export::run(args),
        Cmd::Replay(args) => replay::run(args),
        Cmd::Bridge(args) => bridge::run(args),
        Cmd::ReplayDriver(args) => replay::drive(args),
        Cmd::View(args) => view::run(args),
        Cmd::ProfileFloorPong(args) => profile::run_floor_pong(args),
        Cmd::Bench {
            what: BenchCmd::Learn(args),
        } => agp_harness::stop::guarded(|| bench_learn::run(args)),
        Cmd::Bench {
            what: BenchCmd::Place(args),
        } => agp_harness::stop::guarded(|| bench_tasks::run_place(args)),
        Cmd::Bench {
            what: BenchCmd::Trajectory(args),
        } => agp_harness::stop::guarded(|| bench_trajectory::run_trajectory(args)),
        Cmd::Bench {
            what: BenchCmd::Paper(args),
        } => agp_harness::stop::guarded(|| bench_paper::run(args)),
        Cmd::Bench {
            what: BenchCmd::Merge(args),
        } => agp_harness::stop::guarded(|| bench_merge::run(args)),
        Cmd::Bench {
            what: BenchCmd::Adapt(args),
        } => agp_harness::stop::guarded(|| bench_adapt::run(args)),
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
            console::warn(format_args!("agp: error: {e:#}"));
            ExitCode::FAILURE
        }
    }
}

fn up(args: &UpArgs) -> Result<u8> {
    // Every child inherits it: a value that names no strategy is refused here, not guessed.
    if let Err(why) = agp_runtime::WaitStrategy::from_env_checked() {
        console::warn(format_args!("agp: error: {why}"));
        console::warn(format_args!("agp: nothing was started"));
        return Ok(run_end::exit::INVALID);
    }
    let exe = std::env::current_exe().context("cannot find the running `agp` executable")?;
    let options = LaunchOptions {
        instance: args.instance.clone(),
        exe_dir: exe.parent().map(PathBuf::from).unwrap_or_default(),
        remote_checks: Some(BRIDGE_CHECKS),
    };
    let config = match LaunchConfig::load(&args.launch, &options)
        .and_then(|c| c.check_processes().map(|()| c))
    {
        Ok(c) => c,
        Err(e) => {
            for line in e.to_string().lines() {
                console::warn(format_args!("agp: error: {line}"));
            }
            console::warn(format_args!("agp: nothing was started"));
            return Ok(run_end::exit::INVALID);
        }
    };
    // An instance another supervisor holds is refused before anything starts, exit 2.
    match InstanceLock::acquire(&control::instance_named(&config.instance)?) {
        Ok(lock) => drop(lock),
        Err(e @ agp_runtime::InstanceLockError::Held { .. }) => {
            console::warn(format_args!("agp: error: {e}"));
            console::warn(format_args!("agp: nothing was started"));
            return Ok(run_end::exit::INVALID);
        }
        Err(e) => return Err(e.into()),
    }
    if args.detach && std::env::var_os(DETACHED_ENV).is_none() {
        return detach(args, &config);
    }
    up::up(&config)
}

/// How long every process of a detached run must have run, none restarted, before
/// `agp up --detach` calls it started: a planner with no AG file, a bad argument or a
/// missing service fails well within it (the one seen: restarted three times, gone in 1.7 s).
const DETACH_SETTLE: std::time::Duration = std::time::Duration::from_secs(2);

/// Set in the environment of the background supervisor `--detach` starts.
const DETACHED_ENV: &str = "AGP_DETACHED";

/// `agp up --detach`: starts `agp up` again in a session of its own with its output in a
/// log file, and returns once its status says every process has run for [`DETACH_SETTLE`]
/// and none was restarted. A process restarted before then failed at start-up: the run is
/// stopped, the error lines of its log are printed, and the exit is 1. An instance another
/// supervisor holds is refused at once, naming that supervisor's pid; and only the status
/// of the supervisor it started (its pid) counts as started.
fn detach(args: &UpArgs, config: &LaunchConfig) -> Result<u8> {
    use std::os::unix::process::CommandExt;
    let instance = crate::control::instance_named(&config.instance)?;
    // Whoever holds the lock is named by it; released at once when no one does.
    drop(InstanceLock::acquire(&instance)?);
    std::fs::create_dir_all(&config.results).with_context(|| {
        format!(
            "cannot create the results folder {}",
            config.results.display()
        )
    })?;
    let log_path = config
        .results
        .join(format!("agp-up-{}.log", config.instance));
    let log = std::fs::File::create(&log_path)
        .with_context(|| format!("cannot create {}", log_path.display()))?;
    let exe = std::env::current_exe().context("cannot find the running `agp` executable")?;
    let mut cmd = std::process::Command::new(exe);
    cmd.arg("up").arg(&args.launch);
    if let Some(i) = &args.instance {
        cmd.args(["--instance", i]);
    }
    cmd.env(DETACHED_ENV, "1")
        .stdin(std::process::Stdio::null())
        .stdout(log.try_clone().context("cannot share the log file")?)
        .stderr(log);
    // SAFETY: setsid is async-signal-safe; the child leaves our session and terminal.
    unsafe {
        cmd.pre_exec(|| {
            if libc::setsid() < 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    let mut child = cmd
        .spawn()
        .context("cannot start the background supervisor")?;
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    let mut started_and_failed: Option<String> = None;
    loop {
        if let Some(status) = child
            .try_wait()
            .context("cannot watch the background supervisor")?
        {
            let text = std::fs::read_to_string(&log_path).unwrap_or_default();
            eprint!("{text}");
            anyhow::bail!(
                "the background supervisor ended ({status}) before every process ran; its log: {}",
                log_path.display()
            );
        }
        if let Some(failing) = started_and_failed.as_deref() {
            // Stop what is left of the run; its log holds each failure's line.
            let _ = control::down(&config.instance, std::time::Duration::from_secs(20));
            let _ = child.wait();
            let text = std::fs::read_to_string(&log_path).unwrap_or_default();
            for line in text.lines().filter(|l| l.contains("error")) {
                console::warn(format_args!("{line}"));
            }
            anyhow::bail!(
                "process `{failing}` of instance `{}` failed at start-up and was restarted; the run was stopped; its log: {}",
                config.instance,
                log_path.display()
            );
        }
        if let Ok(r) = control_client::ask(&config.instance, agp_shared_types::ControlKind::Status)
        {
            let report = control::StatusReport::new(&config.instance, &r);
            if report.supervisor_pid != child.id() {
                anyhow::bail!(
                    "instance `{}` is already up under supervisor pid {}; stop it first or pick another name with `--instance`",
                    config.instance,
                    report.supervisor_pid
                );
            }
            if let Some(p) = report.processes.iter().find(|p| p.restarts > 0) {
                started_and_failed = Some(p.name.clone());
                continue;
            }
            if report.all_running()
                && report
                    .processes
                    .iter()
                    .all(|p| p.uptime_s >= DETACH_SETTLE.as_secs_f64())
            {
                report.print();
                println!(
                    "agp: instance `{}` runs in the background; log {}; stop it with `agp down --instance {}`",
                    config.instance,
                    log_path.display(),
                    config.instance
                );
                return Ok(0);
            }
        }
        if std::time::Instant::now() >= deadline {
            anyhow::bail!(
                "not every process of instance `{}` runs after 60 s; see {} and `agp status --instance {}`",
                config.instance,
                log_path.display(),
                config.instance
            );
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

fn status(args: &StatusArgs) -> Result<u8> {
    let name = args.target.name()?;
    let r = control_client::ask(&name, agp_shared_types::ControlKind::Status)?;
    let report = control::StatusReport::new(&name, &r);
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&report).context("cannot encode the status")?
        );
    } else {
        report.print();
    }
    Ok(0)
}

fn goal(args: &GoalArgs) -> Result<u8> {
    let spec = match (&args.place, &args.path) {
        (Some(p), _) => GoalSpec::place(p[0], p[1], p[2]),
        (None, Some(words)) => GoalSpec::path(words, args.keep_heading),
        (None, None) => unreachable!("clap requires --place or --path"),
    }
    .map_err(|e| anyhow::anyhow!("{e}"))?;
    let name = args.target.name()?;
    let mut request = agp_shared_types::ControlRequest::new(agp_shared_types::ControlKind::Goal);
    request.goal = spec.to_goal();
    let r = control_client::ask_with(&name, request, control_client::ANSWER_TIMEOUT)?;
    if r.ok == 0 {
        anyhow::bail!(
            "instance `{name}` refused the goal: {}",
            agp_shared_types::read_str(&r.message)
        );
    }
    let report = control::StatusReport::new(&name, &r);
    if args.json {
        let doc = serde_json::json!({
            "instance": name,
            "goal_id": r.goal_id,
            "goals": report.goals,
        });
        println!("{doc:#}");
    } else {
        let ahead = report
            .goals
            .iter()
            .filter(|g| g.id < r.goal_id && g.state != "done")
            .count();
        let what = report
            .goals
            .iter()
            .find(|g| g.id == r.goal_id)
            .map_or_else(String::new, goals::GoalReport::what);
        println!(
            "goal {} queued on `{name}`: {what} ({})",
            r.goal_id,
            match ahead {
                0 => "pursued now".to_owned(),
                1 => "after 1 goal".to_owned(),
                n => format!("after {n} goals"),
            }
        );
    }
    Ok(0)
}

fn swap(args: &SwapArgs) -> Result<u8> {
    if !(args.timeout_s.is_finite() && args.timeout_s > 0.0 && args.timeout_s <= 3600.0) {
        anyhow::bail!(
            "--timeout-s must be between 0 and 3600 seconds, got {}",
            args.timeout_s
        );
    }
    let name = args.target.name()?;
    if let Some(path) = &args.watch {
        return watch(args, &name, path);
    }
    let swapped = swap_once(args, &name, args.exec.as_deref())?;
    swapped.print(args.json)?;
    Ok(0)
}

/// A swap that went through.
struct Swapped {
    instance: String,
    process: String,
    pid: Option<u32>,
    epoch: u64,
    handover_us: f64,
    exec: Option<String>,
}

impl Swapped {
    fn print(&self, json: bool) -> Result<()> {
        if json {
            let v = serde_json::json!({
                "instance": self.instance,
                "process": self.process,
                "pid": self.pid,
                "epoch": self.epoch,
                "handover_us": self.handover_us,
                "exec": self.exec,
            });
            console::say(format_args!(
                "{}",
                serde_json::to_string(&v).context("cannot encode JSON")?
            ));
        } else {
            console::say(format_args!(
                "agp: swapped `{}` of instance `{}`: pid {}, epoch {}, handover {:.1} us (ready -> first command applied)",
                self.process,
                self.instance,
                self.pid.map_or("-".to_owned(), |p| p.to_string()),
                self.epoch,
                self.handover_us
            ));
        }
        Ok(())
    }
}

/// Asks the supervisor of `name` for one swap and waits for its end.
fn swap_once(args: &SwapArgs, name: &str, exec: Option<&std::path::Path>) -> Result<Swapped> {
    use agp_shared_types::{ControlKind, ControlRequest, read_str, write_str};
    let mut request = ControlRequest::new(ControlKind::SwapPlanner);
    if args.process.len() > request.name.len() {
        anyhow::bail!("no process is named `{}`", args.process);
    }
    write_str(&mut request.name, &args.process);
    if let Some(exec) = exec {
        let exec = std::fs::canonicalize(exec)
            .with_context(|| format!("--exec {}: no such file", exec.display()))?;
        let text = exec.to_string_lossy();
        if text.len() > request.exec.len() {
            anyhow::bail!(
                "--exec {text}: the path is longer than {} bytes",
                request.exec.len()
            );
        }
        write_str(&mut request.exec, &text);
    }
    if let Some(a) = &args.args
        && !request.set_args(a)
    {
        anyhow::bail!(
            "the arguments do not fit in {} bytes",
            agp_shared_types::SWAP_ARGS_LEN
        );
    }
    let timeout = std::time::Duration::from_secs_f64(args.timeout_s);
    request.value_ns = u64::try_from(timeout.as_nanos()).unwrap_or(u64::MAX);
    // The answer comes when the swap ends: ready, then driving, each within the timeout.
    let r = control_client::ask_with(
        name,
        request,
        timeout * 2 + std::time::Duration::from_secs(5),
    )?;
    if r.ok == 0 {
        anyhow::bail!(
            "swap of `{}` refused: {}",
            args.process,
            read_str(&r.message)
        );
    }
    let report = control::StatusReport::new(name, &r);
    let entry = report.processes.iter().find(|p| p.name == args.process);
    Ok(Swapped {
        instance: name.to_owned(),
        process: args.process.clone(),
        pid: entry.and_then(|p| p.pid),
        epoch: r.active_epoch,
        handover_us: r.handover_ns as f64 * 1e-3,
        exec: entry.map(|p| p.exec.clone()),
    })
}

/// What identifies one build of a file: a new build changes at least one.
fn file_stamp(path: &std::path::Path) -> Option<(std::time::SystemTime, u64, u64)> {
    use std::os::unix::fs::MetadataExt;
    let m = std::fs::metadata(path).ok()?;
    Some((m.modified().ok()?, m.len(), m.ino()))
}

/// `agp swap PROCESS --watch PATH`: swaps PATH in now and after every change, until a stop
/// signal or the end of the instance. Each swap is printed (one JSON object per line with
/// `--json`); a refused one is reported and the watch goes on with the old process driving.
fn watch(args: &SwapArgs, name: &str, path: &std::path::Path) -> Result<u8> {
    use std::time::Duration;
    /// How often the file is looked at, and how long it must stay unchanged before a swap
    /// (a linker writes the file in several steps).
    const LOOK: Duration = Duration::from_millis(100);
    const SETTLE: Duration = Duration::from_millis(300);
    signals::install().context("cannot install the signal handlers")?;
    let instance = crate::control::instance_named(name)?;
    if file_stamp(path).is_none() {
        anyhow::bail!("--watch {}: no such file", path.display());
    }
    console::warn(format_args!(
        "agp: watching {} for `{}` of instance `{name}`: each new build is swapped in (Ctrl-C to stop)",
        path.display(),
        args.process
    ));
    let mut swapped_stamp = None;
    let mut swaps = 0u32;
    let mut refused = 0u32;
    loop {
        if let Some(s) = signals::first() {
            console::warn(format_args!(
                "agp: watch stopped by {}: {swaps} swaps, {refused} refused",
                signals::name(s)
            ));
            return Ok(0);
        }
        if !InstanceLock::is_held(&instance) {
            console::warn(format_args!(
                "agp: instance `{name}` is down: watch ends ({swaps} swaps, {refused} refused)"
            ));
            return Ok(0);
        }
        let stamp = file_stamp(path);
        if stamp.is_some() && stamp != swapped_stamp {
            std::thread::sleep(SETTLE);
            if file_stamp(path) != stamp {
                continue;
            }
            swapped_stamp = stamp;
            match swap_once(args, name, Some(path)) {
                Ok(s) => {
                    swaps += 1;
                    s.print(args.json)?;
                }
                Err(e) => {
                    refused += 1;
                    if args.json {
                        console::say(format_args!(
                            "{}",
                            serde_json::json!({"instance": name, "process": args.process, "refused": format!("{e:#}")})
                        ));
                    } else {
                        console::say(format_args!(
                            "agp: {e:#}; the running `{}` drives on",
                            args.process
                        ));
                    }
                }
            }
        }
        std::thread::sleep(LOOK);
    }
}

fn down(args: &DownArgs) -> Result<u8> {
    if args.stale {
        return control::down_stale();
    }
    let name = args.target.name()?;
    match control::down(&name, std::time::Duration::from_secs(args.timeout_s))? {
        control::DownOutcome::Stopped => println!("agp: instance `{name}` is down"),
        control::DownOutcome::Cleaned { removed } => println!(
            "agp: instance `{name}` had no supervisor (it died); removed {removed} leftover file(s): it is down"
        ),
    }
    Ok(0)
}
