//! Benchmark episodes over the real pipeline: a private instance (`bench-<pid>-<tag>`) with
//! lockstep `agp-physics`, `agp-estimator` serving an AG file's gradients over the `grids`
//! topic, and one `agp-planner` process per episode. The benchmark plays the experimenter
//! and the judge: it puts the object and the robot back at the scenario's start before each
//! episode (a reset, as the learning protocol does) and reads ground truth, which no
//! planner but the oracle sees. Every file of the instance is removed at the end.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
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
}

impl PipelineBench {
    /// Starts physics (seeded with `seed`) and the estimator, serving `ag`'s gradients if
    /// given, under the instance `bench-<pid>-<tag>` (`tag`: lowercase letters, digits,
    /// `-`, `_`; one per pipeline running at once).
    pub fn start(scenario_arg: &str, ag: Option<&Path>, seed: u64, tag: &str) -> Result<Self> {
        Self::launch(scenario_arg, ag, false, seed, tag)
    }

    /// As [`PipelineBench::start`], for an object never pushed before: no AG file; each
    /// episode starts with a fresh estimator that builds its gradient from the contact
    /// prior of the episode's first circling and learns on from the episode's pushes
    /// (issue 33), and the affordance planner plans on what it publishes.
    pub fn start_online(scenario_arg: &str, seed: u64, tag: &str) -> Result<Self> {
        Self::launch(scenario_arg, None, true, seed, tag)
    }

    /// The estimator of this pipeline: serving `ag`, learning online from the prior, or
    /// perceiving only.
    fn spawn_estimator(
        name: &str,
        scenario_arg: &str,
        ag: Option<&Path>,
        online: bool,
    ) -> Result<GuardedChild> {
        let mut cmd = Command::new(sibling_executable("agp-estimator")?);
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
    ) -> Result<Self> {
        let scenario = Scenario::resolve(scenario_arg)?;
        let name = format!("bench-{}-{tag}", std::process::id());
        let instance = Instance::new(&name).map_err(|e| anyhow!("instance `{name}`: {e}"))?;
        // A bench of the same pid that died hard may have left files: they are ours.
        instance
            .remove_files()
            .context("cannot clear the bench's instance files")?;
        let logs = tempfile::tempdir().context("cannot create a folder for the episode logs")?;
        let mut cmd = Command::new(sibling_executable("agp-physics")?);
        cmd.args(["--instance", &name, "--scenario", scenario_arg])
            .args(["--clock", "lockstep", "--idle-timeout-s", "0"])
            .args(["--seed", &seed.to_string()])
            .stdin(Stdio::null())
            .stdout(Stdio::null());
        let physics = GuardedChild::spawn("agp-physics", &mut cmd)?;
        // The estimator perceives for every planner; with `ag` it also serves its gradients.
        let estimator = Some(Self::spawn_estimator(&name, scenario_arg, ag, online)?);
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
