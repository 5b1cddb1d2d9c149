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

use agp_planning::{
    EpisodeConfig, EstimateLog, EstimateVerdict, Evaluation, PoseSample, Task, distance_to_path,
};
use agp_runtime::{AgpIpc, Instance};
use agp_shared_types::{GroundTruth, ObjectEstimate};
use agp_world::Scenario;
use anyhow::{Result, anyhow, bail};
use glam::DVec2;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::Node;

/// Most poses a [`TruthLog`] keeps (32 bytes each: 512 kB at most). Past this, every
/// other kept pose is dropped and half as many are kept from then on, so a run of any
/// length keeps between half this and this many, spread over the whole run.
pub const MAX_KEPT_SAMPLES: usize = 16_384;

/// The object's true poses as an evaluation records them: the first one, then one every
/// `every` physics steps while the robot's body touches the object, and the last one.
///
/// What it keeps is bounded ([`MAX_KEPT_SAMPLES`]: the poses of the plot), what the verdict
/// needs is not lost: the final pose is kept whole, and the mean distance of every recorded
/// pose to the task's path is summed as the poses come ([`TruthLog::follow_path`]).
#[derive(Debug, Clone)]
pub struct TruthLog {
    every: u64,
    /// The poses kept since the last [`TruthLog::restart`]: one of every `stride` recorded.
    pub samples: Vec<PoseSample>,
    /// The latest ground truth received.
    pub last: Option<GroundTruth>,
    /// Steps whose ground truth never arrived (the subscriber's buffer overflowed).
    pub gaps: u64,
    stride: u64,
    recorded: u64,
    /// The last pose recorded, kept or not.
    last_recorded: Option<PoseSample>,
    /// The path whose distance to every recorded pose is summed, the sum, m, and how many
    /// poses it holds.
    path: Option<Vec<DVec2>>,
    distance_sum: f64,
    distance_count: u64,
}

impl TruthLog {
    /// An empty log recording one pose every `every` steps of contact.
    pub fn new(every: u64) -> Self {
        Self {
            every: every.max(1),
            samples: Vec::new(),
            last: None,
            gaps: 0,
            stride: 1,
            recorded: 0,
            last_recorded: None,
            path: None,
            distance_sum: 0.0,
            distance_count: 0,
        }
    }

    /// Forgets what was recorded; the latest pose becomes the first sample.
    pub fn restart(&mut self) {
        self.samples.clear();
        self.gaps = 0;
        self.stride = 1;
        self.recorded = 0;
        self.last_recorded = None;
        self.distance_sum = 0.0;
        self.distance_count = 0;
        if let Some(t) = self.last {
            self.push(&t);
        }
    }

    /// Sums the distance of every recorded pose to `path` from now on (`None`: no path).
    /// The poses recorded before are summed from what was kept of them (all of them, unless
    /// the path changed after [`MAX_KEPT_SAMPLES`] poses).
    pub fn follow_path(&mut self, path: Option<&[DVec2]>) {
        if self.path.as_deref() == path {
            return;
        }
        self.path = path.map(<[DVec2]>::to_vec);
        self.distance_sum = 0.0;
        self.distance_count = 0;
        if let Some(path) = &self.path {
            for s in &self.samples {
                self.distance_sum += distance_to_path(path, DVec2::new(s.pose.x, s.pose.y));
                self.distance_count += 1;
            }
        }
    }

    /// How many poses were recorded since the last restart (kept or not).
    pub fn recorded(&self) -> u64 {
        self.recorded
    }

    /// The mean distance of every recorded pose to the followed path, m: the paper's
    /// trajectory error (`None` without a path or a pose).
    pub fn mean_path_distance(&self) -> Option<f64> {
        (self.path.is_some() && self.distance_count > 0)
            .then(|| self.distance_sum / self.distance_count as f64)
    }

