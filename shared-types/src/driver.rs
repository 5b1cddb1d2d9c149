use std::time::Duration;

use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::{Node, ipc};

use crate::control::ActiveEpoch;
use crate::instance::Instance;
use crate::payloads::{GroundTruth, IrFrame, MotorCommand, ObjectEstimate, Pose2, Reset};
use crate::wait::{WaitOutcome, WaitStrategy, Waiter};
use crate::{monotonic_ns, stage};

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
/// With `ground_truth`, it also reads the true poses: that makes it an evaluation tool, which
/// no estimator or planner may be.
pub struct LockstepDriver {
    _node: Node<ipc::Service>,
    frames: Subscriber<ipc::Service, IrFrame, ()>,
    truth: Option<Subscriber<ipc::Service, GroundTruth, ()>>,
    commands: Publisher<ipc::Service, MotorCommand, ()>,
    resets: Publisher<ipc::Service, Reset, ()>,
    physics_inbox: Notifier<ipc::Service>,
    epochs: Subscriber<ipc::Service, ActiveEpoch, ()>,
    waiter: Waiter,
    frame: IrFrame,
    last_truth: GroundTruth,
    epoch: u64,
    timeout: Duration,
    resets_sent: u64,
    /// `trace_id - step` of the physics process being driven: each run of physics has its
    /// own, so a frame with another one comes from a restarted physics.
    trace_base: u64,
}

fn port<E: std::fmt::Debug>(what: &'static str) -> impl FnOnce(E) -> DriveError {
    move |e| DriveError::Open {
        what,
        detail: format!("{e:?}"),
    }
}

impl LockstepDriver {
    /// Connects to the instance's physics and waits (up to `timeout`) for its first frame.
    pub fn connect(
        instance: &Instance,
        node_name: &str,
        epoch: u64,
        ground_truth: bool,
        timeout: Duration,
    ) -> Result<Self, DriveError> {
        let node = instance.node(node_name, false).map_err(port("node"))?;
        let frames = instance.ir_frames(&node).map_err(port("IR frames"))?;
        let commands = instance
            .motor_commands(&node)
            .map_err(port("motor commands"))?;
        let resets = instance.resets(&node).map_err(port("resets"))?;
        let truth = if ground_truth {
            let t = instance.ground_truth(&node).map_err(port("ground truth"))?;
            Some(
                t.data
                    .subscriber_builder()
                    .create()
                    .map_err(port("ground truth"))?,
            )
        } else {
            None
        };
        let epochs = instance
            .active_epoch(&node)
            .map_err(port("active epoch"))?
            .data
            .subscriber_builder()
            .create()
            .map_err(port("active epoch subscriber"))?;
        let listener = frames
            .event
            .listener_builder()
            .create()
            .map_err(port("IR frame listener"))?;
        let mut driver = Self {
            frames: frames
                .data
                .subscriber_builder()
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
            last_truth: GroundTruth::default(),
            epoch,
            timeout,
            resets_sent: 0,
            trace_base: 0,
            _node: node,
        };
        driver.frame = driver.wait_frame(|_| true, 0)?;
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

    /// Waits for a frame `accept` takes (the latest of them). A frame of another physics
    /// run than the last one seen means physics restarted: that frame becomes the latest
    /// and the wait ends with [`DriveError::PhysicsRestarted`].
    fn wait_frame(
        &mut self,
        accept: impl Fn(&IrFrame) -> bool,
        step: u64,
    ) -> Result<IrFrame, DriveError> {
        let frames = &self.frames;
        let base = self.trace_base;
        let first = base == 0;
        let outcome = self.waiter.wait_for(self.timeout, || {
            let mut found = None;
            while let Ok(Some(f)) = frames.receive() {
                let run = f.timing.trace_id.wrapping_sub(f.step);
                if !first && run != base {
                    found = Some(Err(*f));
                } else if accept(&f) && !matches!(found, Some(Err(_))) {
                    found = Some(Ok(*f));
                }
            }
            // The planner's receive is stamped on the frame the wait returns, once.
            if let Some(Ok(f) | Err(f)) = &mut found {
                f.timing.stamps_ns[stage::PLANNER_RECEIVED] = monotonic_ns();
            }
            found
        });
        let frame = match outcome {
            WaitOutcome::Ready(Ok(f)) => f,
            WaitOutcome::Ready(Err(f)) => {
                self.trace_base = f.timing.trace_id.wrapping_sub(f.step);
                self.frame = f;
                return Err(DriveError::PhysicsRestarted);
            }
            WaitOutcome::TimedOut => {
                return Err(DriveError::NoFrame {
                    step,
                    timeout: self.timeout,
                });
            }
            WaitOutcome::Shutdown => return Err(DriveError::Shutdown),
        };
        if first {
            self.trace_base = frame.timing.trace_id.wrapping_sub(frame.step);
        }
        if let Some(t) = &self.truth {
            // Physics publishes a step's truth before its frame.
            while let Ok(Some(s)) = t.receive() {
                if s.step == frame.step {
                    self.last_truth = *s;
                }
            }
        }
        Ok(frame)
    }

    /// Applies wheel speeds for one step and returns the next frame.
    pub fn step(&mut self, left_mps: f64, right_mps: f64) -> Result<&IrFrame, DriveError> {
        let step = self.frame.step;
        let mut cmd = MotorCommand {
            step,
            epoch: self.epoch,
            left_mps,
            right_mps,
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
        let reset_seq = self.frame.reset_seq;
        // Normally the frame of the next step; after a hot swap's flip the frames may have
        // moved on under the other planner: then the latest.
        self.frame = self.wait_frame(|f| f.step > step && f.reset_seq == reset_seq, step + 1)?;
        Ok(&self.frame)
    }

    /// Puts object and robot at the given world poses (odometry restarts at the robot's
    /// pose) and returns the frame of the reset world.
    pub fn reset(&mut self, object: Pose2, robot: Pose2) -> Result<&IrFrame, DriveError> {
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
            })
            .send()
            .map_err(|e| DriveError::Port(format!("send of a reset: {e:?}")))?;
        let _ = self.physics_inbox.notify();
        let step = self.frame.step;
        self.frame = self.wait_frame(|f| f.reset_seq == seq, step)?;
        Ok(&self.frame)
    }
}
