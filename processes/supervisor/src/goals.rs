//! The goals of a live session: `agp goal` queues them through the control service, the
//! supervisor publishes the one to pursue on the latched `goal` topic, the serving planner
//! (`agp-planner --mode serve`) pursues it and says when it ended (`GoalDone`), and the
//! judge scores it by ground truth before the next one goes out. A planner that starts or
//! is swapped in takes the goal under way from the topic's history.
//!
//! Across a bridge the supervisor of the robot side (physics, the estimator and the judge)
//! owns the goals: the bridge carries its `goal` to the far instance, whose supervisor
//! takes its serving planner's `GoalDone` and relays it on `goal_ends`, which the bridge
//! carries back; this supervisor scores a relayed end as its own planner's.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::time::Duration;

use agp_harness::evaluation::{RunJudge, RunVerdict};
use agp_planning::Task as PlannerTask;
use agp_runtime::{AgpIpc, Instance, Topic};
use agp_shared_types::{
    ControlResponse, Goal, GoalEnd, GoalState, GoalStatus, MAX_STATUS_GOALS, Pose2, TaskKind,
    read_str, write_str,
};
use agp_world::TaskSpec;
use anyhow::{Result, anyhow};
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::Node;

use crate::console::Log;

/// How long the judge may take to score a goal.
const JUDGE_TIMEOUT: Duration = Duration::from_secs(10);

/// Goals kept for status replies and the session's JSON (the oldest are dropped past it).
const MAX_KEPT_GOALS: usize = 1024;

/// Where the goals of this instance's planner come from.
enum Source {
    /// This supervisor owns them: it publishes the one pursued and takes the ends, from its
    /// own planner's `GoalDone` or relayed from a far one on `goal_ends`.
    Own {
        publisher: Publisher<AgpIpc, Goal, ()>,
        _topic: Topic<Goal>,
        ends: Subscriber<AgpIpc, GoalEnd, ()>,
        _ends_topic: Topic<GoalEnd>,
    },
    /// The robot runs under another supervisor, which owns them (the bridge brings its
    /// `goal`): this one relays its planner's ends there on `goal_ends`.
    Relay {
        ends: Publisher<AgpIpc, GoalEnd, ()>,
        _topic: Topic<GoalEnd>,
    },
}

/// The session's goals: queued, pursued, done.
pub(crate) struct GoalBook {
    source: Source,
    /// Tolerances, push limit and seed of every goal: the session scenario's.
    spec: TaskSpec,
    queued: VecDeque<Goal>,
    /// Every goal's status, oldest first (at most [`MAX_KEPT_GOALS`]).
    statuses: VecDeque<GoalStatus>,
    /// The goal pursued.
    current: Option<u64>,
    next_id: u64,
}

impl GoalBook {
    /// Opens the goal topic (owned by the supervisor, so it outlives every planner) and
    /// publishes "no goal"; or, when `relay` (the robot runs under another supervisor), the
    /// `goal_ends` publisher only, leaving the goal topic to the bridge.
    pub(crate) fn open(
        instance: &Instance,
        node: &Node<AgpIpc>,
        spec: &TaskSpec,
        relay: bool,
    ) -> Result<Self> {
        let ends_topic = instance.goal_ends(node)?;
        let source = if relay {
            Source::Relay {
                ends: ends_topic
                    .data
                    .publisher_builder()
                    .create()
                    .map_err(|e| anyhow!("cannot create the goal-end publisher: {e:?}"))?,
                _topic: ends_topic,
            }
        } else {
            let topic = instance.goal(node)?;
            Source::Own {
                publisher: topic
                    .data
                    .publisher_builder()
                    .create()
                    .map_err(|e| anyhow!("cannot create the goal publisher: {e:?}"))?,
                _topic: topic,
                ends: ends_topic
                    .data
                    .subscriber_builder()
                    .create()
                    .map_err(|e| anyhow!("cannot subscribe to the goal ends: {e:?}"))?,
                _ends_topic: ends_topic,
            }
        };
        let book = Self {
            source,
            spec: spec.clone(),
            queued: VecDeque::new(),
            statuses: VecDeque::new(),
            current: None,
            next_id: 1,
        };
        book.publish(&Goal::default())?;
        Ok(book)
    }

