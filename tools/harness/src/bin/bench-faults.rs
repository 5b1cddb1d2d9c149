//! The fault campaign: real pipelines under `agp up` (release binaries), faults injected at
//! random moments, and what survived.
//!
//! Runs cycle through three phases: the learning phase (lockstep, a few trials per alpha,
//! its verdict the saved AG file), the placement task (lockstep, the estimator serving an
//! AG file learned once by `agp bench learn` at the start, its verdict the judge's) and a
//! live session on the realtime clock (the planner serving goals, `--mode serve`, pursuing
//! one `agp goal`, queued again, as its user would, after its supervisor was killed and
//! brought up again: the queue lives in the supervisor; its verdict the goal reached, or
//! ended by the planner with its reason, then `agp down`). Then the bridge phase: placements split over two instances joined by
//! `agp bridge` through a TCP proxy, with faults across the link (`kill -9` and SIGSTOP of
//! the far bridge and of the far supervisor, the link cut then restored); their verdict the
//! judge's, every step applied once (physics's step log) and no step applied while the link
//! was cut. Into each run go
//! several faults, drawn from a shuffled deck (seeded): `kill -9` of each child, SIGSTOP
//! then SIGCONT after a random pause of each child and of the supervisor, and `kill -9` of
//! the supervisor followed by a fresh `agp up` of the same instance, which must clean what
//! the dead one left and run again.
//!
//! A fault is survived when the pipeline is back: the child killed is running again with a
//! higher restart count, the process stopped is running again, the new supervisor answers
//! with every child running, and (lockstep) physics's step log advances again; or the run
//! reached its end with status 0 meanwhile. Its recovery time runs from the kill (or the
//! SIGCONT) to that moment. A fault not survived ends its run's faults.
//!
//! ```text
//! cargo build --release --workspace --bins
//! target/release/bench-faults --faults 500 --seed 1 --json faults.json
//! ```

use std::collections::BTreeMap;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::{Duration, Instant};

use agp_affordance::AffordanceGradient;
use agp_harness::link_proxy::LinkProxy;
use agp_harness::pipeline::{
    Bins, LaunchSpec, Phase, Session, Status, StepCounter, instance_files, is_interrupt,
    last_line_with, reap_children, signal, sleep_checked, step_log_path,
};
use agp_harness::watchdog_stops::{LoggedStop, WatchdogLog, stop_of_fault};
use agp_runtime::install_shutdown_handler;
use agp_shared_types::monotonic_ns;
use agp_world::Rng;
use anyhow::{Context, Result, anyhow, bail};
use clap::Parser;
use serde_json::{Value, json};

/// Injects faults into real pipelines at random moments and reports what survived.
#[derive(Debug, Parser)]
#[command(version)]
struct Args {
    /// Folder of the release binaries (`agp`, `agp-physics`, `agp-estimator`,
    /// `agp-planner`) [default: the folder of this executable].
    #[arg(long, value_name = "DIR")]
    bin_dir: Option<PathBuf>,
    /// Faults to inject in all.
    #[arg(long, default_value_t = 500, value_parser = clap::value_parser!(u32).range(1..))]
    faults: u32,
    /// Seed of the random moments, pauses and the order of the faults.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Most faults injected into one run (a run that ends first gets fewer).
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u32).range(1..))]
    faults_per_run: u32,
    /// Trials per alpha of the learning runs (the paper's 60 would take minutes per run).
    #[arg(long, default_value_t = 6, value_parser = clap::value_parser!(u32).range(1..))]
    trials_per_alpha: u32,
    /// A fault whose pipeline is not back within this many seconds is not survived.
    #[arg(long, default_value_t = 45.0)]
    recovery_timeout_s: f64,
    /// A learning or placement run that has not ended this long after its last fault
    /// is stopped and counted lost.
    #[arg(long, default_value_t = 240.0)]
    run_timeout_s: f64,
    /// Also write the figures and every fault as JSON to this file.
    #[arg(long, value_name = "FILE")]
    json: Option<PathBuf>,
    /// The benchmark phase, after the faults: this many stop signals (SIGINT, SIGTERM,
    /// SIGHUP, to the bench's process group or to it alone, a quarter of them sent twice)
    /// at random moments to running `agp bench place` commands over the pipeline; each
    /// must exit 128 + N and leave no process and no file, and every partial JSON must
    /// read back. 0 skips the phase.
    #[arg(long, default_value_t = 50)]
    bench_signals: u32,
    /// Run the benchmark phase only (no fault campaign).
    #[arg(long)]
    bench_signals_only: bool,
    /// The bridge phase, after the three phases of one instance: this many faults across a
    /// bridge's link, into placements split over two instances (the planner's side reached
    /// through a TCP proxy): `kill -9` and SIGSTOP of the far bridge and of the far
    /// supervisor, and the link cut then restored. 0 skips the phase.
    #[arg(long, default_value_t = 200)]
    bridge_faults: u32,
    /// The live bridge phase, after the bridge phase: this many faults across the link (the
    /// same five kinds) into live sessions on the realtime clock split over two instances,
    /// the far planner (`--mode serve`) pursuing a goal queued on the robot's side. Physics's
    /// own account must show the robot stopped by its watchdog and never moved beyond one
    /// watchdog period while the link was down. 0 skips the phase.
    #[arg(long, default_value_t = 200)]
    bridge_live_faults: u32,
    /// Run the two bridge phases only (either skipped by its count of 0).
    #[arg(long, conflicts_with = "bench_signals_only")]
    bridge_only: bool,
    /// The phases of one instance to cycle through, comma-separated: learn, place, live.
    #[arg(long, default_value = "learn,place,live", value_parser = parse_phases)]
    phases: PhaseList,
}

/// The phases `--phases` names, in the order given.
#[derive(Debug, Clone)]
struct PhaseList(Vec<Phase>);

fn parse_phases(s: &str) -> Result<PhaseList, String> {
    let mut v = Vec::new();
    for name in s.split(',').map(str::trim).filter(|n| !n.is_empty()) {
        let p = Phase::ALL
            .into_iter()
            .find(|p| p.as_str() == name)
            .ok_or_else(|| format!("unknown phase `{name}`: learn, place or live"))?;
        if !v.contains(&p) {
            v.push(p);
        }
    }
    if v.is_empty() {
        return Err("name at least one phase: learn, place, live".to_owned());
    }
    Ok(PhaseList(v))
}

/// The instance of one run of the campaign: `bench-<pid>-<tag>`, as every benchmark names
/// its pipelines, so that what a campaign killed with -9 left (a supervisor it had stopped
/// with SIGSTOP cannot clean when it dies) is removed by the next `agp bench` or by
/// `agp down --stale` once no process runs as its pid. `tag`: the phase's letter (`f` one
/// instance, `l` a placement across the bridge, `v` a live session across it), the run's
/// index, and `r`/`p` for a bridge run's two sides: at most 20 characters with a pid of 7
/// digits.
fn run_instance(tag: &str) -> String {
    format!("bench-{}-{tag}", std::process::id())
}

/// The most restarts a launch file may give a child (`agp`'s own limit is 1000).
const MAX_RESTARTS: u32 = 1000;

/// Faults in a row that find nothing to hit (the supervisor not answering, the target not
/// running) before the run is given up as lost.
const MAX_SKIPS: u32 = 40;

/// Which process a fault hits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Target {
    Physics,
    Estimator,
    Planner,
    Supervisor,
}

impl Target {
    fn child_name(self) -> Option<&'static str> {
        match self {
            Target::Physics => Some("physics"),
            Target::Estimator => Some("estimator"),
            Target::Planner => Some("planner"),
            Target::Supervisor => None,
        }
    }

    fn as_str(self) -> &'static str {
        self.child_name().unwrap_or("supervisor")
    }
}

/// What a fault does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Action {
    /// `kill -9`; for the supervisor, followed by a fresh `agp up` of the instance.
    Kill,
    /// SIGSTOP, a random pause, SIGCONT.
    Stop,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
struct FaultKind {
    action: Action,
    target: Target,
}

impl FaultKind {
    const ALL: [FaultKind; 8] = [
        FaultKind::new(Action::Kill, Target::Physics),
        FaultKind::new(Action::Kill, Target::Estimator),
        FaultKind::new(Action::Kill, Target::Planner),
        FaultKind::new(Action::Stop, Target::Physics),
        FaultKind::new(Action::Stop, Target::Estimator),
        FaultKind::new(Action::Stop, Target::Planner),
        FaultKind::new(Action::Stop, Target::Supervisor),
        FaultKind::new(Action::Kill, Target::Supervisor),
    ];

    const fn new(action: Action, target: Target) -> Self {
        Self { action, target }
    }

    fn label(self) -> String {
        match (self.action, self.target) {
            (Action::Kill, Target::Supervisor) => "kill -9 supervisor, up again".to_owned(),
            (Action::Kill, t) => format!("kill -9 {}", t.as_str()),
            (Action::Stop, t) => format!("stop/cont {}", t.as_str()),
        }
    }

    /// Whether runs of `phase` have the process this fault hits.
    fn applies_to(self, phase: Phase) -> bool {
        self.target
            .child_name()
            .is_none_or(|c| children(phase).contains(&c))
    }
}

/// The faults of a phase, drawn in a shuffled order, reshuffled when all were drawn, so
/// every kind is injected about as often.
struct Deck {
    kinds: Vec<FaultKind>,
    next: usize,
}

impl Deck {
    fn new(phase: Phase) -> Self {
        Self {
            kinds: FaultKind::ALL
                .into_iter()
                .filter(|k| k.applies_to(phase))
                .collect(),
            next: usize::MAX,
        }
    }

    fn draw(&mut self, rng: &mut Rng) -> FaultKind {
        if self.next >= self.kinds.len() {
            for i in (1..self.kinds.len()).rev() {
                let j = (rng.next_u64() % (i as u64 + 1)) as usize;
                self.kinds.swap(i, j);
            }
            self.next = 0;
        }
        self.next += 1;
        self.kinds[self.next - 1]
    }
}

/// One injected fault and what came of it.
#[derive(Debug, Clone)]
struct FaultRecord {
    run: usize,
    phase: Phase,
    kind: FaultKind,
    /// Seconds into the run when it was injected.
    at_s: f64,
    /// SIGSTOP to SIGCONT, ms.
    pause_ms: Option<f64>,
    survived: bool,
    /// Fault (kill, or SIGCONT) to the pipeline back, ms.
    recovery_ms: Option<f64>,
    note: String,
}

/// One run and its verdict.
#[derive(Debug, Clone)]
struct RunRecord {
    index: usize,
    phase: Phase,
    instance: String,
    faults: u32,
    /// `agp up` started for it (more than one when its supervisor was killed).
    ups: u32,
    /// The run's last supervisor exited with status 0 at the run's end.
    completed: bool,
    /// The verdict: the AG file (learn), the judge's (place); `None` for live runs.
    correct: Option<bool>,
    exit: Option<i32>,
    /// Files of the instance left once its last supervisor and every child were gone.
    files_left: usize,
    wall_s: f64,
    note: String,
}

/// How a wait for the pipeline to be back ended.
enum Back {
    /// After this long since the fault.
    In(Duration),
    /// The run's supervisor exited meanwhile, with this status code.
    Ended(Option<i32>),
    /// Not within the recovery timeout; what was still missing.
    Never(String),
}

/// One run under way: its session (supervisor, folder, pids seen: stopped with nothing
/// left on every way out) and physics's step log.
struct Run<'a> {
    session: Session<'a>,
    phase: Phase,
    ups: u32,
    steps: StepCounter,
    started: Instant,
}

impl<'a> Run<'a> {
    fn start(bins: &'a Bins, phase: Phase, instance: &str, launch: PathBuf) -> Result<Self> {
        let session = Session::start(bins, instance, launch)?;
        Ok(Self {
            steps: StepCounter::new(step_log_path(&session.dir)),
            session,
            phase,
            ups: 1,
            started: Instant::now(),
        })
    }

    fn ended(&mut self) -> Option<Option<i32>> {
        self.session.ended()
    }

    fn physics_publishes(&self, s: &Status) -> bool {
        self.phase.has_step_log()
            || s.child("physics")
                .and_then(|p| p.rate_per_s)
                .is_some_and(|r| r > 0.0)
    }

    /// Whether the status shows every child running, physics publishing (realtime).
    fn all_back(&self, s: &Status) -> bool {
        s.all_running(children(self.phase)) && self.physics_publishes(s)
    }

