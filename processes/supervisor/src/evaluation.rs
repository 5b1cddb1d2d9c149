//! The judge: what the supervisor reads of ground truth to evaluate a task, and nobody
//! else in the pipeline but the oracle does. [`TruthRecorder`] keeps the object's true
//! poses while the robot pushes it (the benchmarks' recorded positions); [`RunJudge`]
//! watches an `agp up` run in a thread of its own and, at its end, judges the object's
//! final pose against the task the planner published, and draws it.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use agp_planner::{EpisodeConfig, Evaluation, PoseSample, Task};
use agp_shared_types::{AgpIpc, GroundTruth, Instance, Pose2, TaskKind};
use agp_world::Scenario;
use anyhow::{Result, anyhow, bail};
use glam::DVec2;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::Node;

/// The object's true poses as an evaluation records them: the first one, then one every
/// `every` physics steps while the robot's body touches the object.
pub struct TruthRecorder {
    subscriber: Subscriber<AgpIpc, GroundTruth, ()>,
    every: u64,
    /// What was recorded since the last [`TruthRecorder::restart`].
    pub samples: Vec<PoseSample>,
    /// The latest ground truth received.
    pub last: Option<GroundTruth>,
    /// Steps whose ground truth never arrived (the subscriber's buffer overflowed).
    pub gaps: u64,
}

impl TruthRecorder {
    /// Subscribes to `instance`'s ground truth on `node`.
    pub fn open(instance: &Instance, node: &Node<AgpIpc>, every: u64) -> Result<Self> {
        let subscriber = instance
            .ground_truth(node)
            .map_err(|e| anyhow!("cannot open the ground truth: {e:?}"))?
            .data
            .subscriber_builder()
            .create()
            .map_err(|e| anyhow!("cannot subscribe to the ground truth: {e:?}"))?;
        Ok(Self {
            subscriber,
            every: every.max(1),
            samples: Vec::new(),
            last: None,
            gaps: 0,
        })
    }

    /// Takes everything that arrived.
    pub fn drain(&mut self) -> Result<()> {
        loop {
            match self.subscriber.receive() {
                Ok(Some(t)) => self.take(&t),
                Ok(None) => return Ok(()),
                Err(e) => bail!("cannot receive the ground truth: {e:?}"),
            }
        }
    }

    /// Forgets what was recorded; the latest pose becomes the first sample.
    pub fn restart(&mut self) -> Result<()> {
        self.drain()?;
        self.samples.clear();
        self.gaps = 0;
        if let Some(t) = self.last {
            self.push(&t);
        }
        Ok(())
    }

    fn push(&mut self, t: &GroundTruth) {
        self.samples.push(PoseSample {
            t_s: t.sim_time_s,
            pose: t.object,
        });
    }

    fn take(&mut self, t: &GroundTruth) {
        // A step count that went back is a new world (a reset keeps counting; a restarted
        // physics starts again): not a gap.
        if let Some(l) = &self.last
            && t.step > l.step + 1
        {
            self.gaps += t.step - l.step - 1;
        }
        if self.samples.is_empty() || (t.contact != 0 && t.step.is_multiple_of(self.every)) {
            self.push(t);
        }
        self.last = Some(*t);
    }

    /// The last recorded pose, with the final one added if it is newer.
    pub fn finish(&mut self) -> Result<Option<GroundTruth>> {
        self.drain()?;
        if let Some(t) = self.last
            && self.samples.last().is_none_or(|s| s.t_s < t.sim_time_s)
        {
            self.push(&t);
        }
        Ok(self.last)
    }
}

/// The task as the planner published it, in the planner library's terms.
pub fn task_of(msg: &agp_shared_types::Task) -> Option<Task> {
    match msg.kind {
        k if k == TaskKind::Place as u32 => Some(Task::Place { goal: msg.goal }),
        k if k == TaskKind::Trajectory as u32 => {
            let n = (msg.path_len as usize).min(msg.path.len());
            Some(Task::Trajectory {
                path: msg.path[..n]
                    .iter()
                    .map(|p| DVec2::from_array(*p))
                    .collect(),
            })
        }
        _ => None,
    }
}

/// How an `agp up` run ended, judged by ground truth.
pub struct RunVerdict {
    pub task: Task,
    pub evaluation: Evaluation,
    /// Steps whose ground truth the judge missed.
    pub gaps: u64,
}

/// Watches a run's ground truth and task from a thread of its own.
pub struct RunJudge {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<Result<Option<RunVerdict>>>>,
}

impl RunJudge {
    /// Starts watching `instance` (its processes may not run yet).
    pub fn spawn(instance: &Instance, scenario: Scenario) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let flag = Arc::clone(&stop);
        let instance = instance.clone();
        let thread = std::thread::Builder::new()
            .name("agp-judge".into())
            .spawn(move || watch(&instance, &scenario, &flag))
            .ok();
        Self { stop, thread }
    }

    /// Stops watching and judges what the run left: `None` when no task was published
    /// (the scripted drive, the learning phase).
    pub fn finish(mut self) -> Result<Option<RunVerdict>> {
        self.stop.store(true, Ordering::Relaxed);
        match self.thread.take() {
            Some(t) => t
                .join()
                .map_err(|_| anyhow!("the judge's thread panicked"))?,
            None => bail!("cannot start the judge's thread"),
        }
    }
}

