use std::time::Duration;

use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::Node;

use agp_shared_types::{
    ActiveEpoch, GroundTruth, IrFrame, MotorCommand, ObjectEstimate, Pose2, Reset, monotonic_ns,
    session_token_from_env, stage,
};

use crate::AgpIpc;
use crate::instance::Instance;
use crate::wait::{WaitOutcome, WaitStrategy, Waiter};

/// Why driving physics failed.
#[derive(Debug, thiserror::Error)]
pub enum DriveError {
    #[error("cannot open `{what}`: {detail}")]
    Open { what: &'static str, detail: String },
    #[error(
        "no IR frame of step {step} from physics within {timeout:?}: is `agp-physics` running in lockstep on this instance?"
    )]
    NoFrame { step: u64, timeout: Duration },
    #[error("shutdown requested")]
    Shutdown,
    #[error("epoch {epoch} did not become active within {timeout:?}")]
    NotActivated { epoch: u64, timeout: Duration },
    #[error("iceoryx2 {0}")]
    Port(String),
    /// Physics restarted (a new world, counting steps from 0): the driver now follows the
    /// new one; whatever was under way must start again, from a reset.
    #[error("physics restarted")]
    PhysicsRestarted,
}

/// Drives a lockstep physics process directly: sends a motor command for the current step,
/// waits for the next frame. Used by the probe, the planner's modes and tests. A planner that
/// acts on the estimator's estimate of a frame rather than on the frame itself says so with
/// [`LockstepDriver::note_estimate`], so its command's timing covers the estimator's hops.
///
/// [`LockstepDriver::step`] and [`LockstepDriver::reset`] send and wait on the IR frames'
/// event service. A client that waits on another event instead (the learning planner waits
/// for the estimator's acknowledgement of the next frame, which implies the frame is
/// published) splits them: [`LockstepDriver::send`] or [`LockstepDriver::send_reset`], then
/// [`LockstepDriver::take_frame`] (no wait) or [`LockstepDriver::await_frame`].
///
/// With `ground_truth`, it also reads the true poses: that makes it an evaluation tool, which
/// no estimator or planner may be.
///
/// Every command and reset carries the token the supervisor handed this process in
/// `AGP_TOKEN` ([`agp_shared_types::SessionKey::token`] of its epoch; 0 without one): a physics the
/// supervisor started applies nothing else. A physics started without a session key (by
/// hand, by the probe or a benchmark's private pipeline) takes every command.
pub struct LockstepDriver {
    _node: Node<AgpIpc>,
    frames: Subscriber<AgpIpc, IrFrame, ()>,
    truth: Option<Subscriber<AgpIpc, GroundTruth, ()>>,
    commands: Publisher<AgpIpc, MotorCommand, ()>,
    resets: Publisher<AgpIpc, Reset, ()>,
    physics_inbox: Notifier<AgpIpc>,
    epochs: Subscriber<AgpIpc, ActiveEpoch, ()>,
    waiter: Waiter,
    frame: IrFrame,
    /// The frame the last command or reset will make, until it is taken.
    awaited: Option<Awaited>,
    last_truth: GroundTruth,
    epoch: u64,
    /// The token of `epoch` every command and reset carries.
    token: u64,
    timeout: Duration,
    resets_sent: u64,
    /// `trace_id - step` of the physics process being driven: each run of physics has its
    /// own, so a frame with another one comes from a restarted physics.
    trace_base: u64,
}

/// Which frame the driver waits for.
#[derive(Debug, Clone, Copy)]
enum Awaited {
    /// Any: the first frame after connecting.
    Any,
    /// The frame made by the command for `step`, in the world of reset `reset_seq`. Normally
    /// the frame of `step + 1`; after a hot swap's flip the frames may have moved on under
    /// the other planner: then the latest.
    After { step: u64, reset_seq: u64 },
    /// The frame of the world reset `seq` put in place (still of step `step`).
    Reset { step: u64, seq: u64 },
}

impl Awaited {
    fn accepts(self, f: &IrFrame) -> bool {
        match self {
            Self::Any => true,
            Self::After { step, reset_seq } => f.step > step && f.reset_seq == reset_seq,
            Self::Reset { seq, .. } => f.reset_seq == seq,
        }
    }

    /// The step a [`DriveError::NoFrame`] names.
    fn step(self) -> u64 {
        match self {
            Self::Any => 0,
            Self::After { step, .. } => step + 1,
            Self::Reset { step, .. } => step,
        }
    }
}