    /// Waits until `back` holds in a status and then (lockstep) physics's step log grows;
    /// the time is taken from `since`.
    fn wait_back(
        &mut self,
        since: Instant,
        timeout: Duration,
        what: &str,
        back: impl Fn(&Self, &Status) -> bool,
    ) -> Result<Back> {
        let deadline = since + timeout;
        let mut steps_at_back = None;
        loop {
            sleep_checked(Duration::ZERO)?;
            if let Some(code) = self.ended() {
                return Ok(Back::Ended(code));
            }
            if Instant::now() >= deadline {
                let missing = if steps_at_back.is_some() {
                    format!("{what} back but no physics step within {timeout:?}")
                } else {
                    format!("{what} not back within {timeout:?}")
                };
                return Ok(Back::Never(missing));
            }
            match steps_at_back {
                None => {
                    if let Some(s) = self.session.status()?
                        && back(self, &s)
                    {
                        if !self.phase.has_step_log() {
                            return Ok(Back::In(since.elapsed()));
                        }
                        steps_at_back = Some(self.steps.count());
                    }
                }
                Some(at) => {
                    if self.steps.count() > at {
                        return Ok(Back::In(since.elapsed()));
                    }
                }
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// Waits until every child runs (the run has started).
    fn wait_all_running(&mut self, timeout: Duration) -> Result<Back> {
        let since = Instant::now();
        self.wait_back(since, timeout, "every child", |r, s| r.all_back(s))
    }

    /// A current status, if the supervisor answers within a few tries.
    fn fresh_status(&mut self) -> Result<Option<Status>> {
        for _ in 0..50 {
            if self.ended().is_some() {
                return Ok(None);
            }
            if let Some(s) = self.session.status()? {
                return Ok(Some(s));
            }
            sleep_checked(Duration::from_millis(50))?;
        }
        Ok(None)
    }
}

struct Campaign {
    args: Args,
    bins: Bins,
    rng: Rng,
    work: tempfile::TempDir,
    ag_file: PathBuf,
    decks: BTreeMap<Phase, Deck>,
    faults: Vec<FaultRecord>,
    runs: Vec<RunRecord>,
    started: Instant,
}

impl Campaign {
    fn injected(&self) -> u32 {
        self.faults.len() as u32
    }

    /// The progress line: rewritten in place on a terminal; otherwise a line at each run's
    /// start.
    fn progress(&self, run: usize, phase: Phase, what: &str) {
        let survived = self.faults.iter().filter(|f| f.survived).count();
        let line = format!(
            "[{}/{}] {:.0} s, run {run} ({}): {what}; {survived} survived",
            self.injected(),
            self.args.faults,
            self.started.elapsed().as_secs_f64(),
            phase.as_str()
        );
        if std::io::stderr().is_terminal() {
            eprint!("\r\x1b[2K{line}");
        } else if what == "starting" {
            eprintln!("{line}");
        }
    }

    /// One run of `phase` with at most `budget` faults.
    fn run(&mut self, index: usize, phase: Phase, budget: u32) -> Result<()> {
        let instance = run_instance(&format!("f{index:04}"));
        if !instance_files(&instance)?.is_empty() {
            bail!("instance `{instance}` already has files; remove them or run again");
        }
        let dir = self.work.path().join(format!("run-{index:04}"));
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("cannot create {}", dir.display()))?;
        let spec = LaunchSpec {
            phase,
            instance: &instance,
            trials_per_alpha: self.args.trials_per_alpha,
            ag_file: Some(&self.ag_file),
            max_restarts: self.args.faults_per_run.saturating_mul(4).min(MAX_RESTARTS),
        };
        let launch = write_launch(&spec, &self.bins, &dir, &self.ag_file)?;
        let bins = self.bins.clone();
        let mut run = Run::start(&bins, phase, &instance, launch)?;
        let recovery = Duration::from_secs_f64(self.args.recovery_timeout_s);
        let mut record = RunRecord {
            index,
            phase,
            instance,
            faults: 0,
            ups: 1,
            completed: false,
            correct: None,
            exit: None,
            files_left: 0,
            wall_s: 0.0,
            note: String::new(),
        };
        self.progress(index, phase, "starting");
        let mut lost = match run.wait_all_running(Duration::from_secs(60))? {
            Back::In(_) => None,
            Back::Ended(Some(0)) => None,
            Back::Ended(code) => Some(format!(
                "the run ended before every child ran (status {code:?}){}",
                last_error(&dir)
            )),
            Back::Never(what) => Some(format!("never started: {what}")),
        };
        let mut goal_end = None;
        if lost.is_none() && phase == Phase::Live {
            lost = queue_goal(&run).err().map(|e| format!("{e:#}"));
        }
        let mut skips = 0;
        while lost.is_none() && record.faults < budget && run.ended().is_none() {
            let gap = self.rng.range(0.1, 1.0);
            sleep_checked(Duration::from_secs_f64(gap))?;
            if run.ended().is_some() {
                break;
            }
            let kind = self
                .decks
                .get_mut(&phase)
                .expect("a deck per phase")
                .draw(&mut self.rng);
            self.progress(index, phase, &kind.label());
            let Some(fault) = self.inject(&mut run, index, kind, recovery)? else {
                skips += 1;
                if skips >= MAX_SKIPS {
                    lost = Some(format!(
                        "{skips} faults in a row found nothing to hit: the supervisor did not answer `agp status` or a child stayed down ({})",
                        run.session.status()?.map_or("no status".to_owned(), |s| s
                            .processes
                            .iter()
                            .map(|p| format!("{} {} restarts {}", p.name, p.state, p.restarts))
                            .collect::<Vec<_>>()
                            .join(", "))
                    ));
                }
                continue;
            };
            skips = 0;
            record.faults += 1;
            if !fault.survived {
                lost = Some(format!("{}: {}", kind.label(), fault.note));
            }
            self.faults.push(fault);
        }
        // The run's end: learning and placement end by themselves; the live session is
        // brought down as a user would.
        if lost.is_none() {
            self.progress(index, phase, "to the run's end");
            if phase == Phase::Live && run.ended().is_none() {
                self.progress(index, phase, "the goal's end");
                goal_end = await_goal(&mut run, Duration::from_secs_f64(self.args.run_timeout_s))?;
                if !run.session.down()? {
                    record.note = "`agp down` failed".to_owned();
                }
            }
            let timeout = Duration::from_secs_f64(self.args.run_timeout_s);
            let end = Instant::now() + timeout;
            while run.ended().is_none() && Instant::now() < end {
                sleep_checked(Duration::from_millis(20))?;
            }
            if run.ended().is_none() {
                lost = Some(format!("not ended {timeout:?} after its last fault"));
            }
        }
        record.ups = run.ups;
        record.exit = run.ended().flatten();
        record.completed = lost.is_none() && record.exit == Some(0);
        if !record.completed && lost.is_none() {
            lost = Some(format!(
                "ended with status {:?}{}",
                record.exit,
                last_error(&dir)
            ));
        }
        // Every process gone, then count what the instance left.
        record.files_left = run.session.shut();
        record.wall_s = run.started.elapsed().as_secs_f64();
        record.correct = match phase {
            Phase::Learn => Some(check_learned(
                &dir,
                self.args.trials_per_alpha,
                &mut record.note,
            )),
            Phase::Place => Some(check_placed(&dir, &record.instance, &mut record.note)),
            Phase::Live => Some(check_goal(goal_end.as_ref(), &mut record.note)),
        };
        if let Some(why) = lost {
            if !record.note.is_empty() {
                record.note.insert_str(0, "; ");
            }
            record.note.insert_str(0, &why);
        }
        self.runs.push(record);
        Ok(())
    }

    /// Injects `kind` into `run`; `None` when its target is not running just now (the fault
    /// is not counted and another is drawn).
    fn inject(
        &mut self,
        run: &mut Run<'_>,
        index: usize,
        kind: FaultKind,
        timeout: Duration,
    ) -> Result<Option<FaultRecord>> {
        let Some(before) = run.fresh_status()? else {
            return Ok(None);
        };
        let at_s = run.started.elapsed().as_secs_f64();
        let mut record = FaultRecord {
            run: index,
            phase: run.phase,
            kind,
            at_s,
            pause_ms: None,
            survived: false,
            recovery_ms: None,
            note: String::new(),
        };
        let back = match (kind.action, kind.target.child_name()) {
            (action, Some(name)) => {
                let Some(child) = before.child(name).filter(|c| c.running()).cloned() else {
                    return Ok(None);
                };
                let pid = child.pid.expect("a running child has a pid");
                if !self.bins.owns(pid) {
                    return Ok(None);
                }
                match action {
                    Action::Kill => {
                        let t0 = Instant::now();
                        signal(pid, libc::SIGKILL);
                        run.wait_back(t0, timeout, name, |r, s| {
                            s.child(name).is_some_and(|c| {
                                c.running() && (c.restarts > child.restarts || c.pid != Some(pid))
                            }) && r.physics_publishes(s)
                        })?
                    }
                    Action::Stop => {
                        let t0 = self.pause(run, pid, &mut record)?;
                        run.wait_back(t0, timeout, name, |r, s| {
                            s.child(name).is_some_and(|c| c.running()) && r.physics_publishes(s)
                        })?
                    }
                }
            }
            (Action::Stop, None) => {
                let pid = run.session.sup().pid();
                let t0 = self.pause(run, pid, &mut record)?;
                run.wait_back(t0, timeout, "the supervisor", |r, s| r.all_back(s))?
            }
            (Action::Kill, None) => {
                let t0 = Instant::now();
                let children: Vec<u32> = before.processes.iter().filter_map(|p| p.pid).collect();
                let outlived = kill_supervisor(&mut run.session, &self.bins, &children);
                if outlived > 0 {
                    record.note = format!(
                        "{outlived} child(ren) outlived the killed supervisor (killed by the tool); "
                    );
                }
                let left = instance_files(&run.session.instance)?.len();
                record.note += &format!("{left} file(s) left by the dead supervisor; ");
                run.session.up_again()?;
                run.ups += 1;
                let back =
                    run.wait_back(t0, timeout, "a new supervisor with every child", |r, s| {
                        r.all_back(s)
                    })?;
                // A live session's goals lived in the dead supervisor: queue the goal again,
                // as its user would after bringing the session back.
                if run.phase == Phase::Live
                    && matches!(back, Back::In(_))
                    && let Err(e) = queue_goal(run)
                {
                    record.note += &format!("{e:#}; ");
                    Back::Never("the goal could not be queued again".to_owned())
                } else {
                    back
                }
            }
        };
        match back {
            Back::In(d) => {
                record.survived = !record.note.contains("outlived");
                record.recovery_ms = Some(d.as_secs_f64() * 1e3);
            }
            Back::Ended(Some(0)) => {
                record.survived = !record.note.contains("outlived");
                record.note += "the run reached its end meanwhile, status 0";
            }
            Back::Ended(code) => {
                record.note += &format!(
                    "the run ended with status {}{}",
                    code.map_or("(a signal)".to_owned(), |c| c.to_string()),
                    last_error(&run.session.dir)
                );
            }
            Back::Never(what) => record.note += &what,
        }
        Ok(Some(record))
    }

    /// SIGSTOP to `pid`, a random pause, SIGCONT; returns the moment of SIGCONT.
    fn pause(&mut self, run: &mut Run<'_>, pid: u32, record: &mut FaultRecord) -> Result<Instant> {
        let pause = Duration::from_secs_f64(self.rng.range(0.1, 2.0));
        pause_process(&mut run.session, pid, pause)?;
        record.pause_ms = Some(pause.as_secs_f64() * 1e3);
        Ok(Instant::now())
    }
}

/// SIGSTOP to `pid` (the supervisor of `session` or one of its children), `pause`, then
/// SIGCONT, whatever the sleep ended with: the pid is `session.stopped` meanwhile, so a tool
/// interrupted mid-pause continues it before it stops the session. Every phase's
/// stop/continue fault is this.
fn pause_process(session: &mut Session<'_>, pid: u32, pause: Duration) -> Result<()> {
    session.stopped = Some(pid);
    signal(pid, libc::SIGSTOP);
    let slept = sleep_checked(pause);
    signal(pid, libc::SIGCONT);
    session.stopped = None;
    slept
}

/// `kill -9` of the supervisor of `session`, whose children were `children`: each dies
/// with it (PR_SET_PDEATHSIG); any that outlives it is killed by the tool and counted in
/// what this returns. The caller then starts `agp up` again ([`Session::up_again`]), which
/// must clean what the dead one left.
fn kill_supervisor(session: &mut Session<'_>, bins: &Bins, children: &[u32]) -> usize {
    session.sup().signal(libc::SIGKILL);
    session.sup().wait_exit(Duration::from_secs(10));
    reap_children(bins, children, Duration::from_secs(10))
}

/// The children a run of `phase` has: the live session's planner serves goals.
fn children(phase: Phase) -> &'static [&'static str] {
    match phase {
        Phase::Live => &["physics", "estimator", "planner"],
        p => p.children(),
    }
}

/// The goal each live session pursues: the triangle where it starts, so the planner has to
/// find it on the realtime clock (circling it on the frames physics publishes at 640 Hz of
/// wall time, steering round it by commands that must keep up) and judge that it is there.
const LIVE_GOAL: [&str; 3] = ["0", "0", "0"];

/// Writes the run's launch file: the pipeline's, and for a live session a planner serving
/// goals (`--mode serve`) beside an estimator serving `ag` (`pipeline.rs`'s live run, which
/// `bench-soak` keeps as it is, has neither).
fn write_launch(spec: &LaunchSpec<'_>, bins: &Bins, dir: &Path, ag: &Path) -> Result<PathBuf> {
    if spec.phase != Phase::Live {
        return spec.write(bins, dir);
    }
    let text = spec.text(bins, dir)?;
    let estimator = format!("exec = \"{}\"\n", bins.path("agp-estimator").display());
    let restart = format!(
        "restart = {{ policy = \"on-failure\", max_restarts = {}, backoff_ms = 10 }}\nstop_grace_ms = 1000\n",
        spec.max_restarts
    );
    if !text.contains(&estimator) {
        bail!("the live session's launch file names no estimator");
    }
    let text = text.replace(
        &estimator,
        &format!("{estimator}args = [\"--load\", \"{}\"]\n", ag.display()),
    ) + &format!(
        "[[process]]\nname = \"planner\"\nexec = \"{}\"\nargs = [\"--mode\", \"serve\", \"--planner\", \"affordance\"]\n{restart}",
        bins.path("agp-planner").display()
    );
    let path = dir.join("launch.toml");
    std::fs::write(&path, text).with_context(|| format!("cannot write {}", path.display()))?;
    Ok(path)
}

/// `agp goal --instance NAME --place LIVE_GOAL` on a live session.
fn queue_goal(run: &Run<'_>) -> Result<()> {
    queue_goal_on(&run.session)
}

/// `agp goal --instance NAME --place LIVE_GOAL` on the live session `s` (across a bridge:
/// the robot's side, whose supervisor owns and judges the goals).
fn queue_goal_on(s: &Session<'_>) -> Result<()> {
    let out = s
        .bins
        .agp(&s.dir)
        .args(["goal", "--instance", &s.instance, "--place"])
        .args(LIVE_GOAL)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .output()
        .context("cannot run `agp goal`")?;
    if !out.status.success() {
        bail!(
            "`agp goal` failed: {}",
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    Ok(())
}

/// The goal of a live session as `agp status --json` shows it, once it is done (at most
/// `timeout`); `None` when it is not.
fn await_goal(run: &mut Run<'_>, timeout: Duration) -> Result<Option<Value>> {
    await_done_goal(
        run,
        |r| r.ended().is_some(),
        |r| &r.session,
        timeout,
        Duration::from_millis(500),
    )
}

/// The goal `session_of(run)` shows once it is done, asked every `every` for at most
/// `timeout`; `None` when it is not done by then or `ended(run)` says the run ended.
fn await_done_goal<'s, R>(
    run: &mut R,
    mut ended: impl FnMut(&mut R) -> bool,
    session_of: impl Fn(&R) -> &Session<'s>,
    timeout: Duration,
    every: Duration,
) -> Result<Option<Value>> {
    let deadline = Instant::now() + timeout;
    while Instant::now() < deadline {
        if ended(run) {
            return Ok(None);
        }
        if let Some(g) = goal_of(session_of(run))?.filter(|g| g["state"] == "done") {
            return Ok(Some(g));
        }
        sleep_checked(every)?;
    }
    Ok(None)
}

/// The first goal of the live session `s` as `agp status --json` shows it, if it shows one.
fn goal_of(s: &Session<'_>) -> Result<Option<Value>> {
    let out = s
        .bins
        .agp(&s.dir)
        .args(["status", "--instance", &s.instance, "--json"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .output()
        .context("cannot run `agp status`")?;
    Ok(serde_json::from_slice::<Value>(&out.stdout)
        .ok()
        .map(|v| v["goals"][0].clone())
        .filter(|g| !g.is_null()))
}

/// The live session's verdict: its goal reached, or ended by the planner with its reason
/// (`lost`, with the object not found); not done by the run's end is wrong.
fn check_goal(goal: Option<&Value>, note: &mut String) -> bool {
    let Some(g) = goal else {
        *note = "the goal was not done by the run's end".to_owned();
        return false;
    };
    let end = g["end"].as_str().unwrap_or_default();
    if g["success"] == true {
        *note = format!(
            "goal reached ({:.1} mm, {:.1} deg)",
            g["position_error_mm"].as_f64().unwrap_or(f64::NAN),
            g["orientation_error_deg"].as_f64().unwrap_or(f64::NAN)
        );
        return true;
    }
    *note = format!("goal not reached, ended `{end}`");
    !end.is_empty()
}

/// ": <the supervisor's last error line>" for notes, or nothing.
fn last_error(dir: &Path) -> String {
    last_line_with(dir, "up.err", "error")
        .map(|l| format!(": {l}"))
        .unwrap_or_default()
}

/// The learning run's verdict: an AG file of the triangle with the three alphas, each
/// holding between 1 and `trials` pushes, and the estimator's report counting
/// `3 x trials` trials.
fn check_learned(dir: &Path, trials: u32, note: &mut String) -> bool {
    let path = dir.join("results").join("triangle.ag");
    let g = match AffordanceGradient::load(&path) {
        Ok(g) => g,
        Err(e) => {
            *note = format!("no AG file: {e}");
            return false;
        }
    };
    if g.object_name() != "triangle" {
        *note = format!("the AG file names `{}`", g.object_name());
        return false;
    }
    let alphas: Vec<f64> = g.alphas_deg().collect();
    if alphas.len() != 3 {
        *note = format!("{} alphas in the AG file", alphas.len());
        return false;
    }
    for a in alphas {
        let pushes = g.push_count(a).unwrap_or(0);
        if !(1..=u64::from(trials)).contains(&pushes) {
            *note = format!("alpha {a:+.0} deg: {pushes} pushes of {trials} trials");
            return false;
        }
    }
    let line = last_line_with(dir, "up.log", "agp-estimator: learned");
    let of = line.as_deref().and_then(|l| {
        l.split_once("rejected of ")
            .and_then(|(_, rest)| rest.split(|c: char| !c.is_ascii_digit()).next())
            .and_then(|n| n.parse::<u32>().ok())
    });
    if of != Some(3 * trials) {
        *note = format!(
            "the estimator counted {} trials, not {}",
            of.map_or("no".to_owned(), |n| n.to_string()),
            3 * trials
        );
        return false;
    }
    true
}

/// The placement's verdict: the judge's JSON says placed.
fn check_placed(dir: &Path, instance: &str, note: &mut String) -> bool {
    let path = dir.join("results").join(format!("{instance}-place.json"));
    let verdict: Option<Value> = std::fs::read_to_string(&path)
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok());
    match verdict {
        None => {
            *note = "no verdict from the judge".to_owned();
            false
        }
        Some(v) if v["success"] == true => true,
        Some(v) => {
            *note = format!(
                "NOT placed: {:.1} mm, {:.1} deg",
                v["position_error_mm"].as_f64().unwrap_or(f64::NAN),
                v["orientation_error_deg"].as_f64().unwrap_or(f64::NAN)
            );
            false
        }
    }
}

/// The AG file the placement runs serve: `agp bench learn` on the triangle (the paper's
/// protocol, in-process, no shared memory), once.
fn learn_ag(bins: &Bins, out: &Path) -> Result<PathBuf> {
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let out_str = out
        .to_str()
        .ok_or_else(|| anyhow!("{} is not UTF-8", out.display()))?;
    let mut child = bins
        .agp(out)
        .args([
            "bench",
            "learn",
            "--scenario",
            "triangle",
            "--seed",
            "7",
            "--out",
            out_str,
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .context("cannot start `agp bench learn`")?;
    let exit = loop {
        if let Some(s) = child.try_wait().context("cannot watch `agp bench learn`")? {
            break s;
        }
        if let Err(e) = sleep_checked(Duration::from_millis(50)) {
            let _ = child.kill();
            let _ = child.wait();
            return Err(e);
        }
    };
    let path = out.join("triangle.ag");
    if !exit.success() || !path.is_file() {
        let mut err = String::new();
        if let Some(mut e) = child.stderr.take() {
            use std::io::Read;
            let _ = e.read_to_string(&mut err);
        }
        bail!(
            "`agp bench learn --scenario triangle` failed ({exit}): {}",
            err.lines().last().unwrap_or("no message")
        );
    }
    Ok(path)
}

/// A fault of the bridge phase: what happens to the far end of the link, seen from the
/// robot's side (physics, the estimator and the judge run there; the planner runs beyond
/// the link).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum LinkFault {
    /// `kill -9` of the planner side's bridge (its supervisor restarts it).
    KillFarBridge,
    /// SIGSTOP, a random pause, SIGCONT of the planner side's bridge.
    StopFarBridge,
    /// `kill -9` of the planner side's supervisor (its bridge and planner die with it),
    /// then a fresh `agp up` of it.
    KillFarSupervisor,
    /// SIGSTOP, a random pause, SIGCONT of the planner side's supervisor.
    StopFarSupervisor,
    /// The link cut (the proxy closes every connection and refuses new ones) for a random
    /// pause, then restored.
    Cut,
}

impl LinkFault {
    const ALL: [LinkFault; 5] = [
        LinkFault::KillFarBridge,
        LinkFault::StopFarBridge,
        LinkFault::KillFarSupervisor,
        LinkFault::StopFarSupervisor,
        LinkFault::Cut,
    ];

    fn label(self) -> &'static str {
        match self {
            LinkFault::KillFarBridge => "kill -9 far bridge",
            LinkFault::StopFarBridge => "stop/cont far bridge",
            LinkFault::KillFarSupervisor => "kill -9 far supervisor, up again",
            LinkFault::StopFarSupervisor => "stop/cont far supervisor",
            LinkFault::Cut => "link cut, restored",
        }
    }
}

/// One fault of the bridge phase and what came of it.
#[derive(Debug, Clone)]
struct LinkFaultRecord {
    run: usize,
    kind: LinkFault,
    at_s: f64,
    /// The pause (stop to continue, cut to restore), ms.
    pause_ms: Option<f64>,
    survived: bool,
    /// The fault's end (kill, SIGCONT, restore) to physics stepping again, ms.
    recovery_ms: Option<f64>,
    /// Steps physics applied while the link was cut, from 100 ms after the cut (what was
    /// already on its way) to the restore: nothing may drive the robot meanwhile.
    steps_while_cut: Option<u64>,
    /// Live: the watchdog stop physics logged for this fault (the link down), if one came.
    stop: Option<LoggedStop>,
    /// Live: what physics's account shows went wrong while the link was down (a command
    /// applied, the wheels stopped later than the watchdog, the robot moved beyond one
    /// watchdog period after it).
    violation: Option<String>,
    note: String,
}

impl LinkFaultRecord {
    /// A fault of `kind` in run `run`, `at_s` into it, nothing yet known of its outcome.
    fn new(run: usize, kind: LinkFault, at_s: f64) -> Self {
        Self {
            run,
            kind,
            at_s,
            pause_ms: None,
            survived: false,
            recovery_ms: None,
            steps_while_cut: None,
            stop: None,
            violation: None,
            note: String::new(),
        }
    }
}

/// One run of the bridge phase: a placement split over two instances.
#[derive(Debug, Clone)]
struct LinkRunRecord {
    index: usize,
    robot: String,
    planner: String,
    faults: u32,
    /// `agp up` of the planner side (more than one when its supervisor was killed).
    planner_ups: u32,
    /// Both supervisors exited with status 0.
    completed: bool,
    /// The judge (robot side) says placed.
    placed: bool,
    /// Physics's step log: every step applied exactly once.
    steps_once: bool,
    steps: u64,
    exits: (Option<i32>, Option<i32>),
    files_left: usize,
    wall_s: f64,
    /// Live: how the goal ended (`done`, `lost`, ...), `None` when it was not done by the
    /// run's end.
    goal_end: Option<String>,
    /// Live: physics's watchdog stops over the whole run, and the largest motion (mm, deg)
    /// of the robot beyond one watchdog period after any of them.
    watchdog_stops: usize,
    motion: (f64, f64),
    /// Live: physics's summary line at its end.
    physics_summary: Option<String>,
    note: String,
}

/// A placement split over two instances joined by `agp bridge` through a proxy that can
/// cut the link: the robot side (physics with its step log, the estimator serving the AG
/// file, the bridge listening) and the planner side (the bridge connecting through the
/// proxy, the placing planner).
struct LinkRun<'a> {
    robot: Session<'a>,
    planner: Session<'a>,
    proxy: LinkProxy,
    steps: StepCounter,
    started: Instant,
    planner_ups: u32,
}

/// The far timeout of the robot side's bridge in the bridge phase: far beyond any fault's
/// recovery, so a fault the link rides out never ends the run.
const LINK_FAR_TIMEOUT_S: u32 = 60;

/// The two launch files of a bridge run in `dir` (`robot/`, `planner/`): a placement in
/// lockstep, or (`live`) a live session on the realtime clock, the far planner serving the
/// goals of the robot side's supervisor until `agp down`.
fn link_launches(
    bins: &Bins,
    dir: &Path,
    names: (&str, &str),
    ports: (u16, u16),
    ag: &Path,
    max_restarts: u32,
    live: bool,
) -> Result<(PathBuf, PathBuf)> {
    let exec = |name: &str| format!("\"{}\"", bins.path(name).display());
    let restart = format!(
        "restart = {{ policy = \"on-failure\", max_restarts = {max_restarts}, backoff_ms = 10 }}\nstop_grace_ms = 3000\n"
    );
    let clock = if live { "realtime" } else { "lockstep" };
    let head = |name: &str| {
        format!(
            "instance = \"{name}\"\nscenario = \"triangle\"\nresults = \"results\"\n\n[clock]\nmode = \"{clock}\"\nrate_hz = 640\n\n"
        )
    };
    // A placement ends both runs (the planner's end, across the link); a live session
    // lasts until `agp down`.
    let ends_run = if live { "" } else { "ends_run = true\n" };
    let robot_dir = dir.join("robot");
    let physics_args = if live {
        String::new()
    } else {
        format!(
            "args = [\"--step-log\", \"{}\"]\n",
            step_log_path(&robot_dir).display()
        )
    };
    let robot = head(names.0)
        + &format!(
            "[[process]]\nname = \"physics\"\nexec = {}\n{physics_args}{restart}\n",
            exec("agp-physics"),
        )
        + &format!(
            "[[process]]\nname = \"estimator\"\nexec = {}\nargs = [\"--load\", \"{}\"]\n{restart}\n",
            exec("agp-estimator"),
            ag.display()
        )
        + &format!(
            "[[process]]\nname = \"planner\"\nremote = {{ role = \"planner\", listen = \"tcp/127.0.0.1:{}\", insecure = true }}\nenv = {{ AGP_BRIDGE_FAR_TIMEOUT_S = \"{LINK_FAR_TIMEOUT_S}\" }}\n{ends_run}",
            ports.0
        );
    let mode = if live { "serve" } else { "place" };
    let planner = head(names.1)
        + &format!(
            "[[process]]\nname = \"robot\"\nremote = {{ role = \"robot\", connect = \"tcp/127.0.0.1:{}\", insecure = true }}\n{restart}\n",
            ports.1
        )
        + &format!(
            "[[process]]\nname = \"planner\"\nexec = {}\nargs = [\"--mode\", \"{mode}\", \"--planner\", \"affordance\"]\n{restart}{ends_run}",
            exec("agp-planner")
        );
    let mut paths = Vec::new();
    for (sub, text) in [("robot", robot), ("planner", planner)] {
        let d = dir.join(sub);
        std::fs::create_dir_all(&d).with_context(|| format!("cannot create {}", d.display()))?;
        let p = d.join("launch.toml");
        std::fs::write(&p, text).with_context(|| format!("cannot write {}", p.display()))?;
        paths.push(p);
    }
    Ok((paths[0].clone(), paths[1].clone()))
}

/// Whether physics's step log holds every step exactly once, in order; and how many.
fn steps_once(path: &Path) -> (bool, u64) {
    let Ok(text) = std::fs::read_to_string(path) else {
        return (false, 0);
    };
    let steps: Vec<u64> = text
        .lines()
        .filter_map(|l| l.split_whitespace().next()?.parse().ok())
        .collect();
    let ok = !steps.is_empty() && steps.windows(2).all(|w| w[1] == w[0] + 1);
    (ok, steps.len() as u64)
}

impl LinkRun<'_> {
    /// Both ends' exit codes once both exited.
    fn ended(&mut self) -> Option<(Option<i32>, Option<i32>)> {
        let a = self.robot.ended()?;
        let b = self.planner.ended()?;
        Some((a, b))
    }

    /// The placement ran out: the planner side ended with status 0.
    fn placement_over(&mut self) -> bool {
        self.planner.ended() == Some(Some(0))
    }

    /// A stop/continue fault of the far end, in both bridge phases: SIGSTOP of the far
    /// bridge (`bridge`, [`LinkFault::StopFarBridge`]) or of the far supervisor
    /// ([`LinkFault::StopFarSupervisor`]), `pause`, SIGCONT; the pause goes in `record`.
    fn pause_far(
        &mut self,
        kind: LinkFault,
        bridge: u32,
        pause: Duration,
        record: &mut LinkFaultRecord,
    ) -> Result<()> {
        let target = match kind {
            LinkFault::StopFarBridge => bridge,
            _ => self.planner.sup().pid(),
        };
        pause_process(&mut self.planner, target, pause)?;
        record.pause_ms = Some(pause.as_secs_f64() * 1e3);
        Ok(())
    }

    /// `kill -9` of the far supervisor, whose children `before` shows, then `agp up` of the
    /// planner's side again, in both bridge phases; a child that outlived it goes in
    /// `record`'s note.
    fn kill_far_supervisor(
        &mut self,
        bins: &Bins,
        before: &Status,
        record: &mut LinkFaultRecord,
    ) -> Result<()> {
        let children: Vec<u32> = before.processes.iter().filter_map(|p| p.pid).collect();
        let outlived = kill_supervisor(&mut self.planner, bins, &children);
        if outlived > 0 {
            record.note = format!("{outlived} child(ren) outlived the killed supervisor; ");
        }
        self.planner.up_again()?;
        self.planner_ups += 1;
        Ok(())
    }

    /// Waits until the planner side shows `back` (if given), then until physics steps
    /// again; the time from `since`. `Ok(None)` when the placement ran out meanwhile.
    fn wait_steps(
        &mut self,
        since: Instant,
        timeout: Duration,
        back: Option<&dyn Fn(&Status) -> bool>,
    ) -> Result<std::result::Result<Option<Duration>, String>> {
        let deadline = since + timeout;
        let mut at = back.is_none().then(|| self.steps.count());
        loop {
            sleep_checked(Duration::ZERO)?;
            if self.placement_over() {
                return Ok(Ok(None));
            }
            if let Some(code) = self.robot.ended() {
                return Ok(Err(format!(
                    "the robot side ended with status {code:?}{}",
                    last_error(&self.robot.dir)
                )));
            }
            if Instant::now() >= deadline {
                return Ok(Err(match at {
                    None => format!("the planner side not back within {timeout:?}"),
                    Some(_) => format!("no physics step within {timeout:?}"),
                }));
            }
            match (at, back) {
                (None, Some(back)) => {
                    if let Some(s) = self.planner.status()?
                        && back(&s)
                    {
                        at = Some(self.steps.count());
                    }
                }
                (Some(n), _) => {
                    if self.steps.count() > n {
                        return Ok(Ok(Some(since.elapsed())));
                    }
                }
                (None, None) => unreachable!("`at` is set when there is no `back`"),
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

/// What the bridge phase keeps.
struct LinkCampaign<'a> {
    args: &'a Args,
    bins: &'a Bins,
    work: &'a Path,
    ag_file: &'a Path,
    rng: Rng,
    deck: Vec<LinkFault>,
    next: usize,
    faults: Vec<LinkFaultRecord>,
    runs: Vec<LinkRunRecord>,
    started: Instant,
    /// The live bridge phase: live sessions on the realtime clock, not placements.
    live: bool,
}

impl<'a> LinkCampaign<'a> {
    fn draw(&mut self) -> LinkFault {
        if self.next >= self.deck.len() {
            for i in (1..self.deck.len()).rev() {
                let j = (self.rng.next_u64() % (i as u64 + 1)) as usize;
                self.deck.swap(i, j);
            }
            self.next = 0;
        }
        self.next += 1;
        self.deck[self.next - 1]
    }

    /// Starts run `index`'s two sides (a placement, or a live session when `self.live`):
    /// their instance names, the run's folder and the run.
    fn start_run(&mut self, index: usize) -> Result<((String, String), PathBuf, LinkRun<'a>)> {
        let tag = format!("{}{index:04}", if self.live { 'v' } else { 'l' });
        let names = (
            run_instance(&format!("{tag}r")),
            run_instance(&format!("{tag}p")),
        );
        for n in [&names.0, &names.1] {
            if !instance_files(n)?.is_empty() {
                bail!("instance `{n}` already has files; remove them or run again");
            }
        }
        let dir = self.work.join(format!(
            "{}-{index:04}",
            if self.live { "live-link" } else { "link" }
        ));
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .context("a free port on the loopback")?
            .port();
        let proxy = LinkProxy::start(std::net::SocketAddr::from(([127, 0, 0, 1], port)))
            .context("cannot start the link's proxy")?;
        let max_restarts = self.args.faults_per_run.saturating_mul(4).min(MAX_RESTARTS);
        let (robot_launch, planner_launch) = link_launches(
            self.bins,
            &dir,
            (&names.0, &names.1),
            (port, proxy.port()),
            self.ag_file,
            max_restarts,
            self.live,
        )?;
        let robot = Session::start(self.bins, &names.0, robot_launch)?;
        let planner = Session::start(self.bins, &names.1, planner_launch)?;
        let run = LinkRun {
            steps: StepCounter::new(step_log_path(&dir.join("robot"))),
            robot,
            planner,
            proxy,
            started: Instant::now(),
            planner_ups: 1,
        };
        Ok((names, dir, run))
    }

    /// One placement across the link with at most `budget` faults.
    fn run(&mut self, index: usize, budget: u32) -> Result<()> {
        let (names, dir, mut run) = self.start_run(index)?;
        if self.live {
            return self.run_live(index, budget, names, &dir, run);
        }
        eprintln!(
            "[{}/{}] {:.0} s, bridge run {index}: starting",
            self.faults.len(),
            self.args.bridge_faults,
            self.started.elapsed().as_secs_f64()
        );
        let mut lost = match run.wait_steps(Instant::now(), Duration::from_secs(120), None)? {
            Ok(_) => None,
            Err(why) => Some(format!("never started: {why}")),
        };
        let mut faults = 0;
        while lost.is_none() && faults < budget && !run.placement_over() {
            sleep_checked(Duration::from_secs_f64(self.rng.range(0.1, 1.0)))?;
            if run.placement_over() {
                break;
            }
            let kind = self.draw();
            let Some(record) = self.inject(&mut run, index, kind)? else {
                continue;
            };
            faults += 1;
            if !record.survived {
                lost = Some(format!("{}: {}", kind.label(), record.note));
            }
            self.faults.push(record);
        }
        let timeout = Duration::from_secs_f64(self.args.run_timeout_s);
        let end = Instant::now() + timeout;
        while run.ended().is_none() && Instant::now() < end {
            sleep_checked(Duration::from_millis(20))?;
        }
        let exits = run.ended().unwrap_or((run.robot.ended().flatten(), None));
        if lost.is_none() && run.ended().is_none() {
            lost = Some(format!("not ended {timeout:?} after its last fault"));
        }
        let (once, steps) = steps_once(&step_log_path(&dir.join("robot")));
        let mut note = String::new();
        let placed = check_placed(&dir.join("robot"), &names.0, &mut note);
        let completed = exits == (Some(0), Some(0));
        if lost.is_none() && !completed {
            lost = Some(format!(
                "ended with status {exits:?}{}{}",
                last_error(&dir.join("robot")),
                last_error(&dir.join("planner"))
            ));
        }
        let files_left = run.planner.shut() + run.robot.shut();
        if let Some(why) = lost {
            note = if note.is_empty() {
                why
            } else {
                format!("{why}; {note}")
            };
        }
        self.runs.push(LinkRunRecord {
            index,
            robot: names.0,
            planner: names.1,
            faults,
            planner_ups: run.planner_ups,
            completed,
            placed,
            steps_once: once,
            steps,
            exits,
            files_left,
            wall_s: run.started.elapsed().as_secs_f64(),
            goal_end: None,
            watchdog_stops: 0,
            motion: (0.0, 0.0),
            physics_summary: None,
            note,
        });
        Ok(())
    }

    /// Injects `kind`; `None` when the far bridge is not running just now.
    fn inject(
        &mut self,
        run: &mut LinkRun<'_>,
        index: usize,
        kind: LinkFault,
    ) -> Result<Option<LinkFaultRecord>> {
        let timeout = Duration::from_secs_f64(self.args.recovery_timeout_s);
        let Some(before) = run.planner.status()? else {
            return Ok(None);
        };
        let Some(bridge) = before.child("robot").filter(|c| c.running()).cloned() else {
            return Ok(None);
        };
        let Some(pid) = bridge.pid.filter(|&p| self.bins.owns(p)) else {
            return Ok(None);
        };
        let mut record = LinkFaultRecord::new(index, kind, run.started.elapsed().as_secs_f64());
        let all = |s: &Status| s.all_running(&["robot", "planner"]);
        let pause = Duration::from_secs_f64(self.rng.range(0.2, 2.0));
        let back = match kind {
            LinkFault::KillFarBridge => {
                signal(pid, libc::SIGKILL);
                let t0 = Instant::now();
                let restarted = move |s: &Status| {
                    s.child("robot")
                        .is_some_and(|c| c.running() && c.pid != Some(pid))
                };
                run.wait_steps(t0, timeout, Some(&restarted as &dyn Fn(&Status) -> bool))?
            }
            LinkFault::StopFarBridge | LinkFault::StopFarSupervisor => {
                run.pause_far(kind, pid, pause, &mut record)?;
                run.wait_steps(
                    Instant::now(),
                    timeout,
                    Some(&all as &dyn Fn(&Status) -> bool),
                )?
            }
            LinkFault::KillFarSupervisor => {
                let t0 = Instant::now();
                run.kill_far_supervisor(self.bins, &before, &mut record)?;
                run.wait_steps(t0, timeout, Some(&all as &dyn Fn(&Status) -> bool))?
            }
            LinkFault::Cut => {
                run.proxy.cut();
                let settle = Duration::from_millis(100);
                sleep_checked(settle)?;
                let from = run.steps.count();
                let slept = sleep_checked(pause.saturating_sub(settle));
                let to = run.steps.count();
                run.proxy.restore();
                slept?;
                record.steps_while_cut = Some(to - from);
                record.pause_ms = Some(pause.as_secs_f64() * 1e3);
                if to > from {
                    record.note = format!("{} step(s) applied while the link was cut; ", to - from);
                }
                run.wait_steps(Instant::now(), timeout, None)?
            }
        };
        let clean = record.note.is_empty();
        match back {
            Ok(Some(d)) => {
                record.survived = clean;
                record.recovery_ms = Some(d.as_secs_f64() * 1e3);
            }
            Ok(None) => {
                record.survived = clean;
                record.note += "the placement ran out meanwhile, status 0";
            }
            Err(why) => record.note += &why,
        }
        Ok(Some(record))
    }

    fn json(&self) -> Value {
        let runs: Vec<Value> = self
            .runs
            .iter()
            .map(|r| {
                json!({
                    "run": r.index, "robot": r.robot, "planner": r.planner, "faults": r.faults,
                    "planner_ups": r.planner_ups, "completed": r.completed, "placed": r.placed,
                    "steps_once": r.steps_once, "steps": r.steps,
                    "exit_robot": r.exits.0, "exit_planner": r.exits.1,
                    "files_left": r.files_left, "wall_s": r.wall_s, "note": r.note,
                    "goal_end": r.goal_end, "watchdog_stops": r.watchdog_stops,
                    "motion_mm": r.motion.0, "turn_deg": r.motion.1,
                    "physics_summary": r.physics_summary,
                })
            })
            .collect();
        let faults: Vec<Value> = self
            .faults
            .iter()
            .map(|f| {
                json!({
                    "run": f.run, "fault": f.kind.label(), "at_s": f.at_s, "pause_ms": f.pause_ms,
                    "survived": f.survived, "recovery_ms": f.recovery_ms,
                    "steps_while_cut": f.steps_while_cut, "note": f.note,
                    "violation": f.violation,
                    "stop": f.stop.map(|s| json!({
                        "last_command_ns": s.last_command_ns, "fired_ns": s.fired_ns,
                        "resumed_ns": s.resumed_ns, "stopped_after_ms": s.stopped_after_ms(),
                        "wheels_mm_s": [s.wheels_mm_s.0, s.wheels_mm_s.1],
                        "accounted": s.accounted, "motion_mm": s.motion_mm, "turn_deg": s.turn_deg,
                    })),
                })
            })
            .collect();
        json!({
            "live": self.live,
            "faults_injected": self.faults.len(),
            "faults_survived": self.faults.iter().filter(|f| f.survived).count(),
            "violations": self.faults.iter().filter(|f| f.violation.is_some()).count(),
            "watchdog_stops": self.faults.iter().filter(|f| f.stop.is_some()).count(),
            "max_motion_mm": self.runs.iter().map(|r| r.motion.0).fold(0.0, f64::max),
            "max_turn_deg": self.runs.iter().map(|r| r.motion.1).fold(0.0, f64::max),
            "goals_reached": self.runs.iter().filter(|r| self.live && r.placed).count(),
            "goals_not_done": self.runs.iter().filter(|r| self.live && r.goal_end.is_none()).count(),
            "runs": self.runs.len(),
            "runs_completed": self.runs.iter().filter(|r| r.completed).count(),
            "runs_placed": self.runs.iter().filter(|r| r.placed).count(),
            "runs_every_step_once": self.runs.iter().filter(|r| r.steps_once).count(),
            "files_left": self.runs.iter().map(|r| r.files_left).sum::<usize>(),
            "steps_while_cut": self.faults.iter().filter_map(|f| f.steps_while_cut).sum::<u64>(),
            "wall_s": self.started.elapsed().as_secs_f64(),
            "fault_list": faults,
            "run_list": runs,
        })
    }

    fn missed(&self) -> Option<String> {
        let not_survived = self.faults.iter().filter(|f| !f.survived).count();
        let lost = self.runs.iter().filter(|r| !r.completed).count();
        let files: usize = self.runs.iter().map(|r| r.files_left).sum();
        if self.live {
            // A goal ended `lost` by the planner, with its reason, is an outcome; one not
            // done by the run's end is not.
            let not_done = self.runs.iter().filter(|r| r.goal_end.is_none()).count();
            let violations = self.faults.iter().filter(|f| f.violation.is_some()).count();
            let moved = self
                .runs
                .iter()
                .filter(|r| r.motion.0 > STILL_MM || r.motion.1 > STILL_DEG)
                .count();
            return (not_survived + lost + not_done + violations + moved + files > 0).then(|| {
                format!(
                    "live bridge phase: {not_survived} fault(s) not survived, {lost} session(s) lost, {not_done} goal(s) not done, {violations} fault(s) with a command, a late stop or motion while the link was down, {moved} session(s) with the robot moving after a watchdog stop, {files} file(s) left"
                )
            });
        }
        let wrong = self
            .runs
            .iter()
            .filter(|r| !r.placed || !r.steps_once)
            .count();
        (not_survived + lost + wrong + files > 0).then(|| {
            format!(
                "bridge phase: {not_survived} fault(s) not survived, {lost} run(s) lost, {wrong} not placed or a step lost or applied twice, {files} file(s) left"
            )
        })
    }

    fn print(&self) {
        println!(
            "bridge phase: {} faults across the link in {} runs, seed {}, {:.0} s wall (a placement split over two instances in lockstep, the planner's side beyond a TCP proxy that cuts the link)",
            self.faults.len(),
            self.runs.len(),
            self.args.seed,
            self.started.elapsed().as_secs_f64()
        );
        println!(
            "{:<34} {:>8} {:>8} {:>14} {:>14} {:>10}",
            "fault", "injected", "survived", "recovery p50", "recovery max", "cut steps"
        );
        for kind in LinkFault::ALL {
            let of: Vec<&LinkFaultRecord> = self.faults.iter().filter(|f| f.kind == kind).collect();
            let rec: Vec<f64> = of.iter().filter_map(|f| f.recovery_ms).collect();
            let cut: Option<u64> =
                (kind == LinkFault::Cut).then(|| of.iter().filter_map(|f| f.steps_while_cut).sum());
            println!(
                "{:<34} {:>8} {:>8} {:>11} ms {:>11} ms {:>10}",
                kind.label(),
                of.len(),
                of.iter().filter(|f| f.survived).count(),
                ms(median(&rec)),
                ms(max(&rec)),
                cut.map_or("-".to_owned(), |c| c.to_string())
            );
        }
        let all: Vec<f64> = self.faults.iter().filter_map(|f| f.recovery_ms).collect();
        println!(
            "{:<34} {:>8} {:>8} {:>11} ms {:>11} ms",
            "all",
            self.faults.len(),
            self.faults.iter().filter(|f| f.survived).count(),
            ms(median(&all)),
            ms(max(&all))
        );
        let j = self.json();
        println!(
            "runs {}: completed {}, placed {}, every step applied once {}, lost {}, files left {}",
            j["runs"],
            j["runs_completed"],
            j["runs_placed"],
            j["runs_every_step_once"],
            self.runs.len() - self.runs.iter().filter(|r| r.completed).count(),
            j["files_left"]
        );
        for f in self.faults.iter().filter(|f| !f.survived) {
            println!(
                "  NOT SURVIVED: run {} at {:.1} s: {}: {}",
                f.run,
                f.at_s,
                f.kind.label(),
                f.note
            );
        }
        for r in self
            .runs
            .iter()
            .filter(|r| !r.completed || !r.placed || !r.steps_once || r.files_left > 0)
        {
            println!(
                "  RUN {} (`{}`/`{}`, {} fault(s), {} up(s) of the planner side, exits {:?}, {} steps, {} file(s) left): {}",
                r.index,
                r.robot,
                r.planner,
                r.faults,
                r.planner_ups,
                r.exits,
                r.steps,
                r.files_left,
                r.note
            );
        }
    }
}

/// Physics's watchdog (`agp-physics --watchdog-ms`, 250 by default, which the live bridge
/// phase's launch files keep).
const WATCHDOG: Duration = Duration::from_millis(250);

/// Commands already on their way when the link went down (in a socket, in Zenoh's queues,
/// from a far planner a moment before its parent's death killed it): physics may still
/// apply them this long after.
const IN_FLIGHT: Duration = Duration::from_millis(100);

/// How late a tick of physics's realtime clock may come on a loaded machine before a stop
/// later than the watchdog counts as missed.
const LATE_TICK: Duration = Duration::from_millis(100);

/// Motion of the robot beyond one watchdog period after a stop that counts as moved (a
/// stopped E-puck does not move at all: any motion is something driving it).
const STILL_MM: f64 = 0.1;
const STILL_DEG: f64 = 0.1;

/// Pauses (stop to continue, cut to restore) of the live bridge phase, s: longer than the
/// watchdog, so each must stop the robot.
const LIVE_PAUSE_S: (f64, f64) = (0.5, 2.0);

/// How a live session's link came back after a fault that took it down, by physics's log.
enum LinkBack {
    /// The watchdog stopped the wheels; this stop.
    Stop(LoggedStop),
    /// No stop: commands came again within the watchdog.
    WithinWatchdog,
    /// Not within the recovery timeout (or the robot's side ended): why.
    Never(String),
}

/// What physics's own account of `stop` says went wrong while the link was down (from
/// `down_ns` to `up_ns`, when the tool brought it back): a command applied after the link
/// went down, commands again before it was back, the wheels stopped later than the
/// watchdog, the robot moved beyond one watchdog period after the stop.
///
/// A command applied more than [`IN_FLIGHT`] after the link went down is wrong unless it
/// answered a frame physics published before that (it was on its way; physics applies such
/// a command only if its frame is at most one watchdog period old, and refuses it else).
/// The wheels' stop is judged in ticks of physics's realtime clock (one watchdog period of
/// ticks at most on the last command): a physics descheduled on a loaded machine delays its
/// ticks, and the world with them. A physics that does not say its ticks is judged on the
/// machine's clock, with [`LATE_TICK`] of slack.
fn judge_stop(stop: &LoggedStop, down_ns: u64, up_ns: Option<u64>) -> Option<String> {
    let ns = |d: Duration| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX);
    let ms = |a: u64, b: u64| b.saturating_sub(a) as f64 * 1e-6;
    let mut wrong = Vec::new();
    if stop.last_command_ns > down_ns + ns(IN_FLIGHT)
        && (stop.last_frame_ns == 0 || stop.last_frame_ns > down_ns)
    {
        wrong.push(format!(
            "a command applied {:.0} ms after the link went down{}",
            ms(down_ns, stop.last_command_ns),
            if stop.last_frame_ns == 0 {
                String::new()
            } else {
                format!(
                    ", answering a frame published {:.0} ms after it",
                    ms(down_ns, stop.last_frame_ns)
                )
            }
        ));
    }
    if let (Some(up), Some(resumed)) = (up_ns, stop.resumed_ns)
        && resumed < up
    {
        wrong.push(format!(
            "commands again {:.0} ms before the link was back",
            ms(resumed, up)
        ));
    }
    match (stop.stopped_late(), stop.ticks) {
        (Some(true), Some((ticks, period))) => wrong.push(format!(
            "the wheels turned {ticks} ticks of physics's clock on the last command (watchdog {period})"
        )),
        (None, _) if stop.stopped_after_ms() > (WATCHDOG + LATE_TICK).as_secs_f64() * 1e3 => {
            wrong.push(format!(
                "the wheels stopped {:.0} ms after the last command (watchdog {} ms)",
                stop.stopped_after_ms(),
                WATCHDOG.as_millis()
            ))
        }
        _ => {}
    }
    if stop.accounted && (stop.motion_mm > STILL_MM || stop.turn_deg > STILL_DEG) {
        wrong.push(format!(
            "the robot moved {:.3} mm, {:.3} deg beyond one watchdog period after the stop",
            stop.motion_mm, stop.turn_deg
        ));
    }
    (!wrong.is_empty()).then(|| wrong.join(", "))
}

impl LinkRun<'_> {
    /// Why a side of the run ended, if one did.
    fn side_ended(&mut self) -> Option<String> {
        for (side, s) in [("robot", &mut self.robot), ("planner", &mut self.planner)] {
            if let Some(code) = s.ended() {
                return Some(format!(
                    "the {side} side ended with status {code:?}{}",
                    last_error(&s.dir)
                ));
            }
        }
        None
    }

    /// Live: waits until both sides run every child and physics publishes, queues the goal
    /// on the robot's side, and waits until the far planner took it (the link is up).
    fn start_live(&mut self, timeout: Duration) -> Result<std::result::Result<(), String>> {
        let deadline = Instant::now() + timeout;
        loop {
            sleep_checked(Duration::from_millis(50))?;
            if let Some(why) = self.side_ended() {
                return Ok(Err(why));
            }
            if Instant::now() >= deadline {
                return Ok(Err(format!("not every child running within {timeout:?}")));
            }
            let robot = self.robot.status()?.is_some_and(|s| {
                s.all_running(&["physics", "estimator", "planner"])
                    && s.child("physics")
                        .and_then(|p| p.rate_per_s)
                        .is_some_and(|r| r > 0.0)
            });
            if robot
                && self
                    .planner
                    .status()?
                    .is_some_and(|s| s.all_running(&["robot", "planner"]))
            {
                break;
            }
        }
        if let Err(e) = queue_goal_on(&self.robot) {
            return Ok(Err(format!("{e:#}")));
        }
        loop {
            sleep_checked(Duration::from_millis(100))?;
            if let Some(why) = self.side_ended() {
                return Ok(Err(why));
            }
            if Instant::now() >= deadline {
                return Ok(Err(format!(
                    "the far planner did not take the goal within {timeout:?}"
                )));
            }
            if goal_of(&self.robot)?.is_some_and(|g| g["state"] != "queued") {
                return Ok(Ok(()));
            }
        }
    }

    /// Waits until the planner's side shows `back`: the time from `since`, or why not.
    fn wait_far_back(
        &mut self,
        since: Instant,
        timeout: Duration,
        back: &dyn Fn(&Status) -> bool,
    ) -> Result<std::result::Result<Duration, String>> {
        let deadline = since + timeout;
        loop {
            if let Some(code) = self.robot.ended() {
                return Ok(Err(format!(
                    "the robot side ended with status {code:?}{}",
                    last_error(&self.robot.dir)
                )));
            }
            if Instant::now() >= deadline {
                return Ok(Err(format!("the planner side not back within {timeout:?}")));
            }
            if let Some(s) = self.planner.status()?
                && back(&s)
            {
                return Ok(Ok(since.elapsed()));
            }
            sleep_checked(Duration::from_millis(10))?;
        }
    }

    /// Live: waits until physics's log (`log`) shows how the link came back after it went
    /// down at `down_ns` (back at `up_ns`, when the tool restored it): the watchdog stop
    /// that spans it, once a command ended it; or none, when no stop is under way three
    /// watchdog periods after the far end was back.
    fn wait_link_back(
        &mut self,
        log: &Path,
        down_ns: u64,
        up_ns: Option<u64>,
        timeout: Duration,
    ) -> Result<LinkBack> {
        let since = Instant::now();
        let from_ns = down_ns + u64::try_from(IN_FLIGHT.as_nanos()).unwrap_or(0);
        loop {
            let w = WatchdogLog::read(log);
            if let Some(stop) = stop_of_fault(&w.stops, from_ns, up_ns.unwrap_or(u64::MAX)) {
                return Ok(LinkBack::Stop(stop));
            }
            if !w.stop_under_way() && since.elapsed() >= WATCHDOG * 3 {
                return Ok(LinkBack::WithinWatchdog);
            }
            if let Some(code) = self.robot.ended() {
                return Ok(LinkBack::Never(format!(
                    "the robot side ended with status {code:?}{}",
                    last_error(&self.robot.dir)
                )));
            }
            if since.elapsed() >= timeout {
                return Ok(LinkBack::Never(format!(
                    "no command reached physics within {timeout:?} of the far end's return"
                )));
            }
            sleep_checked(Duration::from_millis(20))?;
        }
    }
}

impl<'a> LinkCampaign<'a> {
    /// One live session across the link on the realtime clock with at most `budget`
    /// faults: the goal queued on the robot's side, the faults while the far planner
    /// pursues it, then (once it is done) `agp down` of the planner's side and the robot's.
    fn run_live(
        &mut self,
        index: usize,
        budget: u32,
        names: (String, String),
        dir: &Path,
        mut run: LinkRun<'a>,
    ) -> Result<()> {
        eprintln!(
            "[{}/{}] {:.0} s, live bridge run {index}: starting",
            self.faults.len(),
            self.args.bridge_live_faults,
            self.started.elapsed().as_secs_f64()
        );
        let log = dir.join("robot").join("up.log");
        let mut lost = run
            .start_live(Duration::from_secs(120))?
            .err()
            .map(|why| format!("never started: {why}"));
        let (mut faults, mut skips) = (0, 0);
        while lost.is_none() && faults < budget {
            sleep_checked(Duration::from_secs_f64(self.rng.range(0.3, 1.5)))?;
            if goal_of(&run.robot)?.is_some_and(|g| g["state"] == "done") {
                break;
            }
            let kind = self.draw();
            let Some(record) = self.inject_live(&mut run, index, kind, &log)? else {
                skips += 1;
                if skips >= MAX_SKIPS {
                    lost = Some(format!(
                        "{skips} faults in a row found no far bridge running"
                    ));
                }
                continue;
            };
            (faults, skips) = (faults + 1, 0);
            if !record.survived {
                lost = Some(format!("{}: {}", kind.label(), record.note));
            }
            self.faults.push(record);
        }
        let timeout = Duration::from_secs_f64(self.args.run_timeout_s);
        let goal = match lost {
            None => await_goal_on(&mut run, timeout)?,
            Some(_) => None,
        };
        // Brought down as a user would: the planner's side, then the robot's.
        let downs = (run.planner.down()?, run.robot.down()?);
        let end = Instant::now() + timeout;
        while run.ended().is_none() && Instant::now() < end {
            sleep_checked(Duration::from_millis(20))?;
        }
        let exits = (run.robot.ended().flatten(), run.planner.ended().flatten());
        let completed = exits == (Some(0), Some(0));
        if lost.is_none() && !completed {
            lost = Some(format!(
                "ended with status {exits:?} (`agp down` ok: {downs:?}){}{}",
                last_error(&dir.join("robot")),
                last_error(&dir.join("planner"))
            ));
        }
        let mut note = String::new();
        check_goal(goal.as_ref(), &mut note);
        let files_left = run.planner.shut() + run.robot.shut();
        // Physics's whole account of the session, now that it ended.
        let w = WatchdogLog::read(&log);
        let motion = w
            .stops
            .iter()
            .filter(|s| s.accounted)
            .fold((0.0_f64, 0.0_f64), |m, s| {
                (m.0.max(s.motion_mm), m.1.max(s.turn_deg))
            });
        if let Some(why) = lost {
            note = format!("{why}; {note}");
        }
        self.runs.push(LinkRunRecord {
            index,
            robot: names.0,
            planner: names.1,
            faults,
            planner_ups: run.planner_ups,
            completed,
            placed: goal.as_ref().is_some_and(|g| g["success"] == true),
            steps_once: true,
            steps: 0,
            exits,
            files_left,
            wall_s: run.started.elapsed().as_secs_f64(),
            goal_end: goal
                .as_ref()
                .and_then(|g| g["end"].as_str())
                .filter(|e| !e.is_empty())
                .map(str::to_owned),
            watchdog_stops: w.stops.len(),
            motion,
            physics_summary: last_line_with(&dir.join("robot"), "up.log", "agp-physics: realtime:"),
            note,
        });
        Ok(())
    }

    /// Live: injects `kind` into a live session across the link, waits for the far end and
    /// the link back, and matches the fault with physics's watchdog stop; `None` when the
    /// far bridge is not running just now.
    fn inject_live(
        &mut self,
        run: &mut LinkRun<'_>,
        index: usize,
        kind: LinkFault,
        log: &Path,
    ) -> Result<Option<LinkFaultRecord>> {
        let timeout = Duration::from_secs_f64(self.args.recovery_timeout_s);
        let Some(before) = run.planner.status()? else {
            return Ok(None);
        };
        let Some(pid) = before
            .child("robot")
            .filter(|c| c.running())
            .and_then(|c| c.pid)
            .filter(|&p| self.bins.owns(p))
        else {
            return Ok(None);
        };
        let mut record = LinkFaultRecord::new(index, kind, run.started.elapsed().as_secs_f64());
        let all = |s: &Status| s.all_running(&["robot", "planner"]);
        let pause = Duration::from_secs_f64(self.rng.range(LIVE_PAUSE_S.0, LIVE_PAUSE_S.1));
        let t0 = Instant::now();
        let down_ns = monotonic_ns();
        // When the tool brought the link back (a continue, a restore); a killed far end
        // comes back by itself.
        let mut up_ns = None;
        let back = match kind {
            LinkFault::KillFarBridge => {
                signal(pid, libc::SIGKILL);
                let restarted = move |s: &Status| {
                    all(s)
                        && s.child("robot")
                            .is_some_and(|c| c.running() && c.pid != Some(pid))
                };
                run.wait_far_back(t0, timeout, &restarted)?
            }
            LinkFault::StopFarBridge | LinkFault::StopFarSupervisor => {
                run.pause_far(kind, pid, pause, &mut record)?;
                up_ns = Some(monotonic_ns());
                run.wait_far_back(Instant::now(), timeout, &all)?
            }
            LinkFault::KillFarSupervisor => {
                run.kill_far_supervisor(self.bins, &before, &mut record)?;
                run.wait_far_back(t0, timeout, &all)?
            }
            LinkFault::Cut => {
                run.proxy.cut();
                let slept = sleep_checked(pause);
                run.proxy.restore();
                up_ns = Some(monotonic_ns());
                slept?;
                record.pause_ms = Some(pause.as_secs_f64() * 1e3);
                Ok(Duration::ZERO)
            }
        };
        let far_back = match back {
            Ok(d) => d,
            Err(why) => {
                record.note += &why;
                return Ok(Some(record));
            }
        };
        if kind == LinkFault::StopFarSupervisor {
            // The link stays up: the far bridge and planner run on under a stopped parent.
            record.survived = true;
            record.recovery_ms = Some(far_back.as_secs_f64() * 1e3);
            return Ok(Some(record));
        }
        match run.wait_link_back(log, down_ns, up_ns, timeout)? {
            LinkBack::Stop(stop) => {
                record.stop = Some(stop);
                let from = up_ns.unwrap_or(down_ns);
                match stop.resumed_ns {
                    Some(r) => record.recovery_ms = Some(r.saturating_sub(from) as f64 * 1e-6),
                    None => record.note += "physics ended during the stop; ",
                }
                record.violation = judge_stop(&stop, down_ns, up_ns);
            }
            LinkBack::WithinWatchdog => {
                record.recovery_ms = Some(far_back.as_secs_f64() * 1e3);
                record.note += "the far end was back within the watchdog: no stop; ";
                if let Some(up) = up_ns {
                    record.violation = Some(format!(
                        "no watchdog stop while the link was down for {:.0} ms: commands went on",
                        up.saturating_sub(down_ns) as f64 * 1e-6
                    ));
                }
            }
            LinkBack::Never(why) => record.note += &why,
        }
        record.survived = record.recovery_ms.is_some() && !record.note.contains("outlived");
        Ok(Some(record))
    }

    /// The live bridge phase's figures.
    fn print_live(&self) {
        println!(
            "live bridge phase: {} faults across the link in {} live sessions, seed {}, {:.0} s wall (the realtime clock at 640 Hz; physics, the estimator and the goal's judge on the robot's side; the far planner, `--mode serve`, pursuing `agp goal --place {}` beyond a TCP proxy that cuts the link; physics's watchdog {} ms)",
            self.faults.len(),
            self.runs.len(),
            self.args.seed,
            self.started.elapsed().as_secs_f64(),
            LIVE_GOAL.join(" "),
            WATCHDOG.as_millis()
        );
        println!(
            "{:<34} {:>8} {:>8} {:>13} {:>13} {:>14} {:>11} {:>20}",
            "fault",
            "injected",
            "survived",
            "recovery p50",
            "recovery max",
            "stops (moving)",
            "stop after",
            "motion while down"
        );
        let row = |label: &str, of: &[&LinkFaultRecord]| {
            let rec: Vec<f64> = of.iter().filter_map(|f| f.recovery_ms).collect();
            let stops: Vec<&LoggedStop> = of.iter().filter_map(|f| f.stop.as_ref()).collect();
            let after: Vec<f64> = stops.iter().map(|s| s.stopped_after_ms()).collect();
            let moved = stops
                .iter()
                .filter(|s| s.accounted)
                .fold((0.0_f64, 0.0_f64), |m, s| {
                    (m.0.max(s.motion_mm), m.1.max(s.turn_deg))
                });
            println!(
                "{:<34} {:>8} {:>8} {:>10} ms {:>10} ms {:>14} {:>8} ms {:>20}",
                label,
                of.len(),
                of.iter().filter(|f| f.survived).count(),
                ms(median(&rec)),
                ms(max(&rec)),
                format!(
                    "{} ({})",
                    stops.len(),
                    stops.iter().filter(|s| s.was_moving()).count()
                ),
                ms(max(&after)),
                if stops.is_empty() {
                    "-".to_owned()
                } else {
                    format!("{:.3} mm {:.3} deg", moved.0, moved.1)
                }
            );
        };
        for kind in LinkFault::ALL {
            let of: Vec<&LinkFaultRecord> = self.faults.iter().filter(|f| f.kind == kind).collect();
            row(kind.label(), &of);
        }
        let all: Vec<&LinkFaultRecord> = self.faults.iter().collect();
        row("all", &all);
        let count = |f: &dyn Fn(&LinkRunRecord) -> bool| self.runs.iter().filter(|r| f(r)).count();
        let ends: BTreeMap<&str, usize> = self
            .runs
            .iter()
            .filter_map(|r| r.goal_end.as_deref())
            .fold(BTreeMap::new(), |mut m, e| {
                *m.entry(e).or_default() += 1;
                m
            });
        println!(
            "sessions {}: completed {}, goals reached {}, goals ended {:?}, not done {}, lost {}, files left {}",
            self.runs.len(),
            count(&|r| r.completed),
            count(&|r| r.placed),
            ends,
            count(&|r| r.goal_end.is_none()),
            count(&|r| !r.completed),
            self.runs.iter().map(|r| r.files_left).sum::<usize>()
        );
        let motion = self.runs.iter().fold((0.0_f64, 0.0_f64), |m, r| {
            (m.0.max(r.motion.0), m.1.max(r.motion.1))
        });
        println!(
            "physics's own account over every session: {} watchdog stops, robot motion beyond one watchdog period after a stop at most {:.3} mm, {:.3} deg; faults with a command applied while the link was down, or a stop later than the watchdog, or motion: {}",
            self.runs.iter().map(|r| r.watchdog_stops).sum::<usize>(),
            motion.0,
            motion.1,
            self.faults.iter().filter(|f| f.violation.is_some()).count()
        );
        for f in self
            .faults
            .iter()
            .filter(|f| !f.survived || f.violation.is_some())
        {
            // The violation and the run's notes, each a clause of its own.
            let what: Vec<&str> = f
                .violation
                .as_deref()
                .into_iter()
                .chain(f.note.split("; ").map(str::trim))
                .filter(|s| !s.is_empty())
                .collect();
            println!(
                "  {}: run {} at {:.1} s: {}: {}",
                if f.survived {
                    "VIOLATION"
                } else {
                    "NOT SURVIVED"
                },
                f.run,
                f.at_s,
                f.kind.label(),
                what.join("; ")
            );
        }
        for r in self
            .runs
            .iter()
            .filter(|r| !r.completed || r.goal_end.is_none() || r.files_left > 0)
        {
            println!(
                "  RUN {} (`{}`/`{}`, {} fault(s), {} up(s) of the planner side, exits {:?}, {} file(s) left): {}",
                r.index, r.robot, r.planner, r.faults, r.planner_ups, r.exits, r.files_left, r.note
            );
        }
    }
}

/// The goal of a live session across the link, once the robot's side says it is done (at
/// most `timeout`); `None` when it is not, or a side ended.
fn await_goal_on(run: &mut LinkRun<'_>, timeout: Duration) -> Result<Option<Value>> {
    await_done_goal(
        run,
        |r| r.side_ended().is_some(),
        |r| &r.robot,
        timeout,
        Duration::from_millis(250),
    )
}

/// The bridge phase: `args.bridge_faults` faults across the link, into placements split
/// over two instances; or (`live`) the live bridge phase, `args.bridge_live_faults` into
/// live sessions on the realtime clock.
fn bridge_phase<'a>(
    args: &'a Args,
    bins: &'a Bins,
    work: &'a Path,
    ag_file: &'a Path,
    live: bool,
) -> Result<LinkCampaign<'a>> {
    let mut c = LinkCampaign {
        args,
        bins,
        work,
        ag_file,
        rng: Rng::stream(args.seed, if live { 32 } else { 31 }),
        deck: LinkFault::ALL.to_vec(),
        next: usize::MAX,
        faults: Vec::new(),
        runs: Vec::new(),
        started: Instant::now(),
        live,
    };
    let wanted = if live {
        args.bridge_live_faults
    } else {
        args.bridge_faults
    };
    let mut index = 0;
    while (c.faults.len() as u32) < wanted {
        let left = wanted - c.faults.len() as u32;
        c.run(index, left.min(args.faults_per_run))?;
        index += 1;
        if c.live && c.runs.last().is_some_and(|r| r.faults == 0 && !r.completed) {
            // A session that never took a fault and was lost: another would be too.
            break;
        }
    }
    if live {
        c.print_live();
    } else {
        c.print();
    }
    Ok(c)
}

