//! Benchmark episodes over the real pipeline: a private instance (`bench-<pid>-<tag>`) with
//! lockstep `agp-physics`, `agp-estimator` serving an AG file's gradients over the `grids`
//! topic, and one `agp-planner` process per episode. The benchmark plays the experimenter
//! and the judge: it puts the object and the robot back at the scenario's start before each
//! episode (a reset, as the learning protocol does) and reads ground truth, which no
//! planner but the oracle sees. Every file of the instance is removed at the end.

use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use agp_planning::{EpisodeConfig, EpisodeEnd, EpisodeResult, PlannerKind, Task};
use agp_runtime::{AgpIpc, DriveError, Instance, LockstepDriver, TruthAccess};
use agp_shared_types::Pose2;
use agp_world::Scenario;
use anyhow::{Context, Result, anyhow, bail};
use iceoryx2::prelude::Node;

use crate::evaluation::{EstimateRecorder, TruthRecorder};
use agp_runtime::children::{GuardedChild, sibling_executable};

/// Safety net of the waits on the pipeline's processes (never the check itself).
const LINK_TIMEOUT: Duration = Duration::from_secs(60);
/// Longest wall time one episode may take before the benchmark gives up on it.
const EPISODE_WALL_LIMIT: Duration = Duration::from_secs(600);

/// Whether each pipeline's processes are pinned to one core ([`CoreLease`]): `AGP_BENCH_PIN`
/// `0` turns it off, anything else (or unset) leaves it on.
fn pinning_wanted() -> bool {
    std::env::var("AGP_BENCH_PIN").map_or(true, |v| v.trim() != "0")
}

/// The environment variable naming a folder of slot files (`slot-0`, `slot-1`, ...) shared
/// by several bench processes: a pipeline runs only while it holds one slot's lock, on that
/// slot's core, so benches started side by side (`agp bench paper --jobs N`) run at most N
/// pipelines at once between them.
pub const SLOTS_ENV: &str = "AGP_BENCH_SLOTS";

/// How many pipelines of this process run on each core the process may use, by the
/// core's place in [`allowed_cpus`] (without [`SLOTS_ENV`]).
static PIPELINES_ON_CORE: Mutex<Vec<usize>> = Mutex::new(Vec::new());

/// The cores this process may run on (its affinity mask), ascending; empty when the mask
/// cannot be read.
pub fn allowed_cpus() -> Vec<usize> {
    // SAFETY: an all-zero `cpu_set_t` is a valid empty set; `sched_getaffinity` writes at
    // most `size_of::<cpu_set_t>()` bytes into the set we own.
    let (set, ok) = unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        let ok = libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set) == 0;
        (set, ok)
    };
    if !ok {
        return Vec::new();
    }
    (0..libc::CPU_SETSIZE as usize)
        // SAFETY: `c` is below CPU_SETSIZE, the set's size in bits.
        .filter(|&c| unsafe { libc::CPU_ISSET(c, &set) })
        .collect()
}

/// The set holding `cpu` alone.
fn cpu_set_of(cpu: usize) -> libc::cpu_set_t {
    // SAFETY: an all-zero `cpu_set_t` is a valid empty set, and callers pass a core of the
    // affinity mask, which is below CPU_SETSIZE.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        libc::CPU_SET(cpu, &mut set);
        set
    }
}

/// Where a pipeline runs: one core for all its processes (physics, the estimator, each
/// episode's planner), and with [`SLOTS_ENV`] the slot it holds. A lockstep step passes the
/// three processes one after the other, so one core holds a ring; pipelines side by side
/// each on a core of their own no longer wait for each other's polling processes in their
/// handoffs (README, The paper's tasks, gives the figures). Results do not change: a
/// lockstep run is the same whatever the scheduling. The lease gives the core (and the
/// slot) back when dropped.
struct CoreLease {
    /// The core's place in [`allowed_cpus`] (its count in [`PIPELINES_ON_CORE`]), without
    /// slots.
    counted: Option<usize>,
    /// The locked slot file, with [`SLOTS_ENV`]: unlocked when closed.
    _slot: Option<std::fs::File>,
    /// The core, when pinning is on.
    set: Option<libc::cpu_set_t>,
}

