//! `agp`: the supervisor CLI: the verbs' clap definitions and their dispatch. Each verb is a
//! module of its own (`up`, `status`, `down`, `swap`, `goal`, `profile`, ...); the benchmarks
//! and the probe are the harness's (`agp_harness`).

use agp_harness::{
    bench_adapt, bench_learn, bench_merge, bench_paper, bench_tasks, bench_trajectory, probe,
};

mod bridge_process;
mod console;
mod control;
mod control_plane;
mod detach;
mod down;
mod export;
mod goal;
mod goals;
mod profile;
mod rates;
mod record;
mod replay;
mod run_end;
mod signals;
mod slot;
mod status;
mod swap;
mod up;
mod view;

use std::process::ExitCode;

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
    Up(up::UpArgs),
    /// Show each process of a running instance: state, pid, restarts, uptime.
    Status(status::StatusArgs),
    /// Stop a running instance: every process, then every file of it.
    Down(down::DownArgs),
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
    Swap(swap::SwapArgs),
    /// Give a live session a goal. Its serving planner (`agp-planner --mode serve`, as in
    /// launch-live.toml) pursues the goals one after the other, in the order given; the
    /// judge scores each by ground truth as it ends, and `agp status` lists them with
    /// their verdicts (`--json`: under `goals`).
    ///
    /// Example: agp goal --instance live --place 300 150 90
    ///
    /// Example: agp goal --instance live --path 0,0 200,0 300,100
    Goal(goal::GoalArgs),
    /// Measure where the time of a control step goes on a running instance: each hop, each
    /// stage and end to end (IR frame published -> the motor command it caused applied),
    /// beside the floor of a bare iceoryx2 ping-pong with the same waiting strategy.
    ///
    /// Across a bridge (an instance with a `remote` process, whose planner runs in another
    /// instance): profile the robot's instance. Its frames carry the planner side's stamps
    /// too, so the two hops that cross the link (estimator->planner, planner->physics) are
    /// measured, and in the same run the link's floor: a bare Zenoh ping-pong between two
    /// `agp` processes on the bridge's own transport (mutual TLS with its key folder, or
    /// plain TCP if it runs `insecure`), each bridged hop given as a ratio to it ("link
    /// floor" line; `link_floor` in the JSON). Profile a TLS bridge and a plain one to set
    /// them side by side (tools/bench_bridge_profile.py does both, repeated).
    ///
    /// Example: agp profile --seconds 5 --json profile.json --plot profile.svg
    ///
    /// Example: agp profile --instance bridge_robot --seconds 5 --floor-seconds 2
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
    /// `remote = { ... }` process runs it with the run. It runs the bridge binary
    /// `agp-bridge` beside `agp` (built by `cargo build --release --workspace --bins`).
    ///
    /// Example: agp bridge keygen results/bridge-keys
    ///
    /// Example: agp bridge --instance lab --side robot --listen tls/127.0.0.1:7447 --tls results/bridge-keys
    ///
    /// Example: agp bridge --instance desk --side planner --connect tls/127.0.0.1:7447 --tls results/bridge-keys
    Bridge(bridge_process::BridgeArgs),
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
    /// Place an object never pushed before (issue 33): no learning phase, no AG file; each
    /// episode's estimator builds the gradient from the contact prior of its first
    /// circling and learns on from the episode's own pushes. The goals are `agp bench
    /// place`'s, so `agp bench place --planners affordance` (learn first) stands beside it.
    ///
    /// Example: agp bench online --scenario libs/world/scenarios/pentagon.toml --json online.json
    Online(agp_harness::bench_online::BenchOnlineArgs),
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
        Cmd::Up(args) => up::start(args),
        Cmd::Status(args) => status::run(args),
        Cmd::Down(args) => down::run(args),
        Cmd::Swap(args) => swap::run(args),
        Cmd::Goal(args) => goal::run(args),
        Cmd::Profile(args) => profile::run(args),
        Cmd::Record(args) => record::run(args),
        Cmd::Export(args) => export::run(args),
        Cmd::Replay(args) => replay::run(args),
        Cmd::Bridge(args) => bridge_process::run(args),
        Cmd::ReplayDriver(args) => replay::drive(args),
        Cmd::View(args) => view::run(args),
        Cmd::ProfileFloorPong(args) => profile::run_floor_pong(args),
        Cmd::Bench {
            what: BenchCmd::Learn(args),
        } if args.curve.is_empty() => agp_harness::stop::guarded(|| bench_learn::run(args)),
        Cmd::Bench {
            what: BenchCmd::Learn(args),
        } => agp_harness::stop::guarded(|| {
            agp_harness::learn_curve::run_curve(args).map(|_| ExitCode::SUCCESS)
        }),
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
        Cmd::Bench {
            what: BenchCmd::Online(args),
        } => agp_harness::stop::guarded(|| agp_harness::bench_online::run(args)),
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