impl Drop for RunJudge {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn watch(
    instance: &Instance,
    scenario: &Scenario,
    stop: &AtomicBool,
) -> Result<Option<RunVerdict>> {
    let node = instance
        .node("agp-judge", false)
        .map_err(|e| anyhow!("cannot create the judge's node: {e:?}"))?;
    let config = EpisodeConfig::for_scenario(scenario);
    let mut truth = TruthRecorder::open(instance, &node, config.record_every_steps)?;
    let tasks = instance
        .task(&node)
        .map_err(|e| anyhow!("cannot open the task topic: {e:?}"))?
        .data
        .subscriber_builder()
        .create()
        .map_err(|e| anyhow!("cannot subscribe to the task: {e:?}"))?;
    let mut task = None;
    while !stop.load(Ordering::Relaxed) {
        truth.drain()?;
        while let Ok(Some(t)) = tasks.receive() {
            if task.is_none() {
                // Recording starts with the task: what came before (learning) is no part
                // of it.
                truth.restart()?;
            }
            task = task_of(&t);
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    while let Ok(Some(t)) = tasks.receive() {
        task = task_of(&t);
    }
    let Some(task) = task else {
        return Ok(None);
    };
    let Some(last) = truth.finish()? else {
        return Ok(None);
    };
    let evaluation = Evaluation::judge(
        &task,
        last.object,
        scenario.object.shape.symmetry_order(),
        &config,
        std::mem::take(&mut truth.samples),
    );
    Ok(Some(RunVerdict {
        task,
        evaluation,
        gaps: truth.gaps,
    }))
}

/// Prints the verdict and writes its JSON and plot in `results`; the plot's path.
pub fn report(
    verdict: &RunVerdict,
    scenario: &Scenario,
    instance: &str,
    results: &Path,
) -> Result<(PathBuf, PathBuf)> {
    let e = &verdict.evaluation;
    let kind = match verdict.task {
        Task::Place { .. } => "place",
        Task::Trajectory { .. } => "trajectory",
    };
    let stem = format!("{instance}-{kind}");
    let json_path = results.join(format!("{stem}.json"));
    let plot_path = results.join(format!("{stem}.svg"));
    let poses: Vec<Pose2> = e.samples.iter().map(|s| s.pose).collect();
    let (headline, detail) = match &verdict.task {
        Task::Place { goal } => (
            if e.success { "placed" } else { "NOT placed" },
            format!(
                "goal ({:.0}, {:.0}) mm, {:.0} deg; final error {:.1} mm, {:.1} deg (tolerance {:.0} mm, {:.0} deg)",
                goal.x * 1e3,
                goal.y * 1e3,
                goal.theta.to_degrees(),
                e.position_error_mm,
                e.orientation_error_deg,
                scenario.task.tolerance_m * 1e3,
                scenario.task.tolerance_rad.to_degrees()
            ),
        ),
        Task::Trajectory { path } => (
            if e.success {
                "reached the path's end"
            } else {
                "did NOT reach the path's end"
            },
            format!(
                "mean distance to the path {:.2} mm over {} recorded positions; {:.1} mm from its end",
                agp_planner::trajectory_error(path, &poses).unwrap_or(f64::NAN) * 1e3,
                poses.len(),
                e.position_error_mm
            ),
        ),
    };
    println!(
        "agp: result (ground truth): `{}` {headline}: {detail}",
        scenario.name
    );
    let trajectory_error_mm = match &verdict.task {
        Task::Trajectory { path } => agp_planner::trajectory_error(path, &poses).map(|v| v * 1e3),
        Task::Place { .. } => None,
    };
    let doc = serde_json::json!({
        "task": kind,
        "scenario": scenario.name,
        "success": e.success,
        "position_error_mm": e.position_error_mm,
        "orientation_error_deg": e.orientation_error_deg,
        "mean_error_mm": trajectory_error_mm,
        "recorded_positions": e.samples.len(),
        "ground_truth_gaps": verdict.gaps,
    });
    std::fs::write(&json_path, format!("{doc:#}\n"))
        .map_err(|err| anyhow!("cannot write {}: {err}", json_path.display()))?;
    let overlay = match &verdict.task {
        Task::Place { goal } => crate::bench_tasks::Overlay::Goal(*goal),
        Task::Trajectory { path } => crate::bench_tasks::Overlay::Path(path),
    };
    crate::bench_tasks::plot_runs(
        &plot_path,
        &format!(
            "`{}` {kind}, instance `{instance}`: the object every few steps",
            scenario.name
        ),
        &scenario.object.shape,
        &[crate::bench_tasks::Panel {
            title: format!("{headline}: {detail}"),
            samples: &e.samples,
        }],
        overlay,
    )?;
    Ok((json_path, plot_path))
}