/// The bridge phases `args` asks for (placements, then live sessions), each printed as it
/// ends: their JSON and what they missed.
fn bridge_phases(
    args: &Args,
    bins: &Bins,
    work: &Path,
    ag_file: &Path,
) -> Result<(Value, Vec<String>)> {
    let mut doc = json!({});
    let mut missed = Vec::new();
    for (live, wanted, key) in [
        (false, args.bridge_faults, "bridge"),
        (true, args.bridge_live_faults, "bridge_live"),
    ] {
        if wanted == 0 {
            continue;
        }
        let c = bridge_phase(args, bins, work, ag_file, live)?;
        doc[key] = c.json();
        missed.extend(c.missed());
    }
    Ok((doc, missed))
}

fn main() {
    let args = Args::parse();
    install_shutdown_handler();
    match campaign(args) {
        Ok(None) => {}
        Ok(Some(missed)) => {
            eprintln!("bench-faults: targets missed: {missed}");
            std::process::exit(2);
        }
        Err(e) if is_interrupt(&e) => {
            eprintln!("bench-faults: interrupted; every process stopped, no file left");
            std::process::exit(130);
        }
        Err(e) => {
            eprintln!("bench-faults: error: {e:#}");
            std::process::exit(1);
        }
    }
}

/// Runs the campaign and prints its figures; `Some(what)` when a target was missed (a
/// fault not survived, a run lost or wrong, a file left).
fn campaign(args: Args) -> Result<Option<String>> {
    let bins = Bins::new(args.bin_dir.clone())?;
    let work = tempfile::Builder::new()
        .prefix("bench-faults-")
        .tempdir()
        .context("cannot create a temporary folder")?;
    let started = Instant::now();
    eprint!("learning the triangle's AG file for the placements (agp bench learn)...");
    let ag_file = learn_ag(&bins, &work.path().join("ag"))?;
    eprintln!(" {:.1} s", started.elapsed().as_secs_f64());
    if args.bench_signals_only {
        let report = bench_signal_phase(&args, &bins, work.path(), &ag_file)?;
        if let Some(path) = &args.json {
            let text = serde_json::to_string_pretty(&json!({ "bench_signals": report.json() }))
                .context("cannot format the JSON")?;
            std::fs::write(path, text + "\n")
                .with_context(|| format!("cannot write {}", path.display()))?;
        }
        return Ok(report.missed());
    }
    if args.bridge_only {
        let (doc, missed) = bridge_phases(&args, &bins, work.path(), &ag_file)?;
        if let Some(path) = &args.json {
            let text = serde_json::to_string_pretty(&doc).context("cannot format the JSON")?;
            std::fs::write(path, text + "\n")
                .with_context(|| format!("cannot write {}", path.display()))?;
        }
        return Ok((!missed.is_empty()).then(|| missed.join("; ")));
    }
    let mut c = Campaign {
        rng: Rng::new(args.seed),
        decks: Phase::ALL.into_iter().map(|p| (p, Deck::new(p))).collect(),
        args,
        bins,
        work,
        ag_file,
        faults: Vec::new(),
        runs: Vec::new(),
        started: Instant::now(),
    };
    let mut index = 0;
    let result = loop {
        let left = c.args.faults.saturating_sub(c.injected());
        if left == 0 {
            break Ok(());
        }
        let phases = &c.args.phases.0;
        let phase = phases[index % phases.len()];
        if let Err(e) = c.run(index, phase, left.min(c.args.faults_per_run)) {
            break Err(e);
        }
        index += 1;
    };
    if std::io::stderr().is_terminal() {
        eprintln!();
    }
    let interrupted = result.as_ref().is_err_and(is_interrupt);
    let (link_json, link_missed) = if result.is_ok() {
        let (doc, missed) = bridge_phases(&c.args, &c.bins, c.work.path(), &c.ag_file)?;
        (Some(doc), (!missed.is_empty()).then(|| missed.join("; ")))
    } else {
        (None, None)
    };
    let signals = if result.is_ok() && c.args.bench_signals > 0 {
        Some(bench_signal_phase(
            &c.args,
            &c.bins,
            c.work.path(),
            &c.ag_file,
        )?)
    } else {
        None
    };
    if result.is_ok() || interrupted {
        let report = Report::new(&c);
        report.print(&c, interrupted);
        if let Some(path) = &c.args.json {
            let mut doc = report.json(&c);
            if let Some(s) = &signals {
                doc["bench_signals"] = s.json();
            }
            if let Some(l) = link_json.as_ref().and_then(Value::as_object) {
                for (key, phase) in l {
                    doc[key.as_str()] = phase.clone();
                }
            }
            let text = serde_json::to_string_pretty(&doc).context("cannot format the JSON")?;
            std::fs::write(path, text + "\n")
                .with_context(|| format!("cannot write {}", path.display()))?;
        }
    }
    result?;
    let not_survived = c.faults.iter().filter(|f| !f.survived).count();
    let lost = c.runs.iter().filter(|r| !r.completed).count();
    let wrong = c.runs.iter().filter(|r| r.correct == Some(false)).count();
    let files: usize = c.runs.iter().map(|r| r.files_left).sum();
    let missed = [
        (not_survived + lost + wrong + files > 0).then(|| {
            format!(
                "{not_survived} fault(s) not survived, {lost} run(s) lost, {wrong} wrong, {files} file(s) left"
            )
        }),
        signals.and_then(|s| s.missed()),
        link_missed,
    ];
    let missed: Vec<String> = missed.into_iter().flatten().collect();
    Ok((!missed.is_empty()).then(|| missed.join("; ")))
}