/// What the subscriber holds: the latest frame `awaited` accepts, or, if any, the latest
/// frame of another physics run than `base` (`base` 0: none seen yet, every run is
/// accepted). Stamps the planner's receive on the frame returned.
fn poll_frames(
    frames: &Subscriber<AgpIpc, IrFrame, ()>,
    base: u64,
    awaited: Awaited,
) -> Option<Result<IrFrame, IrFrame>> {
    let first = base == 0;
    let mut found = None;
    while let Ok(Some(f)) = frames.receive() {
        let run = f.timing.trace_id.wrapping_sub(f.step);
        if !first && run != base {
            found = Some(Err(*f));
        } else if awaited.accepts(&f) && !matches!(found, Some(Err(_))) {
            found = Some(Ok(*f));
        }
    }
    // The planner's receive is stamped on the frame returned, once.
    if let Some(Ok(f) | Err(f)) = &mut found {
        f.timing.stamps_ns[stage::PLANNER_RECEIVED] = monotonic_ns();
    }
    found
}

fn port<E: std::fmt::Debug>(what: &'static str) -> impl FnOnce(E) -> DriveError {
    move |e| DriveError::Open {
        what,
        detail: format!("{e:?}"),
    }
}

/// Whether a driver subscribes to ground truth. Only the `oracle` planner (an upper bound
/// that says so), the probe and the tests that check physics against the truth may; the
/// estimator and every other planner see the senses only.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TruthAccess {
    /// The robot's senses only: what a planner sees.
    SensesOnly,
    /// The senses and the world's true state ([`LockstepDriver::truth`]).
    GroundTruth,
}

impl LockstepDriver {
    /// Connects to the instance's physics and waits (up to `timeout`) for its first frame.
    pub fn connect(
        instance: &Instance,
        node_name: &str,
        epoch: u64,
        access: TruthAccess,
        timeout: Duration,
    ) -> Result<Self, DriveError> {
        let ground_truth = access == TruthAccess::GroundTruth;
        let node = instance.node(node_name, false).map_err(port("node"))?;
        let frames = instance.ir_frames(&node).map_err(port("IR frames"))?;
        let commands = instance
            .motor_commands(&node)
            .map_err(port("motor commands"))?;
        let resets = instance.resets(&node).map_err(port("resets"))?;
        let truth = if ground_truth {
            let t = instance.ground_truth(&node).map_err(port("ground truth"))?;
            Some(t.subscriber().create().map_err(port("ground truth"))?)
        } else {
            None
        };
        let epochs = instance
            .active_epoch(&node)
            .map_err(port("active epoch"))?
            .subscriber()
            .create()
            .map_err(port("active epoch subscriber"))?;
        let listener = frames
            .event
            .listener_builder()
            .create()
            .map_err(port("IR frame listener"))?;
        let mut driver = Self {
            frames: frames
                .subscriber()
                .create()
                .map_err(port("IR frame subscriber"))?,
            truth,
            commands: commands
                .data
                .publisher_builder()
                .create()
                .map_err(port("motor command publisher"))?,
            resets: resets
                .data
                .publisher_builder()
                .create()
                .map_err(port("reset publisher"))?,
            physics_inbox: commands
                .event
                .notifier_builder()
                .create()
                .map_err(port("physics inbox notifier"))?,
            epochs,
            waiter: Waiter::new(listener, WaitStrategy::from_env()),
            frame: IrFrame::default(),
            awaited: Some(Awaited::Any),
            last_truth: GroundTruth::default(),
            epoch,
            token: session_token_from_env(),
            timeout,
            resets_sent: 0,
            trace_base: 0,
            _node: node,
        };
        driver.await_frame()?;
        Ok(driver)
    }

    /// The epoch this driver's commands carry.
    pub fn epoch(&self) -> u64 {
        self.epoch
    }

    /// For a planner started by a hot swap, after it told the supervisor it is ready:
    /// waits until the supervisor made its epoch the active one, then takes the latest
    /// frame, the one physics waits to get this planner's command for.
    pub fn take_over(&mut self, timeout: Duration) -> Result<&IrFrame, DriveError> {
        let _in_iceoryx2 = crate::alloc_count::enter(crate::alloc_count::Region::Iceoryx2);
        let start = std::time::Instant::now();
        loop {
            let mut active = None;
            while let Ok(Some(e)) = self.epochs.receive() {
                active = Some(e.epoch);
            }
            if active == Some(self.epoch) {
                break;
            }
            if crate::wait::shutdown_requested() {
                return Err(DriveError::Shutdown);
            }
            if start.elapsed() > timeout {
                return Err(DriveError::NotActivated {
                    epoch: self.epoch,
                    timeout,
                });
            }
            std::thread::sleep(Duration::from_micros(50));
        }
        let frames = &self.frames;
        let mut taken = false;
        while let Ok(Some(f)) = frames.receive() {
            if f.step >= self.frame.step {
                self.frame = *f;
                taken = true;
            }
        }
        if taken {
            self.frame.timing.stamps_ns[stage::PLANNER_RECEIVED] = monotonic_ns();
        }
        Ok(&self.frame)
    }