    fn publish(&self, goal: &Goal) -> Result<()> {
        let Source::Own { publisher, .. } = &self.source else {
            return Ok(());
        };
        let sample = publisher
            .loan_uninit()
            .map_err(|e| anyhow!("cannot loan a goal sample: {e:?}"))?;
        sample
            .write_payload(*goal)
            .send()
            .map_err(|e| anyhow!("cannot publish the goal: {e:?}"))?;
        Ok(())
    }

    /// Hands the goal under way to planners that subscribed since it was published (a
    /// publisher gives its history to a new subscriber only when it sends or updates its
    /// connections): a planner swapped in or restarted takes the goal on from there.
    pub(crate) fn update_connections(&self) {
        if let Source::Own { publisher, .. } = &self.source {
            let _ = publisher.update_connections();
        }
    }

    /// Scores the goals a far planner ended, relayed through the bridge on `goal_ends`, as
    /// [`GoalBook::done`] scores this instance's own planner's.
    pub(crate) fn take_relayed(&mut self, judge: &RunJudge, log: &Log) {
        loop {
            let end = match &self.source {
                Source::Own { ends, .. } => match ends.receive() {
                    Ok(Some(e)) => *e,
                    Ok(None) => return,
                    Err(e) => {
                        log.note(format_args!("cannot receive a relayed goal end: {e:?}"));
                        return;
                    }
                },
                Source::Relay { .. } => return,
            };
            let how = read_str(&end.end);
            let sim_time_s = end.sim_time_ns as f64 * 1e-9;
            if let Err(why) = self.done(end.id, &how, sim_time_s, judge, log) {
                log.note(format_args!(
                    "the far planner's end of goal {} was not taken: {why}",
                    end.id
                ));
            }
        }
    }

    /// Queues `goal` (checked already); returns its id. It goes out at once when no goal is
    /// pursued.
    pub(crate) fn queue(&mut self, mut goal: Goal, log: &Log) -> Result<u64, String> {
        if matches!(self.source, Source::Relay { .. }) {
            return Err(
                "the robot of this instance runs under another supervisor, which owns \
                 the session's goals and judges them: queue them with `agp goal --instance` \
                 naming that supervisor's instance"
                    .to_owned(),
            );
        }
        let id = self.next_id;
        self.next_id += 1;
        goal.id = id;
        goal.task.tolerance_m = self.spec.tolerance_m;
        goal.task.tolerance_rad = self.spec.tolerance_rad;
        goal.task.max_pushes = self.spec.max_pushes;
        goal.task.seed = self.spec.seed;
        let t = &goal.task;
        let mut status = GoalStatus {
            id,
            state: GoalState::Queued as u32,
            kind: t.kind,
            path_len: t.path_len,
            ..GoalStatus::default()
        };
        status.target = if t.kind == TaskKind::Trajectory as u32 {
            let end = t.path[(t.path_len as usize).saturating_sub(1)];
            Pose2::new(end[0], end[1], 0.0)
        } else {
            t.goal
        };
        if self.statuses.len() >= MAX_KEPT_GOALS {
            self.statuses.pop_front();
        }
        self.statuses.push_back(status);
        log.note(format_args!(
            "goal {id} queued: {}",
            GoalReport::new(&status).what()
        ));
        self.queued.push_back(goal);
        if self.current.is_none() {
            self.next(log).map_err(|e| format!("{e:#}"))?;
        }
        Ok(id)
    }

    /// Sends out the next queued goal, or "no goal".
    fn next(&mut self, log: &Log) -> Result<()> {
        match self.queued.pop_front() {
            Some(goal) => {
                self.current = Some(goal.id);
                if let Some(s) = self.status_mut(goal.id) {
                    s.state = GoalState::Pursued as u32;
                }
                log.note(format_args!("goal {} sent to the planner", goal.id));
                self.publish(&goal)
            }
            None => {
                self.current = None;
                self.publish(&Goal::default())
            }
        }
    }

    fn status_mut(&mut self, id: u64) -> Option<&mut GoalStatus> {
        self.statuses.iter_mut().rev().find(|s| s.id == id)
    }

