//! The learner's side of the learning protocol: the planner's [`LearnEvent`]s turned into
//! [`LearningSession`] calls and the [`LearnReport`]s that answer them.
//!
//! The estimator process feeds it every IR frame ([`ProtocolLearner::observe`]) and every
//! learning event ([`ProtocolLearner::handle`]) in the order the planner made them (events
//! about a frame after that frame, before the next); the in-process learning bench does
//! the same, so both learn the same gradients from the same protocol
//! (`agp_planning::LearnProtocol`). The `Task*` kinds are not learning: they are the
//! [`crate::ObjectTracker`]'s, and ignored here.

use agp_affordance::AffordanceGradient;
use agp_shared_types::{LearnEvent, LearnEventKind, LearnReport, LearnReportKind};
use agp_world::RobotDescription;

use crate::{
    IrView, LearningConfig, LearningSession, SessionBuildError, ShapeLearnError, TrialLearnError,
    TrialOrderError, TrialPhase, TrialRecord, TrialStartError,
};

/// Something that went wrong with a learning event. None stops the learning: the report
/// that answers the event (if any) says how it ended; a caller prints these or, like a
/// bench that must not go on quietly, treats some as fatal.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LearnProblem {
    /// Events of another run of the protocol arrived (its planner restarted): everything
    /// learned from the previous run was dropped and learning started over.
    #[error(
        "a new learning session from the planner: the {dropped} trial(s) of the previous one are dropped and learning starts over"
    )]
    SessionRestarted {
        /// Trials learned or rejected in the dropped run.
        dropped: u32,
    },
    /// The shape circling gave no shape (reported `ShapeFailed`).
    #[error("the shape circling of `{object}` gave no shape: {source}")]
    Shape {
        /// The object learned.
        object: String,
        /// Why.
        source: ShapeLearnError,
    },
    /// A trial could not start (reported `TrialRejected`).
    #[error("trial {index} cannot start: {source}")]
    TrialStart {
        /// The trial's index.
        index: u32,
        /// Why.
        source: TrialStartError,
    },
    /// Contact or the push's end came in a phase that does not take it.
    #[error("trial {index}: {source}")]
    Order {
        /// The trial's index.
        index: u32,
        /// The call refused.
        source: TrialOrderError,
    },
    /// The trial taught nothing (reported `TrialRejected`): no match, a poor match.
    #[error("trial {index} rejected: {source}")]
    TrialRejected {
        /// The trial's index.
        index: u32,
        /// Why.
        source: TrialLearnError,
    },
}

/// What [`ProtocolLearner::handle`] made of one event.
#[derive(Debug, Clone, Default)]
pub struct LearnReply {
    /// The report answering the event, to send to the planner: `ShapeLearned` (its `value`
    /// the border points, `border_radius_m` the learned border's radius) or `ShapeFailed`
    /// at `ShapeEnd`; `TrialLearned` or `TrialRejected` once per trial.
    pub report: Option<LearnReport>,
    /// What went wrong, if anything.
    pub problem: Option<LearnProblem>,
    /// The trial learned at `TrialEnd`: the estimates behind its report.
    pub record: Option<TrialRecord>,
    /// The event was `LearningDone`: the gradient is ready ([`ProtocolLearner::take_gradient`]).
    pub finished: bool,
}

/// The learner of the protocol: a [`LearningSession`] driven by the planner's events.
/// Starts over (a fresh session) when events of another protocol run arrive; ignores
/// everything after `LearningDone`.
pub struct ProtocolLearner {
    object_name: String,
    robot: RobotDescription,
    config: LearningConfig,
    session: Option<LearningSession>,
    /// The protocol run the session learns ([`LearnEvent::session`]; 0: no event yet).
    learn_session: u64,
    trials_total: u32,
    /// `LearningDone` came.
    finished: bool,
    /// Trials learned and rejected when the session was taken.
    final_counts: (u32, u32),
}