    /// The latest frame.
    pub fn frame(&self) -> &IrFrame {
        &self.frame
    }

    /// Notes that the planner acts on the estimator's `estimate` of the latest frame, which
    /// it received at `received_ns` (CLOCK_MONOTONIC): the next command then carries the
    /// estimator's stamps (ESTIMATOR_RECEIVED, ESTIMATE_PUBLISHED) and, as PLANNER_RECEIVED,
    /// the estimate's receipt instead of the frame's. An estimate of another frame (another
    /// trace or publish stamp) changes nothing; returns whether it was noted.
    pub fn note_estimate(&mut self, estimate: &ObjectEstimate, received_ns: u64) -> bool {
        let (e, f) = (&estimate.timing, &mut self.frame.timing);
        if e.trace_id != f.trace_id
            || e.stamps_ns[stage::FRAME_PUBLISHED] != f.stamps_ns[stage::FRAME_PUBLISHED]
        {
            return false;
        }
        f.stamps_ns[stage::ESTIMATOR_RECEIVED] = e.stamps_ns[stage::ESTIMATOR_RECEIVED];
        f.stamps_ns[stage::ESTIMATE_PUBLISHED] = e.stamps_ns[stage::ESTIMATE_PUBLISHED];
        f.stamps_ns[stage::PLANNER_RECEIVED] = received_ns;
        true
    }

    /// The ground truth of the latest frame's step (only when connected with ground truth).
    pub fn truth(&self) -> &GroundTruth {
        &self.last_truth
    }

    /// Takes the frame the last command or reset made if the subscriber holds it, without
    /// waiting: `None` if it is not there yet. With nothing awaited, the latest frame. A
    /// frame of another physics run than the last one seen means physics restarted: that
    /// frame becomes the latest and this returns [`DriveError::PhysicsRestarted`].
    pub fn take_frame(&mut self) -> Result<Option<&IrFrame>, DriveError> {
        let _in_iceoryx2 = crate::alloc_count::enter(crate::alloc_count::Region::Iceoryx2);
        let Some(awaited) = self.awaited else {
            return Ok(Some(&self.frame));
        };
        match poll_frames(&self.frames, self.trace_base, awaited) {
            None => Ok(None),
            Some(found) => self.accept(found).map(Some),
        }
    }

    /// Waits (up to the driver's timeout) for the frame the last command or reset made and
    /// returns it; with nothing awaited, the latest frame. Ends with
    /// [`DriveError::PhysicsRestarted`] as [`LockstepDriver::take_frame`] does.
    pub fn await_frame(&mut self) -> Result<&IrFrame, DriveError> {
        let _in_iceoryx2 = crate::alloc_count::enter(crate::alloc_count::Region::Iceoryx2);
        let Some(awaited) = self.awaited else {
            return Ok(&self.frame);
        };
        let frames = &self.frames;
        let base = self.trace_base;
        match self
            .waiter
            .wait_for(self.timeout, || poll_frames(frames, base, awaited))
        {
            WaitOutcome::Ready(found) => self.accept(found),
            WaitOutcome::TimedOut => Err(DriveError::NoFrame {
                step: awaited.step(),
                timeout: self.timeout,
            }),
            WaitOutcome::Shutdown => Err(DriveError::Shutdown),
        }
    }

    /// Waits (up to the driver's timeout) for a frame newer than the latest and returns
    /// the newest there is; with a command or reset under way, the frame it makes, as
    /// [`LockstepDriver::await_frame`]. For a realtime physics, which publishes frames
    /// whether commanded or not: a client that needs a later frame than the one it holds
    /// (its estimate is not in, or predates what it told the estimator) takes it without
    /// commanding. A lockstep physics publishes none uncommanded: this would time out.
    pub fn await_newer_frame(&mut self) -> Result<&IrFrame, DriveError> {
        if self.awaited.is_none() {
            self.awaited = Some(Awaited::After {
                step: self.frame.step,
                reset_seq: self.frame.reset_seq,
            });
        }
        self.await_frame()
    }