    /// The serving planner ended goal `id` as `end` says, after `sim_time_s` simulated
    /// seconds: the judge scores it, the next goal goes out.
    pub(crate) fn done(
        &mut self,
        id: u64,
        end: &str,
        sim_time_s: f64,
        judge: &RunJudge,
        log: &Log,
    ) -> Result<(), String> {
        if let Source::Relay { ends, .. } = &self.source {
            let mut relayed = GoalEnd {
                id,
                sim_time_ns: (sim_time_s.max(0.0) * 1e9) as u64,
                ..GoalEnd::default()
            };
            write_str(&mut relayed.end, end);
            ends.send_copy(relayed)
                .map_err(|e| format!("cannot relay the end of goal {id}: {e:?}"))?;
            log.note(format_args!(
                "goal {id} ended `{end}`: relayed to the robot side's supervisor, which judges it"
            ));
            return Ok(());
        }
        if self.current != Some(id) {
            return Err(match self.current {
                Some(c) => format!("goal {id} is not the one pursued (goal {c} is)"),
                None => format!("goal {id} is not the one pursued (none is)"),
            });
        }
        let verdict = judge.judge_now(JUDGE_TIMEOUT);
        let line = {
            let status = self
                .status_mut(id)
                .ok_or_else(|| format!("goal {id} is unknown"))?;
            status.state = GoalState::Done as u32;
            status.sim_time_s = sim_time_s;
            write_str(&mut status.end, end);
            match &verdict {
                Ok(Some(v)) => {
                    fill_verdict(status, v);
                    format!(
                        "goal {id} {}: {}",
                        if v.evaluation.success {
                            "reached"
                        } else {
                            "NOT reached"
                        },
                        describe_result(status)
                    )
                }
                Ok(None) => format!("goal {id} ended `{end}` but the judge saw no task for it"),
                Err(e) => format!("goal {id} ended `{end}` but could not be judged: {e:#}"),
            }
        };
        log.note(format_args!("{line}"));
        self.next(log).map_err(|e| format!("{e:#}"))
    }

    /// The latest goals into a status reply.
    pub(crate) fn fill(&self, out: &mut ControlResponse) {
        out.goals_total = u32::try_from(self.next_id - 1).unwrap_or(u32::MAX);
        let skip = self.statuses.len().saturating_sub(MAX_STATUS_GOALS);
        let mut n = 0;
        for (s, slot) in self.statuses.iter().skip(skip).zip(out.goals.iter_mut()) {
            *slot = *s;
            n += 1;
        }
        out.goal_count = n;
    }

    /// Whether the session has had any goal.
    pub(crate) fn any(&self) -> bool {
        !self.statuses.is_empty()
    }

    /// Writes every goal kept, as `agp status --json` lists them, to
    /// `<results>/<instance>-goals.json`; returns the path.
    pub(crate) fn write_json(&self, results: &Path, instance: &str) -> Result<PathBuf> {
        let path = results.join(format!("{instance}-goals.json"));
        let goals: Vec<GoalReport> = self.statuses.iter().map(GoalReport::new).collect();
        let doc = serde_json::json!({ "instance": instance, "goals": goals });
        std::fs::write(&path, format!("{doc:#}\n"))
            .map_err(|e| anyhow!("cannot write {}: {e}", path.display()))?;
        Ok(path)
    }
}

fn fill_verdict(status: &mut GoalStatus, v: &RunVerdict) {
    let e = &v.evaluation;
    status.success = u32::from(e.success);
    status.position_error_mm = e.position_error_mm;
    match v.task {
        PlannerTask::Place { .. } => status.orientation_error_deg = e.orientation_error_deg,
        PlannerTask::Trajectory { .. } => {
            status.mean_path_error_mm = v.mean_path_distance_m.map_or(f64::NAN, |m| m * 1e3);
        }
    }
    status.estimate_position_error_mm = v.estimate.final_position_error_mm.unwrap_or(f64::NAN);
    status.estimate_orientation_error_deg =
        v.estimate.final_orientation_error_deg.unwrap_or(f64::NAN);
}