/// One stop of the benchmark phase.
#[derive(Debug, Clone)]
struct BenchStop {
    signal: i32,
    to_group: bool,
    twice: bool,
    /// When the signal went, s after the bench started.
    at_s: f64,
    /// The exit code (`None`: ended by a signal, or never).
    code: Option<i32>,
    /// From the (first) signal to the exit, s.
    stop_s: f64,
    /// Processes of the bench still alive after it exited.
    processes_left: usize,
    /// Files of its pipelines left (`/dev/shm` and root folders).
    files_left: usize,
    /// Whether it had said an episode finished.
    finished_an_episode: bool,
    /// The JSON: `None` none written; `Some(Ok(episodes))` read back, partial and whole;
    /// `Some(Err(why))` unreadable or wrong.
    json: Option<Result<u64, String>>,
}

impl BenchStop {
    fn ok(&self) -> bool {
        self.code == Some(128 + self.signal)
            && self.processes_left == 0
            && self.files_left == 0
            && match &self.json {
                Some(Ok(_)) => true,
                Some(Err(_)) => false,
                // No JSON is right only when no episode had finished.
                None => !self.finished_an_episode,
            }
    }
}

/// What the benchmark phase measured.
struct BenchSignalReport {
    stops: Vec<BenchStop>,
}