impl ProtocolLearner {
    /// A learner of `object_name`, seen by `robot`. Allocates the session's buffers.
    pub fn new(
        object_name: &str,
        robot: &RobotDescription,
        config: LearningConfig,
    ) -> Result<Self, SessionBuildError> {
        Ok(Self {
            session: Some(LearningSession::new(object_name, robot, config.clone())?),
            object_name: object_name.to_owned(),
            robot: robot.clone(),
            config,
            learn_session: 0,
            trials_total: 0,
            finished: false,
            final_counts: (0, 0),
        })
    }

    /// The session: the shape, the matcher and the gradients learned so far. `None` once
    /// the gradient was taken.
    pub fn session(&self) -> Option<&LearningSession> {
        self.session.as_ref()
    }

    /// The protocol run learned ([`LearnEvent::session`]), 0 before its first event.
    pub fn learn_session(&self) -> u64 {
        self.learn_session
    }

    /// Whether it still learns: `LearningDone` has not come.
    pub fn is_learning(&self) -> bool {
        !self.finished
    }

    /// Whether `LearningDone` came.
    pub fn finished(&self) -> bool {
        self.finished
    }

    /// Trials of the whole protocol, as the planner announced them.
    pub fn trials_total(&self) -> u32 {
        self.trials_total
    }

    /// Trials learned and rejected so far (at the end, in all).
    pub fn counts(&self) -> (u32, u32) {
        self.session.as_ref().map_or(self.final_counts, |s| {
            (s.trials_learned() as u32, s.trials_rejected() as u32)
        })
    }

    /// The gradients learned, once `LearningDone` came (once: the session ends). The
    /// counts stay.
    pub fn take_gradient(&mut self) -> Option<AffordanceGradient> {
        if !self.finished {
            return None;
        }
        let s = self.session.take()?;
        self.final_counts = (s.trials_learned() as u32, s.trials_rejected() as u32);
        Some(s.into_gradient())
    }

    /// The gradients learned, ending the learner (`None` before `LearningDone` or when
    /// already taken).
    pub fn into_gradient(mut self) -> Option<AffordanceGradient> {
        self.take_gradient()
    }

    /// The `Learned` report of a finished learning: counts, the grids' sequence number and
    /// whether the gradients were saved.
    pub fn learned_report(&self, grids_seq: u64, saved: bool) -> LearnReport {
        let (learned, rejected) = self.counts();
        LearnReport {
            kind: LearnReportKind::Learned as u32,
            trials_learned: learned,
            trials_rejected: rejected,
            trials_total: self.trials_total,
            valid: u32::from(saved),
            grids_seq,
            ..LearnReport::default()
        }
    }

    /// Takes one IR frame (allocates nothing).
    pub fn observe(&mut self, view: &IrView) {
        if !self.finished
            && let Some(s) = &mut self.session
        {
            s.observe(view);
        }
    }

    /// A trial report of `kind` for `event`, with the counts so far.
    fn trial_report(&self, kind: LearnReportKind, event: &LearnEvent) -> LearnReport {
        let (learned, rejected) = self.counts();
        LearnReport {
            kind: kind as u32,
            index: event.index,
            trials_learned: learned,
            trials_rejected: rejected,
            trials_total: self.trials_total,
            step: event.step,
            alpha_deg: event.alpha_deg,
            ..LearnReport::default()
        }
    }