fn describe_result(s: &GoalStatus) -> String {
    if s.kind == TaskKind::Trajectory as u32 {
        format!(
            "{:.1} mm from the path's end, {:.2} mm from the path on average ({}, {:.1} s simulated)",
            s.position_error_mm,
            s.mean_path_error_mm,
            read_str(&s.end),
            s.sim_time_s
        )
    } else {
        format!(
            "final error {:.1} mm, {:.1} deg ({}, {:.1} s simulated)",
            s.position_error_mm,
            s.orientation_error_deg,
            read_str(&s.end),
            s.sim_time_s
        )
    }
}

/// One goal of `agp status --json` and of the session's JSON.
#[derive(Debug, serde::Serialize)]
pub struct GoalReport {
    pub id: u64,
    /// `queued`, `pursued` or `done`.
    pub state: &'static str,
    /// `place` or `trajectory`.
    pub task: &'static str,
    /// Place: the goal pose; trajectory: the path's end.
    pub x_mm: f64,
    pub y_mm: f64,
    pub theta_deg: Option<f64>,
    pub path_points: Option<u32>,
    /// The judge's verdict (`null` until done).
    pub success: Option<bool>,
    pub position_error_mm: Option<f64>,
    pub orientation_error_deg: Option<f64>,
    pub mean_path_error_mm: Option<f64>,
    /// The last estimate against the final true pose.
    pub estimate_position_error_mm: Option<f64>,
    pub estimate_orientation_error_deg: Option<f64>,
    /// How the planner said it ended.
    pub end: Option<String>,
    pub sim_time_s: Option<f64>,
}

impl GoalReport {
    pub fn new(s: &GoalStatus) -> Self {
        let state = GoalState::from_u32(s.state).unwrap_or(GoalState::Queued);
        let done = state == GoalState::Done;
        let num = |v: f64| (done && v.is_finite()).then_some(v);
        let trajectory = s.kind == TaskKind::Trajectory as u32;
        Self {
            id: s.id,
            state: state.as_str(),
            task: if trajectory { "trajectory" } else { "place" },
            x_mm: s.target.x * 1e3,
            y_mm: s.target.y * 1e3,
            theta_deg: (!trajectory).then(|| s.target.theta.to_degrees()),
            path_points: trajectory.then_some(s.path_len),
            success: done.then_some(s.success == 1),
            position_error_mm: num(s.position_error_mm),
            orientation_error_deg: num(s.orientation_error_deg),
            mean_path_error_mm: num(s.mean_path_error_mm),
            estimate_position_error_mm: num(s.estimate_position_error_mm),
            estimate_orientation_error_deg: num(s.estimate_orientation_error_deg),
            end: done.then(|| read_str(&s.end)),
            sim_time_s: num(s.sim_time_s),
        }
    }

    /// What the goal asks, in words.
    pub fn what(&self) -> String {
        match self.path_points {
            Some(n) => format!(
                "push along a {n}-point path to ({:.0}, {:.0}) mm",
                self.x_mm, self.y_mm
            ),
            None => format!(
                "place at ({:.0}, {:.0}) mm, {:.0} deg",
                self.x_mm,
                self.y_mm,
                self.theta_deg.unwrap_or(0.0)
            ),
        }
    }

    /// One line for `agp status`.
    pub fn line(&self) -> String {
        let what = self.what();
        let result = match (self.success, self.path_points) {
            (None, _) => String::new(),
            (Some(ok), None) => format!(
                ": {}, {:.1} mm, {:.1} deg ({})",
                if ok { "reached" } else { "NOT reached" },
                self.position_error_mm.unwrap_or(f64::NAN),
                self.orientation_error_deg.unwrap_or(f64::NAN),
                self.end.as_deref().unwrap_or("")
            ),
            (Some(ok), Some(_)) => format!(
                ": {}, {:.1} mm from its end, {:.2} mm from the path on average ({})",
                if ok { "reached" } else { "NOT reached" },
                self.position_error_mm.unwrap_or(f64::NAN),
                self.mean_path_error_mm.unwrap_or(f64::NAN),
                self.end.as_deref().unwrap_or("")
            ),
        };
        format!("goal {} {:<7} {what}{result}", self.id, self.state)
    }
}