impl BenchSignalReport {
    fn missed(&self) -> Option<String> {
        let bad = self.stops.iter().filter(|s| !s.ok()).count();
        (bad > 0).then(|| format!("{bad} of {} benchmark stop(s) wrong", self.stops.len()))
    }

    fn json(&self) -> Value {
        let n = self.stops.len();
        let count = |f: &dyn Fn(&BenchStop) -> bool| self.stops.iter().filter(|s| f(s)).count();
        let mut stop_s: Vec<f64> = self.stops.iter().map(|s| s.stop_s).collect();
        stop_s.sort_by(f64::total_cmp);
        json!({
            "signals": n,
            "sigint": count(&|s| s.signal == libc::SIGINT),
            "sigterm": count(&|s| s.signal == libc::SIGTERM),
            "sighup": count(&|s| s.signal == libc::SIGHUP),
            "to_group": count(&|s| s.to_group),
            "sent_twice": count(&|s| s.twice),
            "exit_128_plus_n": count(&|s| s.code == Some(128 + s.signal)),
            "processes_left": self.stops.iter().map(|s| s.processes_left).sum::<usize>(),
            "files_left": self.stops.iter().map(|s| s.files_left).sum::<usize>(),
            "partial_json_readable": count(&|s| matches!(s.json, Some(Ok(_)))),
            "partial_json_bad": count(&|s| matches!(s.json, Some(Err(_)))),
            "no_json_before_first_episode": count(&|s| s.json.is_none() && !s.finished_an_episode),
            "no_json_after_an_episode": count(&|s| s.json.is_none() && s.finished_an_episode),
            "episodes_kept": self.stops.iter().filter_map(|s| s.json.as_ref()?.as_ref().ok()).sum::<u64>(),
            "signal_at_min_s": self.stops.iter().map(|s| s.at_s).reduce(f64::min),
            "signal_at_max_s": self.stops.iter().map(|s| s.at_s).reduce(f64::max),
            "stop_time_median_s": stop_s.get(n / 2).copied(),
            "stop_time_max_s": stop_s.last().copied(),
            "all_ok": self.missed().is_none(),
            "problems": self.stops.iter().filter(|s| !s.ok()).map(|s| format!("{s:?}")).collect::<Vec<_>>(),
        })
    }