    /// Takes one event of the learning protocol (about the frame it carries, observed
    /// before). Other kinds, and every event after `LearningDone`, are ignored. Fails only
    /// when a session started over cannot be built.
    pub fn handle(&mut self, event: &LearnEvent) -> Result<LearnReply, SessionBuildError> {
        let mut reply = LearnReply::default();
        let Some(kind) = LearnEventKind::from_u32(event.kind) else {
            return Ok(reply);
        };
        if self.finished || kind as u32 > LearnEventKind::LearningDone as u32 {
            return Ok(reply);
        }
        if event.session != self.learn_session {
            if self.learn_session != 0 {
                // Another run of the protocol: its planner restarted. Everything learned
                // from the previous one (a half-done trial included) goes, so no trial is
                // counted twice.
                let (learned, rejected) = self.counts();
                reply.problem = Some(LearnProblem::SessionRestarted {
                    dropped: learned + rejected,
                });
                self.session = Some(LearningSession::new(
                    &self.object_name,
                    &self.robot,
                    self.config.clone(),
                )?);
                self.trials_total = 0;
            }
            self.learn_session = event.session;
        }
        self.trials_total = self.trials_total.max(event.total);
        let Some(session) = &mut self.session else {
            return Ok(reply);
        };
        let v = IrView::new(event.ir_sample, event.ir_raw, event.odometry);
        let object = event.object;
        match kind {
            LearnEventKind::ShapeBegin => {
                session.begin_shape_circling(object);
                session.observe(&v);
            }
            LearnEventKind::ShapeEnd => {
                let r = session.finish_shape_circling();
                let border = session.border_radius_m();
                let mut report = self.trial_report(LearnReportKind::ShapeLearned, event);
                match r {
                    Ok(points) => {
                        report.value = points as f64;
                        report.border_radius_m = border.unwrap_or(0.0);
                    }
                    Err(source) => {
                        report.kind = LearnReportKind::ShapeFailed as u32;
                        if let ShapeLearnError::TooLarge { reach_m, .. } = source {
                            report.border_radius_m = reach_m;
                        }
                        reply.problem = Some(LearnProblem::Shape {
                            object: self.object_name.clone(),
                            source,
                        });
                    }
                }
                reply.report = Some(report);
            }
            LearnEventKind::TrialBegin => {
                if let Err(source) = session.begin_trial(event.alpha_deg, object) {
                    session.abandon_trial();
                    reply.problem = Some(LearnProblem::TrialStart {
                        index: event.index,
                        source,
                    });
                    reply.report = Some(self.trial_report(LearnReportKind::TrialRejected, event));
                } else {
                    session.observe(&v);
                }
            }
            LearnEventKind::Contact => {
                if session.recorder().phase() == TrialPhase::Approach
                    && let Err(source) = session.infer_contact(&v)
                {
                    reply.problem = Some(LearnProblem::Order {
                        index: event.index,
                        source,
                    });
                }
            }
            LearnEventKind::PushEnd => {
                if event.flag == 1 && session.recorder().phase() == TrialPhase::Push {
                    if let Err(source) = session.end_push(&v) {
                        reply.problem = Some(LearnProblem::Order {
                            index: event.index,
                            source,
                        });
                    }
                } else if session.recorder().phase() != TrialPhase::Idle {
                    session.abandon_trial();
                    reply.report = Some(self.trial_report(LearnReportKind::TrialRejected, event));
                }
            }
            LearnEventKind::TrialEnd => {
                if session.recorder().phase() != TrialPhase::Circling {
                    return Ok(reply);
                }
                let result = session.finish_trial();
                let mut r = self.trial_report(LearnReportKind::TrialLearned, event);
                match result {
                    Ok(record) => {
                        r.contact_point = record.outcome.contact_point_obj.to_array();
                        r.displacement = record.outcome.displacement_obj.to_array();
                        r.rotation_rad = record.outcome.rotation_rad;
                        r.value = record.matched.inlier_fraction;
                        reply.record = Some(record);
                    }
                    Err(source) => {
                        r.kind = LearnReportKind::TrialRejected as u32;
                        reply.problem = Some(LearnProblem::TrialRejected {
                            index: event.index,
                            source,
                        });
                    }
                }
                reply.report = Some(r);
            }
            LearnEventKind::LearningDone => {
                self.finished = true;
                reply.finished = true;
            }
            _ => {}
        }
        Ok(reply)
    }
}