impl CoreLease {
    /// Where a new pipeline runs. With [`SLOTS_ENV`] it waits for a free slot (its core:
    /// the slot's number modulo the cores); without, it takes the core with the fewest of
    /// this process's pipelines. `Ok(None)`: anywhere (pinning off, one core, no slots).
    /// `cost` (the pipeline's expected work) and `tag` (its name among this process's
    /// pipelines) place it in the slots' queue ([`take_slot`]).
    fn take(cost: u64, tag: &str) -> Result<Option<Self>> {
        let cpus = allowed_cpus();
        let pinning = pinning_wanted() && cpus.len() > 1;
        if let Some(dir) = std::env::var_os(SLOTS_ENV) {
            let (k, file) = take_slot(Path::new(&dir), cost, tag)?;
            return Ok(Some(Self {
                counted: None,
                _slot: Some(file),
                set: pinning.then(|| cpu_set_of(cpus[k % cpus.len()])),
            }));
        }
        if !pinning {
            return Ok(None);
        }
        let mut counts = PIPELINES_ON_CORE
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        counts.resize(cpus.len(), 0);
        let Some(k) = (0..cpus.len()).min_by_key(|&k| counts[k]) else {
            return Ok(None);
        };
        counts[k] += 1;
        Ok(Some(Self {
            counted: Some(k),
            _slot: None,
            set: Some(cpu_set_of(cpus[k])),
        }))
    }

    /// Makes `cmd`'s process start on this lease's core, if it has one.
    fn pin(&self, cmd: &mut Command) {
        let Some(set) = self.set else {
            return;
        };
        // SAFETY: between fork and exec only `sched_setaffinity`, a plain system call on the
        // child itself, reading the copied set.
        unsafe {
            cmd.pre_exec(move || {
                if libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
                Ok(())
            });
        }
    }
}

impl Drop for CoreLease {
    fn drop(&mut self) {
        if let Some(k) = self.counted {
            let mut counts = PIPELINES_ON_CORE
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            if let Some(n) = counts.get_mut(k) {
                *n = n.saturating_sub(1);
            }
        }
    }
}

/// How often the waiting pipeline of most work looks for a free slot.
const HEAD_POLL: Duration = Duration::from_millis(20);
/// How often the other waiting pipelines look whether they now have the most work: a slot
/// freed only every ten seconds or so (a pipeline's episodes take 10-40 s).
const QUEUE_POLL: Duration = Duration::from_millis(250);

/// A pipeline waiting for a slot, as the others see it: the file
/// `wait-<cost, 12 digits>-<pid>-<tag>` in the slots' folder, locked (flock) while its
/// owner lives, removed when the pipeline has its slot or gives up. The file's name orders
/// the waiters: most work first (ties: the larger name).
struct Waiting {
    path: PathBuf,
    name: String,
    _lock: std::fs::File,
}

impl Waiting {
    /// Enters the queue of `dir`. The file is locked under a name no other waiter reads and
    /// only then renamed into the queue, so a waiter that finds a `wait-` file it can lock
    /// knows its owner is gone.
    fn enter(dir: &Path, cost: u64, tag: &str) -> Result<Self> {
        let pid = std::process::id();
        let name = format!("wait-{cost:012}-{pid}-{tag}");
        let draft = dir.join(format!("draft-{pid}-{tag}"));
        let file = std::fs::File::create(&draft)
            .with_context(|| format!("cannot create {}", draft.display()))?;
        if !try_lock(&file) {
            bail!(
                "cannot lock {}: {}",
                draft.display(),
                std::io::Error::last_os_error()
            );
        }
        let path = dir.join(&name);
        std::fs::rename(&draft, &path)
            .with_context(|| format!("cannot rename {} to {name}", draft.display()))?;
        Ok(Self {
            path,
            name,
            _lock: file,
        })
    }

    /// Whether a live pipeline of more work (a larger name) waits in `dir`; the files of
    /// waiters that died are removed on the way.
    fn behind_another(&self, dir: &Path) -> Result<bool> {
        let entries =
            std::fs::read_dir(dir).with_context(|| format!("cannot read {}", dir.display()))?;
        for entry in entries.flatten() {
            let name = entry.file_name();
            let Some(name) = name.to_str() else { continue };
            if !name.starts_with("wait-") || name <= self.name.as_str() {
                continue;
            }
            // Gone already: it took its slot.
            let Ok(file) = std::fs::File::open(entry.path()) else {
                continue;
            };
            if !try_lock(&file) {
                return Ok(true);
            }
            // Its owner died waiting (or took its slot just now: then the name is gone).
            let _ = std::fs::remove_file(entry.path());
        }
        Ok(false)
    }
}