    fn print(&self) {
        let j = self.json();
        println!(
            "benchmark phase: {} stop signals to `agp bench place` (SIGINT {}, SIGTERM {}, SIGHUP {}; {} to the process group, {} sent twice)",
            j["signals"], j["sigint"], j["sigterm"], j["sighup"], j["to_group"], j["sent_twice"]
        );
        println!(
            "  exit 128+N {}/{}, processes left {}, files left {}, partial JSONs read back {} (bad {}), no JSON {} (stopped before the first episode ended; {} after one)",
            j["exit_128_plus_n"],
            j["signals"],
            j["processes_left"],
            j["files_left"],
            j["partial_json_readable"],
            j["partial_json_bad"],
            j["no_json_before_first_episode"],
            j["no_json_after_an_episode"]
        );
        println!(
            "  episodes kept in the partial JSONs {}; signal to exit: median {:.2} s, max {:.2} s",
            j["episodes_kept"],
            j["stop_time_median_s"].as_f64().unwrap_or(f64::NAN),
            j["stop_time_max_s"].as_f64().unwrap_or(f64::NAN)
        );
        for s in self.stops.iter().filter(|s| !s.ok()) {
            println!("  WRONG: {s:?}");
        }
    }
}

/// The pids whose parent is `pid`.
fn children_of(pid: u32) -> Vec<u32> {
    let Ok(entries) = std::fs::read_dir("/proc") else {
        return Vec::new();
    };
    entries
        .filter_map(Result::ok)
        .filter_map(|e| e.file_name().to_str()?.parse::<u32>().ok())
        .filter(|&p| {
            std::fs::read_to_string(format!("/proc/{p}/stat"))
                .ok()
                .and_then(|s| {
                    let (_, rest) = s.rsplit_once(')')?;
                    rest.split_whitespace().nth(1)?.parse::<u32>().ok()
                })
                == Some(pid)
        })
        .collect()
}