    fn push(&mut self, t: &GroundTruth) {
        let sample = PoseSample {
            t_s: t.sim_time_s,
            pose: t.object,
        };
        if let Some(path) = &self.path {
            self.distance_sum += distance_to_path(path, DVec2::new(t.object.x, t.object.y));
            self.distance_count += 1;
        }
        self.last_recorded = Some(sample);
        if self.recorded.is_multiple_of(self.stride) {
            self.samples.push(sample);
            if self.samples.len() > MAX_KEPT_SAMPLES {
                // Keep the poses recorded at multiples of twice the stride.
                let mut k = 0;
                self.samples.retain(|_| {
                    k += 1;
                    k % 2 == 1
                });
                self.stride *= 2;
            }
        }
        self.recorded += 1;
    }

    /// Takes one ground truth message.
    pub fn take(&mut self, t: &GroundTruth) {
        // A step count that went back is a new world (a reset keeps counting; a restarted
        // physics starts again): not a gap.
        if let Some(l) = &self.last
            && t.step > l.step + 1
        {
            self.gaps += t.step - l.step - 1;
        }
        if self.recorded == 0 || (t.contact != 0 && t.step.is_multiple_of(self.every)) {
            self.push(t);
        }
        self.last = Some(*t);
    }

    /// Records the final pose if it is newer than the last recorded one, and keeps it
    /// whatever the stride; the latest ground truth.
    pub fn finish(&mut self) -> Option<GroundTruth> {
        if let Some(t) = self.last
            && self.last_recorded.is_none_or(|s| s.t_s < t.sim_time_s)
        {
            let stride = self.stride;
            self.stride = 1;
            self.push(&t);
            self.stride = stride;
        } else if let Some(s) = self.last_recorded
            && self.samples.last() != Some(&s)
        {
            // Recorded but dropped by the stride: the plot still ends where the run did.
            self.samples.push(s);
        }
        self.last
    }
}

/// [`TruthLog`] fed from an instance's ground truth topic.
pub struct TruthRecorder {
    subscriber: Subscriber<AgpIpc, GroundTruth, ()>,
    log: TruthLog,
}

impl std::ops::Deref for TruthRecorder {
    type Target = TruthLog;

    fn deref(&self) -> &TruthLog {
        &self.log
    }
}

impl std::ops::DerefMut for TruthRecorder {
    fn deref_mut(&mut self) -> &mut TruthLog {
        &mut self.log
    }
}

impl TruthRecorder {
    /// Subscribes to `instance`'s ground truth on `node`.
    pub fn open(instance: &Instance, node: &Node<AgpIpc>, every: u64) -> Result<Self> {
        let subscriber = instance
            .ground_truth(node)
            .map_err(|e| anyhow!("cannot open the ground truth: {e:?}"))?
            .subscriber()
            .create()
            .map_err(|e| anyhow!("cannot subscribe to the ground truth: {e:?}"))?;
        Ok(Self {
            subscriber,
            log: TruthLog::new(every),
        })
    }

    /// Takes everything that arrived.
    pub fn drain(&mut self) -> Result<()> {
        loop {
            match self.subscriber.receive() {
                Ok(Some(t)) => self.log.take(&t),
                Ok(None) => return Ok(()),
                Err(e) => bail!("cannot receive the ground truth: {e:?}"),
            }
        }
    }

    /// Forgets what was recorded; the latest pose becomes the first sample.
    pub fn restart(&mut self) -> Result<()> {
        self.drain()?;
        self.log.restart();
        Ok(())
    }

    /// The last recorded pose, with the final one added if it is newer.
    pub fn finish(&mut self) -> Result<Option<GroundTruth>> {
        self.drain()?;
        Ok(self.log.finish())
    }
}

/// [`EstimateLog`] fed from an instance's estimates: every estimate the estimator
/// publishes during a task, for the `estimate` block of its verdict.
pub struct EstimateRecorder {
    subscriber: Subscriber<AgpIpc, ObjectEstimate, ()>,
    pub log: EstimateLog,
}