impl Drop for Waiting {
    fn drop(&mut self) {
        // Removed before the lock goes with the file (fields drop after this).
        let _ = std::fs::remove_file(&self.path);
    }
}

/// Takes an exclusive flock(2) on `file` without waiting: whether it got it. The lock lasts
/// as long as the file stays open.
fn try_lock(file: &std::fs::File) -> bool {
    use std::os::fd::AsRawFd;
    // SAFETY: flock(2) on a descriptor `file` owns and keeps open for the call.
    unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) == 0 }
}

/// Waits until one of the slot files `slot-0`, `slot-1`, ... in `dir` can be locked and no
/// live pipeline of more expected work (`cost`) waits for one; its number and the locked
/// file. Longest first: the pipelines of a run sharing the slots (`agp bench paper
/// --jobs N`) are scheduled by their expected work, so that no long one starts last and
/// leaves the other cores idle while it ends. Gives up at a shutdown request.
fn take_slot(dir: &Path, cost: u64, tag: &str) -> Result<(usize, std::fs::File)> {
    let mut count = 0;
    while dir.join(format!("slot-{count}")).is_file() {
        count += 1;
    }
    if count == 0 {
        bail!("{SLOTS_ENV}={}: no slot file `slot-0` there", dir.display());
    }
    let waiting = Waiting::enter(dir, cost, tag)?;
    loop {
        if agp_runtime::shutdown_requested() {
            bail!("interrupted");
        }
        if waiting.behind_another(dir)? {
            std::thread::sleep(QUEUE_POLL);
            continue;
        }
        for k in 0..count {
            let path = dir.join(format!("slot-{k}"));
            let file = std::fs::File::open(&path)
                .with_context(|| format!("cannot open the slot file {}", path.display()))?;
            if try_lock(&file) {
                return Ok((k, file));
            }
        }
        std::thread::sleep(HEAD_POLL);
    }
}

/// Pins `cmd` to `core`'s core, when the pipeline has one.
fn pin(core: Option<&CoreLease>, cmd: &mut Command) {
    if let Some(core) = core {
        core.pin(cmd);
    }
}

/// A running private pipeline for benchmark episodes.
pub struct PipelineBench {
    instance: Instance,
    scenario_arg: String,
    scenario: Scenario,
    physics: GuardedChild,
    estimator: Option<GuardedChild>,
    /// The experimenter's hand: resets only, never a motor command.
    driver: LockstepDriver,
    truth: TruthRecorder,
    estimates: EstimateRecorder,
    _node: Node<AgpIpc>,
    logs: tempfile::TempDir,
    episodes: u32,
    /// An object never pushed: the estimator starts each episode from nothing
    /// (`--learn-online --from-prior`, restarted before each episode but the first) and the
    /// affordance planner plans on its prior (`--from-prior`).
    online: bool,
    /// Ground-truth samples the evaluation missed (its buffer overflowed), all episodes.
    pub truth_gaps: u64,
    /// The core every process of this pipeline runs on (none when pinning is off).
    core: Option<CoreLease>,
}

impl PipelineBench {
    /// Starts physics (seeded with `seed`) and the estimator, serving `ag`'s gradients if
    /// given, under the instance `bench-<pid>-<tag>` (`tag`: lowercase letters, digits,
    /// `-`, `_`; one per pipeline running at once). With [`SLOTS_ENV`] it first waits for
    /// a slot, the waiting pipeline of most expected work `cost` first (any unit, the same
    /// for every pipeline sharing the slots; the task benches use simulated seconds).
    pub fn start(
        scenario_arg: &str,
        ag: Option<&Path>,
        seed: u64,
        tag: &str,
        cost: u64,
    ) -> Result<Self> {
        Self::launch(scenario_arg, ag, false, seed, tag, cost)
    }

    /// As [`PipelineBench::start`], for an object never pushed before: no AG file; each
    /// episode starts with a fresh estimator that builds its gradient from the contact
    /// prior of the episode's first circling and learns on from the episode's pushes
    /// (issue 33), and the affordance planner plans on what it publishes.
    pub fn start_online(scenario_arg: &str, seed: u64, tag: &str, cost: u64) -> Result<Self> {
        Self::launch(scenario_arg, None, true, seed, tag, cost)
    }