/// Files of the pipelines of the bench of `pid`: `/dev/shm/agp_bench-<pid>-…` and root
/// folders `bench-<pid>-*`.
fn bench_files_of(pid: u32) -> usize {
    let base = agp_runtime::Instance::new("bench-0-x")
        .ok()
        .and_then(|i| i.root_dir().parent().map(Path::to_path_buf))
        .unwrap_or_else(|| PathBuf::from("/tmp/agp"));
    let count = |dir: &Path, prefix: &str| {
        std::fs::read_dir(dir).map_or(0, |entries| {
            entries
                .filter_map(Result::ok)
                .filter(|e| e.file_name().to_string_lossy().starts_with(prefix))
                .count()
        })
    };
    count(Path::new("/dev/shm"), &format!("agp_bench-{pid}-"))
        + count(&base, &format!("bench-{pid}-"))
}

/// A stopped bench's JSON: `None` when it wrote none; else the episodes it holds, or why
/// it is unreadable or wrong (not marked partial, `episodes_finished` not what it holds).
fn read_partial_json(path: &Path) -> Option<Result<u64, String>> {
    path.is_file().then(|| {
        let text = std::fs::read_to_string(path).map_err(|e| e.to_string())?;
        let v: Value = serde_json::from_str(&text).map_err(|e| format!("not JSON: {e}"))?;
        if v["partial"] != true {
            return Err("not marked partial".to_owned());
        }
        let held: u64 = v["planners"]
            .as_object()
            .map(|m| m.values().filter_map(|p| p["episodes"].as_u64()).sum())
            .unwrap_or(0);
        if v["episodes_finished"].as_u64() != Some(held) {
            return Err(format!(
                "episodes_finished {} but {held} held",
                v["episodes_finished"]
            ));
        }
        Ok(held)
    })
}