impl EstimateRecorder {
    /// Subscribes to `instance`'s estimates on `node`.
    pub fn open(instance: &Instance, node: &Node<AgpIpc>) -> Result<Self> {
        let subscriber = instance
            .estimates(node)
            .map_err(|e| anyhow!("cannot open the estimates: {e:?}"))?
            .subscriber()
            .create()
            .map_err(|e| anyhow!("cannot subscribe to the estimates: {e:?}"))?;
        Ok(Self {
            subscriber,
            log: EstimateLog::default(),
        })
    }

    /// Takes everything that arrived; into the log when `counting`, else drops it.
    pub fn drain(&mut self, counting: bool) {
        while let Ok(Some(e)) = self.subscriber.receive() {
            if counting {
                self.log.take(&e);
            }
        }
    }

    /// Drops what arrived and forgets what was logged: the task starts now.
    pub fn restart(&mut self) {
        self.drain(false);
        self.log = EstimateLog::default();
    }
}

/// How an `agp up` run ended, judged by ground truth.
pub struct RunVerdict {
    pub task: Task,
    /// Its `samples` are the poses kept for the plot, not every one recorded.
    pub evaluation: Evaluation,
    /// Steps whose ground truth the judge missed.
    pub gaps: u64,
    /// Poses recorded during the task.
    pub recorded: u64,
    /// Trajectory: the mean distance of every recorded pose to the path, m.
    pub mean_path_distance_m: Option<f64>,
    /// The estimator's estimates published during the task, judged against the final true
    /// pose.
    pub estimate: EstimateVerdict,
}

/// Watches a run's ground truth and task from a thread of its own.
pub struct RunJudge {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<Result<Option<RunVerdict>>>>,
    requests: std::sync::mpsc::Sender<JudgeNow>,
}