    /// The estimator of this pipeline: serving `ag`, learning online from the prior, or
    /// perceiving only.
    fn spawn_estimator(
        name: &str,
        scenario_arg: &str,
        ag: Option<&Path>,
        online: bool,
        core: Option<&CoreLease>,
    ) -> Result<GuardedChild> {
        let mut cmd = Command::new(sibling_executable("agp-estimator")?);
        pin(core, &mut cmd);
        cmd.args(["--instance", name, "--scenario", scenario_arg])
            .stdin(Stdio::null())
            .stdout(Stdio::null());
        match ag {
            _ if online => cmd.args(["--learn-online", "--from-prior"]),
            Some(path) => cmd.arg("--load").arg(path),
            None => cmd.arg("--perceive-only"),
        };
        GuardedChild::spawn("agp-estimator", &mut cmd)
    }

    fn launch(
        scenario_arg: &str,
        ag: Option<&Path>,
        online: bool,
        seed: u64,
        tag: &str,
        cost: u64,
    ) -> Result<Self> {
        let scenario = Scenario::resolve(scenario_arg)?;
        let name = format!("bench-{}-{tag}", std::process::id());
        let instance = Instance::new(&name).map_err(|e| anyhow!("instance `{name}`: {e}"))?;
        // A bench of the same pid that died hard may have left files: they are ours.
        instance
            .remove_files()
            .context("cannot clear the bench's instance files")?;
        let logs = tempfile::tempdir().context("cannot create a folder for the episode logs")?;
        let core = CoreLease::take(cost, tag)?;
        let mut cmd = Command::new(sibling_executable("agp-physics")?);
        pin(core.as_ref(), &mut cmd);
        cmd.args(["--instance", &name, "--scenario", scenario_arg])
            .args(["--clock", "lockstep", "--idle-timeout-s", "0"])
            .args(["--seed", &seed.to_string()])
            .stdin(Stdio::null())
            .stdout(Stdio::null());
        let physics = GuardedChild::spawn("agp-physics", &mut cmd)?;
        // The estimator perceives for every planner; with `ag` it also serves its gradients.
        let estimator = Some(Self::spawn_estimator(
            &name,
            scenario_arg,
            ag,
            online,
            core.as_ref(),
        )?);
        let driver = match LockstepDriver::connect(
            &instance,
            "bench",
            0,
            TruthAccess::SensesOnly,
            LINK_TIMEOUT,
        ) {
            Ok(d) => d,
            Err(DriveError::Shutdown) => bail!("interrupted"),
            Err(e) => return Err(e).context("cannot reach the bench's physics"),
        };
        let node = instance
            .node("bench-judge", false)
            .map_err(|e| anyhow!("cannot create the bench's node: {e:?}"))?;
        let every = EpisodeConfig::for_task(&scenario.task).record_every_steps;
        let truth = TruthRecorder::open(&instance, &node, every)?;
        let estimates = EstimateRecorder::open(&instance, &node)?;
        Ok(Self {
            instance,
            scenario_arg: scenario_arg.to_owned(),
            scenario,
            physics,
            estimator,
            driver,
            truth,
            estimates,
            _node: node,
            logs,
            episodes: 0,
            online,
            truth_gaps: 0,
            core,
        })
    }