/// The benchmark phase: `args.bench_signals` benches stopped by a signal at a random
/// moment (0.3 to 8 s after their start: setting up, placing, between episodes).
fn bench_signal_phase(
    args: &Args,
    bins: &Bins,
    work: &Path,
    ag_file: &Path,
) -> Result<BenchSignalReport> {
    const SIGNALS: [i32; 3] = [libc::SIGINT, libc::SIGTERM, libc::SIGHUP];
    let mut rng = Rng::stream(args.seed, 35);
    let mut stops = Vec::new();
    for i in 0..args.bench_signals {
        let dir = work.join(format!("bench-signal-{i}"));
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("cannot create {}", dir.display()))?;
        let sig = SIGNALS[(rng.next_u64() % 3) as usize];
        let to_group = rng.uniform() < 0.5;
        let twice = rng.uniform() < 0.25;
        let at = Duration::from_secs_f64(rng.range(0.3, 8.0));
        let err_path = dir.join("bench.err");
        let mut child = bins
            .agp(&dir)
            .args([
                "bench",
                "place",
                "--scenario",
                "triangle",
                "--episodes",
                "40",
            ])
            .args(["--seed", &(200 + u64::from(i)).to_string()])
            .args(["--planners", "affordance,baseline", "--ag"])
            .arg(ag_file)
            .args(["--json", "place.json"])
            .stdout(Stdio::null())
            .stderr(
                std::fs::File::create(&err_path)
                    .with_context(|| format!("cannot create {}", err_path.display()))?,
            )
            .spawn()
            .context("cannot start `agp bench place`")?;
        let pid = child.id();
        let started = Instant::now();
        let mut ended = None;
        while started.elapsed() < at {
            if let Some(s) = child.try_wait().context("cannot watch the bench")? {
                ended = Some(s);
                break;
            }
            if let Err(e) = sleep_checked(Duration::from_millis(10)) {
                signal(pid, libc::SIGKILL);
                let _ = child.wait();
                return Err(e);
            }
        }
        if ended.is_some() {
            bail!(
                "`agp bench place` ended before its signal; see {}",
                err_path.display()
            );
        }
        let mut pids = children_of(pid);
        let at_s = started.elapsed().as_secs_f64();
        let target = if to_group { -(pid as i64) } else { pid as i64 };
        let send = |s: i32| {
            // SAFETY: plain kill(2) of our own child, not reaped, or the group it leads.
            unsafe { libc::kill(target as libc::pid_t, s) };
        };
        let sent = Instant::now();
        send(sig);
        if twice {
            // Once the bench said it is stopping (or 2 s, if it did not get there).
            while sent.elapsed() < Duration::from_secs(2)
                && !std::fs::read_to_string(&err_path)
                    .unwrap_or_default()
                    .contains("a second signal stops at once")
                && child.try_wait().ok().flatten().is_none()
            {
                std::thread::sleep(Duration::from_millis(5));
            }
            send(sig);
        }
        let exit = loop {
            if let Some(s) = child.try_wait().context("cannot watch the bench")? {
                break Some(s);
            }
            if sent.elapsed() > Duration::from_secs(60) {
                signal(pid, libc::SIGKILL);
                let _ = child.wait();
                break None;
            }
            for p in children_of(pid) {
                if !pids.contains(&p) {
                    pids.push(p);
                }
            }
            std::thread::sleep(Duration::from_millis(5));
        };
        let stop_s = sent.elapsed().as_secs_f64();
        // Children already dying (killed with the bench) get a moment.
        let deadline = Instant::now() + Duration::from_secs(2);
        while pids.iter().any(|&p| !agp_harness::pipeline::is_gone(p)) && Instant::now() < deadline
        {
            std::thread::sleep(Duration::from_millis(5));
        }
        let processes_left = pids
            .iter()
            .filter(|&&p| !agp_harness::pipeline::is_gone(p))
            .count();
        reap_children(bins, &pids, Duration::ZERO);
        let stderr = std::fs::read_to_string(&err_path).unwrap_or_default();
        let json = read_partial_json(&dir.join("place.json"));
        let stop = BenchStop {
            signal: sig,
            to_group,
            twice,
            at_s,
            code: exit.and_then(|e| e.code()),
            stop_s,
            processes_left,
            files_left: bench_files_of(pid),
            finished_an_episode: stderr.contains(" done ("),
            json,
        };
        eprintln!(
            "bench signal {}/{}: {} {} at {at_s:.1} s{}: exit {:?} after {stop_s:.2} s, {} process(es) and {} file(s) left, JSON {:?}",
            i + 1,
            args.bench_signals,
            agp_harness::stop::signal_name(sig),
            if to_group {
                "to the group"
            } else {
                "to the bench"
            },
            if twice { " (twice)" } else { "" },
            stop.code,
            stop.processes_left,
            stop.files_left,
            stop.json
        );
        stops.push(stop);
    }
    let report = BenchSignalReport { stops };
    report.print();
    Ok(report)
}

/// The figures of a campaign.
struct Report {
    wall_s: f64,
    /// Per (kind, phase): injected, survived, recoveries ms.
    table: BTreeMap<(FaultKind, Phase), (u32, u32, Vec<f64>)>,
}

fn median(v: &[f64]) -> Option<f64> {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    (!v.is_empty()).then(|| v[v.len() / 2])
}

fn max(v: &[f64]) -> Option<f64> {
    v.iter().copied().max_by(f64::total_cmp)
}

fn ms(v: Option<f64>) -> String {
    v.map_or("-".to_owned(), |v| format!("{v:.0}"))
}

impl Report {
    fn new(c: &Campaign) -> Self {
        let mut table: BTreeMap<(FaultKind, Phase), (u32, u32, Vec<f64>)> = BTreeMap::new();
        for f in &c.faults {
            let e = table.entry((f.kind, f.phase)).or_default();
            e.0 += 1;
            e.1 += u32::from(f.survived);
            e.2.extend(f.recovery_ms);
        }
        Self {
            wall_s: c.started.elapsed().as_secs_f64(),
            table,
        }
    }

    fn longest(c: &Campaign) -> Option<&FaultRecord> {
        c.faults
            .iter()
            .filter(|f| f.recovery_ms.is_some())
            .max_by(|a, b| {
                a.recovery_ms
                    .unwrap_or(0.0)
                    .total_cmp(&b.recovery_ms.unwrap_or(0.0))
            })
    }

    fn print(&self, c: &Campaign, interrupted: bool) {
        let injected = c.faults.len();
        let survived = c.faults.iter().filter(|f| f.survived).count();
        println!(
            "fault campaign{}: {injected} faults in {} runs, seed {}, {:.0} s wall (release binaries in {})",
            if interrupted { " (interrupted)" } else { "" },
            c.runs.len(),
            c.args.seed,
            self.wall_s,
            c.bins.dir().display()
        );
        println!(
            "live = a live session on the realtime clock (physics at 640 Hz of wall time, the estimator serving the AG file, `agp-planner --mode serve`) pursuing the goal `agp goal --place {}` (the object where it starts: found by circling it, then judged there), then `agp down`; correct = the goal reached, or ended by the planner with its reason",
            LIVE_GOAL.join(" ")
        );
        let live: Vec<&RunRecord> = c.runs.iter().filter(|r| r.phase == Phase::Live).collect();
        if !live.is_empty() {
            println!(
                "live goals: {} reached of {} ({})",
                live.iter()
                    .filter(|r| r.note.starts_with("goal reached"))
                    .count(),
                live.len(),
                live.iter()
                    .filter(|r| !r.note.starts_with("goal reached"))
                    .map(|r| format!("run {}: {}", r.index, r.note))
                    .collect::<Vec<_>>()
                    .join("; ")
            );
        }
        println!();
        println!(
            "{:<30} {:<6} {:>8} {:>8} {:>14} {:>14}",
            "fault", "phase", "injected", "survived", "recovery p50", "recovery max"
        );
        for ((kind, phase), (n, ok, rec)) in &self.table {
            println!(
                "{:<30} {:<6} {:>8} {:>8} {:>11} ms {:>11} ms",
                kind.label(),
                phase.as_str(),
                n,
                ok,
                ms(median(rec)),
                ms(max(rec))
            );
        }
        let all: Vec<f64> = c.faults.iter().filter_map(|f| f.recovery_ms).collect();
        println!(
            "{:<30} {:<6} {:>8} {:>8} {:>11} ms {:>11} ms",
            "all",
            "",
            injected,
            survived,
            ms(median(&all)),
            ms(max(&all))
        );
        println!();
        println!(
            "{:<6} {:>6} {:>9} {:>7} {:>5} {:>11}",
            "phase", "runs", "completed", "correct", "lost", "files left"
        );
        for phase in Phase::ALL {
            let runs: Vec<&RunRecord> = c.runs.iter().filter(|r| r.phase == phase).collect();
            let completed = runs.iter().filter(|r| r.completed).count();
            let correct = runs
                .iter()
                .filter(|r| r.correct == Some(true))
                .count()
                .to_string();
            let files: usize = runs.iter().map(|r| r.files_left).sum();
            println!(
                "{:<6} {:>6} {:>9} {:>7} {:>5} {:>11}",
                phase.as_str(),
                runs.len(),
                completed,
                correct,
                runs.len() - completed,
                files
            );
        }
        let completed = c.runs.iter().filter(|r| r.completed).count();
        let files: usize = c.runs.iter().map(|r| r.files_left).sum();
        println!(
            "{:<6} {:>6} {:>9} {:>7} {:>5} {:>11}",
            "all",
            c.runs.len(),
            completed,
            c.runs.iter().filter(|r| r.correct == Some(true)).count(),
            c.runs.len() - completed,
            files
        );
        println!();
        match Self::longest(c) {
            Some(f) => println!(
                "longest recovery: {:.0} ms ({}, {} run {}, {:.1} s into it)",
                f.recovery_ms.unwrap_or(0.0),
                f.kind.label(),
                f.phase.as_str(),
                f.run,
                f.at_s
            ),
            None => println!("longest recovery: none measured"),
        }
        let failed: Vec<&FaultRecord> = c.faults.iter().filter(|f| !f.survived).collect();
        if !failed.is_empty() {
            println!("faults not survived:");
            for f in failed {
                println!(
                    "  run {} ({}) at {:.1} s: {}: {}",
                    f.run,
                    f.phase.as_str(),
                    f.at_s,
                    f.kind.label(),
                    f.note
                );
            }
        }
        let bad: Vec<&RunRecord> = c
            .runs
            .iter()
            .filter(|r| !r.completed || r.correct == Some(false) || r.files_left > 0)
            .collect();
        if !bad.is_empty() {
            println!("runs lost, wrong or leaving files:");
            for r in bad {
                println!(
                    "  run {} ({}, `{}`, {} fault(s), {} up(s), exit {}, {} file(s) left): {}",
                    r.index,
                    r.phase.as_str(),
                    r.instance,
                    r.faults,
                    r.ups,
                    r.exit.map_or("-".to_owned(), |c| c.to_string()),
                    r.files_left,
                    r.note
                );
            }
        }
    }

    fn json(&self, c: &Campaign) -> Value {
        let table: Vec<Value> = self
            .table
            .iter()
            .map(|((kind, phase), (n, ok, rec))| {
                json!({
                    "fault": kind.label(),
                    "phase": phase.as_str(),
                    "injected": n,
                    "survived": ok,
                    "recovery_p50_ms": median(rec),
                    "recovery_max_ms": max(rec),
                })
            })
            .collect();
        let faults: Vec<Value> = c
            .faults
            .iter()
            .map(|f| {
                json!({
                    "run": f.run,
                    "phase": f.phase.as_str(),
                    "fault": f.kind.label(),
                    "at_s": f.at_s,
                    "pause_ms": f.pause_ms,
                    "survived": f.survived,
                    "recovery_ms": f.recovery_ms,
                    "note": f.note,
                })
            })
            .collect();
        let runs: Vec<Value> = c
            .runs
            .iter()
            .map(|r| {
                json!({
                    "run": r.index,
                    "phase": r.phase.as_str(),
                    "instance": r.instance,
                    "faults": r.faults,
                    "ups": r.ups,
                    "completed": r.completed,
                    "correct": r.correct,
                    "exit": r.exit,
                    "files_left": r.files_left,
                    "wall_s": r.wall_s,
                    "note": r.note,
                })
            })
            .collect();
        let longest = Self::longest(c);
        json!({
            "seed": c.args.seed,
            "faults_requested": c.args.faults,
            "faults_injected": c.faults.len(),
            "faults_survived": c.faults.iter().filter(|f| f.survived).count(),
            "runs": c.runs.len(),
            "runs_completed": c.runs.iter().filter(|r| r.completed).count(),
            "runs_correct": c.runs.iter().filter(|r| r.correct == Some(true)).count(),
            "runs_with_verdict": c.runs.iter().filter(|r| r.correct.is_some()).count(),
            "files_left": c.runs.iter().map(|r| r.files_left).sum::<usize>(),
            "longest_recovery_ms": longest.and_then(|f| f.recovery_ms),
            "longest_recovery_fault": longest.map(|f| format!("{} ({}, run {})", f.kind.label(), f.phase.as_str(), f.run)),
            "wall_s": self.wall_s,
            "trials_per_alpha": c.args.trials_per_alpha,
            "live_session": format!("a live session on the realtime clock with `agp-planner --mode serve` pursuing `agp goal --place {}`, then `agp down`", LIVE_GOAL.join(" ")),
            "by_fault_and_phase": table,
            "fault_list": faults,
            "run_list": runs,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_instance_of_the_campaign_is_one_agp_down_stale_removes_once_the_campaign_is_dead() {
        // The longest name: the longest tag, with a pid of 7 digits (the kernel's limit).
        let longest = format!("bench-{}-v9999r", 4_194_304);
        agp_runtime::Instance::validate_name(&longest).expect("a valid instance name");
        for tag in ["f0001", "l0001r", "v0001p"] {
            let name = run_instance(tag);
            assert!(
                name.starts_with(&format!("bench-{}-", std::process::id())),
                "{name}"
            );
            agp_runtime::Instance::validate_name(&name).expect("a valid instance name");
        }
        // What a campaign killed with -9 left: its pid is a child's that exited, reaped.
        let mut child = std::process::Command::new("true")
            .spawn()
            .expect("`true` runs");
        let dead = child.id();
        child.wait().expect("reaped");
        let name = format!("bench-{dead}-v0001r");
        let leftover = Path::new("/dev/shm").join(format!("agp_{name}.leftover"));
        std::fs::write(&leftover, b"").expect("a file in /dev/shm");
        let swept = agp_harness::stop::sweep_stale();
        let gone = !leftover.exists();
        let _ = std::fs::remove_file(&leftover);
        let swept = swept.expect("the sweep");
        assert!(swept.instances.contains(&name), "{swept:?}");
        assert!(gone, "{} is left", leftover.display());
    }
}