    /// Makes a polled frame the latest: the awaited one (`Ok`), with its step's ground
    /// truth, or the first of a restarted physics (`Err`).
    fn accept(&mut self, found: Result<IrFrame, IrFrame>) -> Result<&IrFrame, DriveError> {
        self.awaited = None;
        let (frame, restarted) = match found {
            Ok(f) => (f, false),
            Err(f) => (f, true),
        };
        if restarted || self.trace_base == 0 {
            self.trace_base = frame.timing.trace_id.wrapping_sub(frame.step);
        }
        self.frame = frame;
        if restarted {
            return Err(DriveError::PhysicsRestarted);
        }
        if let Some(t) = &self.truth {
            // Physics publishes a step's truth before its frame.
            while let Ok(Some(s)) = t.receive() {
                if s.step == frame.step {
                    self.last_truth = *s;
                }
            }
        }
        crate::alloc_count::message_done();
        Ok(&self.frame)
    }

    /// Applies wheel speeds for one step and returns the next frame.
    pub fn step(&mut self, left_mps: f64, right_mps: f64) -> Result<&IrFrame, DriveError> {
        self.send(left_mps, right_mps)?;
        self.await_frame()
    }

    /// Publishes the motor command for the latest frame's step; the frame it makes is then
    /// taken with [`LockstepDriver::take_frame`] or [`LockstepDriver::await_frame`].
    pub fn send(&mut self, left_mps: f64, right_mps: f64) -> Result<(), DriveError> {
        let _in_iceoryx2 = crate::alloc_count::enter(crate::alloc_count::Region::Iceoryx2);
        let step = self.frame.step;
        let mut cmd = MotorCommand {
            step,
            epoch: self.epoch,
            left_mps,
            right_mps,
            token: self.token,
            ..MotorCommand::default()
        };
        // The frame's trace and its stamps up to the planner's receive (with the
        // estimator's, if `note_estimate` added them); the stages after it belong to this
        // command (the frame's own COMMAND_* stamps are the previous command's).
        cmd.timing.trace_id = self.frame.timing.trace_id;
        cmd.timing.stamps_ns[..=stage::PLANNER_RECEIVED]
            .copy_from_slice(&self.frame.timing.stamps_ns[..=stage::PLANNER_RECEIVED]);
        cmd.timing.stamps_ns[stage::COMMAND_PUBLISHED] = monotonic_ns();
        let sample = self
            .commands
            .loan_uninit()
            .map_err(|e| DriveError::Port(format!("loan of a motor command: {e:?}")))?;
        sample
            .write_payload(cmd)
            .send()
            .map_err(|e| DriveError::Port(format!("send of a motor command: {e:?}")))?;
        let _ = self.physics_inbox.notify();
        self.awaited = Some(Awaited::After {
            step,
            reset_seq: self.frame.reset_seq,
        });
        Ok(())
    }

    /// Puts object and robot at the given world poses (odometry restarts at the robot's
    /// pose) and returns the frame of the reset world.
    pub fn reset(&mut self, object: Pose2, robot: Pose2) -> Result<&IrFrame, DriveError> {
        self.send_reset(object, robot)?;
        self.await_frame()
    }

    /// As [`LockstepDriver::reset`], and physics restarts its noise streams from `seed`
    /// (0: they go on; [`Reset::seed`]).
    pub fn reset_seeded(
        &mut self,
        object: Pose2,
        robot: Pose2,
        seed: u64,
    ) -> Result<&IrFrame, DriveError> {
        self.send_reset_seeded(object, robot, seed)?;
        self.await_frame()
    }

    /// Publishes a reset (as [`LockstepDriver::reset`]); the frame of the reset world is
    /// then taken with [`LockstepDriver::take_frame`] or [`LockstepDriver::await_frame`].
    pub fn send_reset(&mut self, object: Pose2, robot: Pose2) -> Result<(), DriveError> {
        self.send_reset_seeded(object, robot, 0)
    }

    fn send_reset_seeded(
        &mut self,
        object: Pose2,
        robot: Pose2,
        seed: u64,
    ) -> Result<(), DriveError> {
        let _in_iceoryx2 = crate::alloc_count::enter(crate::alloc_count::Region::Iceoryx2);
        self.resets_sent += 1;
        // Unique per driver and reset, so an old frame is never taken for the new world.
        let seq = (monotonic_ns() & !0xffff) | (self.resets_sent & 0xffff);
        let sample = self
            .resets
            .loan_uninit()
            .map_err(|e| DriveError::Port(format!("loan of a reset: {e:?}")))?;
        sample
            .write_payload(Reset {
                seq,
                object,
                robot,
                epoch: self.epoch,
                token: self.token,
                seed,
            })
            .send()
            .map_err(|e| DriveError::Port(format!("send of a reset: {e:?}")))?;
        let _ = self.physics_inbox.notify();
        self.awaited = Some(Awaited::Reset {
            step: self.frame.step,
            seq,
        });
        Ok(())
    }
}