    /// Runs one episode of `task` with `planner` from the scenario's start poses, judged by
    /// ground truth with the tolerances of `config`.
    pub fn episode(
        &mut self,
        planner: PlannerKind,
        task: &Task,
        config: &EpisodeConfig,
    ) -> Result<EpisodeResult> {
        self.episodes += 1;
        let o = self.scenario.object.start;
        let r = self.scenario.robot.start;
        // The episode's seed restarts physics's noise, as an in-process episode's fresh
        // world of that seed draws it: episode k's noise is the same for every planner.
        match self.driver.reset_seeded(o, r, config.seed) {
            Ok(_) => {}
            Err(DriveError::Shutdown) => bail!("interrupted"),
            Err(e) => return Err(e).context("cannot reset the bench's physics"),
        }
        if self.online && self.episodes > 1 {
            // Never pushed before: what the last episode's estimator learned goes with it.
            if let Some(e) = &mut self.estimator {
                e.stop(Duration::from_secs(5))?;
            }
            self.estimator = Some(Self::spawn_estimator(
                self.instance.name(),
                &self.scenario_arg,
                None,
                true,
                self.core.as_ref(),
            )?);
        }
        // The episode starts from the reset: only its samples count.
        self.truth.restart()?;
        self.estimates.restart();

        let report = self
            .logs
            .path()
            .join(format!("episode-{}.json", self.episodes));
        let stderr_path = self
            .logs
            .path()
            .join(format!("episode-{}.stderr", self.episodes));
        let mut cmd = Command::new(sibling_executable("agp-planner")?);
        pin(self.core.as_ref(), &mut cmd);
        cmd.args(["--instance", self.instance.name()])
            .args(["--scenario", &self.scenario_arg])
            .args(["--clock", "lockstep", "--planner", planner.name()])
            .args(
                (self.online && planner == PlannerKind::Affordance)
                    .then_some("--from-prior")
                    .as_slice(),
            )
            .arg("--report")
            .arg(&report)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(
                std::fs::File::create(&stderr_path)
                    .with_context(|| format!("cannot create {}", stderr_path.display()))?,
            );
        match task {
            Task::Place { goal } => {
                cmd.args(["--mode", "place", "--goal"]).arg(format!(
                    "{},{},{}",
                    goal.x * 1e3,
                    goal.y * 1e3,
                    goal.theta.to_degrees()
                ));
            }
            Task::Trajectory {
                path,
                keep_heading_rad,
            } => {
                // Before `--path`, which takes every word after it.
                if let Some(h) = keep_heading_rad {
                    cmd.arg("--keep-heading").arg(format!("{}", h.to_degrees()));
                }
                cmd.args(["--mode", "trajectory", "--path"])
                    .args(path.iter().map(|p| format!("{},{}", p.x * 1e3, p.y * 1e3)));
            }
        }
        let wall = Instant::now();
        let mut child = GuardedChild::spawn("agp-planner", &mut cmd)?;
        let status = loop {
            self.truth.drain()?;
            self.estimates.drain(true);
            if let Some(status) = child.try_wait()? {
                break status;
            }
            if agp_runtime::shutdown_requested() {
                child.stop(Duration::from_secs(2))?;
                bail!("interrupted");
            }
            if wall.elapsed() > EPISODE_WALL_LIMIT {
                child.stop(Duration::from_secs(2))?;
                bail!("planner `{planner}` did not end its episode within {EPISODE_WALL_LIMIT:?}");
            }
            std::thread::sleep(Duration::from_micros(500));
        };
        if !status.success() {
            let text = std::fs::read_to_string(&stderr_path).unwrap_or_default();
            let tail: Vec<&str> = text.lines().rev().take(5).collect();
            bail!(
                "planner `{planner}` exited with {status}: {}",
                tail.into_iter().rev().collect::<Vec<_>>().join(" / ")
            );
        }
        let planner_view = PlannerView::read(&report)?;
        let truth = self
            .truth
            .finish()?
            .ok_or_else(|| anyhow!("no ground truth arrived during the episode"))?;
        self.truth_gaps += self.truth.gaps;
        self.estimates.drain(true);
        // Judged as an in-process episode is: the final true pose, the recorded ones and
        // the estimates.
        Ok(EpisodeResult {
            planner,
            end: planner_view.end,
            pushes: planner_view.pushes,
            circlings: planner_view.circlings,
            sim_time_s: planner_view.sim_time_s,
            wall_time_s: wall.elapsed().as_secs_f64(),
            final_estimate: planner_view.final_estimate,
            evaluation: None,
            samples: std::mem::take(&mut self.truth.samples),
            final_truth: Some(truth.object),
            estimates: self.estimates.log,
            estimate_verdict: None,
        }
        .judged(task, self.scenario.object.shape.symmetry_order(), config))
    }

    /// Stops every process and removes every file of the instance.
    pub fn stop(mut self) -> Result<()> {
        let mut problems = Vec::new();
        if let Some(e) = &mut self.estimator
            && let Err(err) = e.stop(Duration::from_secs(5))
        {
            problems.push(format!("{err:#}"));
        }
        if let Err(err) = self.physics.stop(Duration::from_secs(5)) {
            problems.push(format!("{err:#}"));
        }
        let instance = self.instance.clone();
        drop(self);
        if let Err(err) = instance.remove_files() {
            problems.push(format!(
                "cannot remove the files of instance `{}`: {err}",
                instance.name()
            ));
        }
        if problems.is_empty() {
            Ok(())
        } else {
            bail!("{}", problems.join("; "))
        }
    }
}