impl RunJudge {
    /// Starts watching `instance`, and returns once the judge listens (or failed to): a
    /// process started after this call cannot publish its task or ground truth before the
    /// judge has subscribed (a publisher hands its history only to the subscribers it
    /// knows of when it sends).
    pub fn spawn(instance: &Instance, scenario: Scenario) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let flag = Arc::clone(&stop);
        let instance = instance.clone();
        let (listening, listens) = std::sync::mpsc::channel();
        let (requests, requested) = std::sync::mpsc::channel();
        let thread = std::thread::Builder::new()
            .name("agp-judge".into())
            .spawn(move || watch(&instance, &scenario, &flag, &listening, &requested))
            .ok();
        if thread.is_some() {
            // An error or a panic of the judge drops the sender: no wait then either.
            let _ = listens.recv();
        }
        Self {
            stop,
            thread,
            requests,
        }
    }

    /// Judges the task under way now (a goal of a live session ended) and starts over with
    /// the next task published: `None` when no task was published since the last verdict.
    /// Waits up to `timeout` for the judge's thread.
    pub fn judge_now(&self, timeout: Duration) -> Result<Option<RunVerdict>> {
        let (reply, answer) = std::sync::mpsc::channel();
        self.requests
            .send(reply)
            .map_err(|_| anyhow!("the judge has stopped"))?;
        answer
            .recv_timeout(timeout)
            .map_err(|_| anyhow!("the judge did not answer within {timeout:?}"))?
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

/// A request to the judge's thread: judge the task under way now.
type JudgeNow = std::sync::mpsc::Sender<Result<Option<RunVerdict>>>;

fn watch(
    instance: &Instance,
    scenario: &Scenario,
    stop: &AtomicBool,
    listening: &std::sync::mpsc::Sender<()>,
    requests: &std::sync::mpsc::Receiver<JudgeNow>,
) -> Result<Option<RunVerdict>> {
    let node = instance
        .node("agp-judge", false)
        .map_err(|e| anyhow!("cannot create the judge's node: {e:?}"))?;
    let config = EpisodeConfig::for_task(&scenario.task);
    let mut truth = TruthRecorder::open(instance, &node, config.record_every_steps)?;
    let tasks = instance
        .task(&node)
        .map_err(|e| anyhow!("cannot open the task topic: {e:?}"))?
        .subscriber()
        .create()
        .map_err(|e| anyhow!("cannot subscribe to the task: {e:?}"))?;
    let mut estimates = EstimateRecorder::open(instance, &node)?;
    let _ = listening.send(());
    let mut task = None;
    let take_tasks = |task: &mut Option<Task>,
                      truth: &mut TruthRecorder,
                      estimates: &mut EstimateRecorder|
     -> Result<()> {
        while let Ok(Some(t)) = tasks.receive() {
            if task.is_none() {
                // Recording starts with the task: what came before (learning, the goal
                // judged before) is no part of it.
                truth.restart()?;
                estimates.restart();
            }
            *task = Task::from_message(&t);
            truth.follow_path(match task {
                Some(Task::Trajectory { path, .. }) => Some(path),
                _ => None,
            });
        }
        Ok(())
    };
    while !stop.load(Ordering::Relaxed) {
        truth.drain()?;
        estimates.drain(task.is_some());
        take_tasks(&mut task, &mut truth, &mut estimates)?;
        while let Ok(reply) = requests.try_recv() {
            // A goal of a live session ended: judge it now, and record the next one
            // from its own task on.
            let verdict = verdict(scenario, &config, task.take(), &mut truth, &mut estimates);
            let _ = reply.send(verdict);
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    take_tasks(&mut task, &mut truth, &mut estimates)?;
    verdict(scenario, &config, task, &mut truth, &mut estimates)
}

/// The verdict on `task` from what was recorded since it began.
fn verdict(
    scenario: &Scenario,
    config: &EpisodeConfig,
    task: Option<Task>,
    truth: &mut TruthRecorder,
    estimates: &mut EstimateRecorder,
) -> Result<Option<RunVerdict>> {
    let Some(task) = task else {
        return Ok(None);
    };
    estimates.drain(true);
    truth.follow_path(match &task {
        Task::Trajectory { path, .. } => Some(path),
        Task::Place { .. } => None,
    });
    let Some(last) = truth.finish()? else {
        return Ok(None);
    };
    let order = scenario.object.shape.symmetry_order();
    let evaluation = Evaluation::judge(
        &task,
        last.object,
        order,
        config,
        std::mem::take(&mut truth.samples),
    );
    Ok(Some(RunVerdict {
        task,
        evaluation,
        gaps: truth.gaps,
        recorded: truth.recorded(),
        mean_path_distance_m: truth.mean_path_distance(),
        estimate: estimates.log.judged(last.object, order),
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
        Task::Trajectory { .. } => (
            if e.success {
                "reached the path's end"
            } else {
                "did NOT reach the path's end"
            },
            format!(
                "mean distance to the path {:.2} mm over {} recorded positions; {:.1} mm from its end",
                verdict.mean_path_distance_m.unwrap_or(f64::NAN) * 1e3,
                verdict.recorded,
                e.position_error_mm
            ),
        ),
    };
    crate::say(format_args!(
        "agp: result (ground truth): `{}` {headline}: {detail}",
        scenario.name
    ));
    let trajectory_error_mm = match &verdict.task {
        Task::Trajectory { .. } => verdict.mean_path_distance_m.map(|v| v * 1e3),
        Task::Place { .. } => None,
    };
    let doc = serde_json::json!({
        "task": kind,
        "scenario": scenario.name,
        "success": e.success,
        "position_error_mm": e.position_error_mm,
        "orientation_error_deg": e.orientation_error_deg,
        "mean_error_mm": trajectory_error_mm,
        "recorded_positions": verdict.recorded,
        "ground_truth_gaps": verdict.gaps,
        "estimate": verdict.estimate,
    });
    std::fs::write(&json_path, format!("{doc:#}\n"))
        .map_err(|err| anyhow!("cannot write {}: {err}", json_path.display()))?;
    let overlay = match &verdict.task {
        Task::Place { goal } => crate::task_plot::Overlay::Goal(*goal),
        Task::Trajectory { path, .. } => crate::task_plot::Overlay::Path(path),
    };
    crate::task_plot::plot_runs(
        &plot_path,
        &format!(
            "`{}` {kind}, instance `{instance}`: the object every few steps",
            scenario.name
        ),
        &scenario.object.shape,
        &[crate::task_plot::Panel {
            title: format!("{headline}: {detail}"),
            samples: &e.samples,
        }],
        overlay,
    )?;
    Ok((json_path, plot_path))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trajectory_error;
    use agp_shared_types::Pose2;

    /// Ground truth of step `step`: the object sliding along x with a wobble in y, the
    /// robot touching it.
    fn truth(step: u64) -> GroundTruth {
        let t = step as f64 * 0.01;
        GroundTruth {
            step,
            sim_time_s: t,
            object: Pose2::new(0.001 * t, 0.02 * (0.37 * t).sin(), 0.1 * t.cos()),
            contact: 1,
            ..GroundTruth::default()
        }
    }

    #[test]
    fn the_judge_keeps_a_bounded_record_of_a_long_run_and_judges_it_as_the_full_record() {
        // Two million steps recorded every step: 64 MB of poses unbounded (the supervisor
        // grew about 100 kB/s on a long run).
        let steps = 2_000_000u64;
        let path = vec![DVec2::new(0.0, 0.0), DVec2::new(3.0, 0.0)];
        let config = EpisodeConfig::for_task(
            &Scenario::resolve("triangle")
                .expect("the built-in triangle")
                .task,
        );
        let mut log = TruthLog::new(1);
        let mut full = Vec::new();
        log.take(&truth(0));
        log.restart();
        log.follow_path(Some(&path));
        full.push(PoseSample {
            t_s: 0.0,
            pose: truth(0).object,
        });
        let mut most_kept = 0;
        for step in 1..steps {
            let t = truth(step);
            log.take(&t);
            full.push(PoseSample {
                t_s: t.sim_time_s,
                pose: t.object,
            });
            most_kept = most_kept.max(log.samples.len());
        }
        let last = log.finish().expect("ground truth arrived");
        assert!(
            most_kept <= MAX_KEPT_SAMPLES + 1 && log.samples.capacity() <= 2 * MAX_KEPT_SAMPLES + 2,
            "kept {most_kept} poses (capacity {})",
            log.samples.capacity()
        );
        assert!(
            log.samples.len() >= MAX_KEPT_SAMPLES / 2,
            "{}",
            log.samples.len()
        );
        assert_eq!(log.recorded(), full.len() as u64);
        assert_eq!(log.samples.first(), full.first());
        assert_eq!(log.samples.last(), full.last(), "the final pose is kept");

        let order = 1;
        for task in [
            Task::Place {
                goal: Pose2::new(2.0, 0.0, 0.3),
            },
            Task::Place { goal: last.object },
            Task::Trajectory {
                path: path.clone(),
                keep_heading_rad: None,
            },
        ] {
            let bounded = Evaluation::judge(&task, last.object, order, &config, Vec::new());
            let whole = Evaluation::judge(&task, last.object, order, &config, full.clone());
            assert_eq!(bounded.success, whole.success);
            assert_eq!(bounded.position_error_mm, whole.position_error_mm);
            assert_eq!(bounded.orientation_error_deg, whole.orientation_error_deg);
        }
        let poses: Vec<Pose2> = full.iter().map(|s| s.pose).collect();
        assert_eq!(
            log.mean_path_distance(),
            trajectory_error(&path, &poses),
            "the trajectory error of every recorded pose"
        );
    }
}