/// The planner's own account of an episode (`agp-planner --report`).
struct PlannerView {
    end: EpisodeEnd,
    pushes: u32,
    circlings: u32,
    sim_time_s: f64,
    final_estimate: Option<Pose2>,
}

impl PlannerView {
    fn read(path: &PathBuf) -> Result<Self> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("the planner wrote no report at {}", path.display()))?;
        let v: serde_json::Value =
            serde_json::from_str(&text).with_context(|| format!("{}: not JSON", path.display()))?;
        let num = |k: &str| {
            v.get(k)
                .and_then(serde_json::Value::as_f64)
                .ok_or_else(|| anyhow!("{}: no number `{k}`", path.display()))
        };
        let end_name = v.get("end").and_then(|e| e.as_str()).unwrap_or_default();
        let end = EpisodeEnd::ALL
            .into_iter()
            .find(|e| e.name() == end_name)
            .ok_or_else(|| anyhow!("{}: unknown end `{end_name}`", path.display()))?;
        let final_estimate = v
            .get("final_estimate")
            .filter(|e| !e.is_null())
            .map(|e| -> Result<Pose2> {
                let f = |k: &str| {
                    e.get(k)
                        .and_then(serde_json::Value::as_f64)
                        .ok_or_else(|| anyhow!("{}: no `final_estimate.{k}`", path.display()))
                };
                Ok(Pose2::new(
                    f("x_mm")? * 1e-3,
                    f("y_mm")? * 1e-3,
                    f("theta_deg")?.to_radians(),
                ))
            })
            .transpose()?;
        Ok(Self {
            end,
            pushes: num("pushes")? as u32,
            circlings: num("circlings")? as u32,
            sim_time_s: num("sim_time_s")?,
            final_estimate,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn benches_sharing_slot_files_hold_each_slot_once_and_free_it_when_done() {
        let dir = tempfile::tempdir().expect("a temporary folder");
        for k in 0..2 {
            std::fs::File::create(dir.path().join(format!("slot-{k}"))).expect("slot file");
        }
        let (first, held) = take_slot(dir.path(), 10, "a").expect("a free slot");
        let (second, _held_too) = take_slot(dir.path(), 10, "b").expect("the other slot");
        assert_eq!(
            (first, second),
            (0, 1),
            "two pipelines, two different slots"
        );
        drop(held);
        let (again, _) = take_slot(dir.path(), 10, "c").expect("the slot given back");
        assert_eq!(
            again, 0,
            "a finished pipeline's slot is taken by the next one"
        );
    }

    #[test]
    fn of_the_pipelines_waiting_for_a_slot_the_one_of_most_work_goes_first() {
        let dir = tempfile::tempdir().expect("a temporary folder");
        let small = Waiting::enter(dir.path(), 5, "small").expect("in the queue");
        let big = Waiting::enter(dir.path(), 900, "big").expect("in the queue");
        assert!(small.behind_another(dir.path()).expect("the queue read"));
        assert!(!big.behind_another(dir.path()).expect("the queue read"));
        drop(big);
        assert!(
            !small.behind_another(dir.path()).expect("the queue read"),
            "the big one left the queue (it has its slot)"
        );
    }

    #[test]
    fn a_waiter_that_died_holds_up_nobody_and_its_file_is_removed() {
        let dir = tempfile::tempdir().expect("a temporary folder");
        // Its file is there, unlocked: its process is gone.
        let dead = dir.path().join("wait-000000009999-1-dead");
        std::fs::File::create(&dead).expect("the dead waiter's file");
        let me = Waiting::enter(dir.path(), 5, "me").expect("in the queue");
        assert!(!me.behind_another(dir.path()).expect("the queue read"));
        assert!(!dead.exists(), "the dead waiter's file is removed");
        drop(me);
        let left: Vec<_> = std::fs::read_dir(dir.path())
            .expect("the folder read")
            .flatten()
            .map(|e| e.file_name())
            .collect();
        assert!(left.is_empty(), "a waiter leaves no file: {left:?}");
    }

    #[test]
    fn a_slot_folder_without_slot_files_is_refused_by_name() {
        let dir = tempfile::tempdir().expect("a temporary folder");
        let err = take_slot(dir.path(), 10, "a").expect_err("no slot to take");
        assert!(err.to_string().contains("slot-0"), "{err}");
    }
}
