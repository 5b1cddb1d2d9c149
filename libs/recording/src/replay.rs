//! The plan of a lockstep replay: what physics applied, in the order it applied it, read
//! from a recording, and the frame each action should make.
//!
//! In lockstep physics applies, at step `s`, any pending reset (the world put in place, the
//! same step published again) and then the one motor command for step `s` (to step
//! `s + 1`). The recording holds the commands (each names its step), the resets (each named
//! by its `seq`, which every frame after it echoes in `reset_seq`) and the frames: a reset
//! applied at step `s` is the one whose `seq` the first frame of step `s` carries.

use std::collections::{BTreeMap, HashMap};

use agp_shared_types::{IrFrame, MotorCommand, Pose2, Reset, ServiceNames, Task};

use crate::reader::{ReadError, Recording};
use crate::topics::payload_from_bytes;

/// One thing physics applied.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ReplayAction {
    /// Put object and robot at these poses (odometry restarts at the robot's).
    Reset {
        /// The `seq` it had in the recorded run.
        seq: u64,
        object: Pose2,
        robot: Pose2,
        /// The noise seed it restarted physics's streams from (0: none).
        seed: u64,
    },
    /// The wheel speeds that stepped the world from `step` to `step + 1`.
    Command {
        step: u64,
        left_mps: f64,
        right_mps: f64,
    },
}

/// Why a recording cannot be replayed.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    #[error(transparent)]
    Read(#[from] ReadError),
    #[error("the recording was made on the `{0}` clock: only a lockstep run replays")]
    NotLockstep(String),
    #[error("the recording holds no IR frame")]
    NoFrames,
    #[error(
        "the recording starts at step {0}, not at the run's start: only a recording from the first step replays"
    )]
    NotFromStart(u64),
    #[error(
        "physics restarted during the recorded run (its steps started over): it cannot be replayed"
    )]
    PhysicsRestarted,
    #[error(
        "the recording lacks the motor commands of {missing} step(s) of 0..={last} (the first: step {first}); \
         the recorder lost them (see `lost` and `dropped` in its account): the run cannot be replayed bit for bit"
    )]
    MissingCommands { missing: u64, first: u64, last: u64 },
}

/// What a lockstep replay does and expects.
#[derive(Debug, Clone)]
pub struct ReplayScript {
    /// The resets and commands physics applied, in order.
    pub actions: Vec<ReplayAction>,
    /// The recorded frame each action made (same index), when the recorder got it.
    pub expected: Vec<Option<IrFrame>>,
    /// The first frame (step 0), which physics publishes before any action.
    pub first_frame: IrFrame,
    /// The last task the planner published, if any (replay publishes it again, so the
    /// judge judges the replayed run as it judged the recorded one).
    pub task: Option<Task>,
    /// Resets recorded that physics did not apply (no frame echoes them).
    pub resets_not_applied: usize,
    /// Commands recorded beyond the one applied per step (another epoch's, or stale).
    pub commands_not_applied: usize,
    pub frames_recorded: usize,
}

impl ReplayScript {
    /// Reads the plan from `recording`: a lockstep run recorded from its first step, with
    /// the command of every step.
    pub fn from_recording(recording: &Recording) -> Result<Self, ReplayError> {
        let run = recording.run();
        if let Some(clock) = run.get("clock")
            && clock != "lockstep"
        {
            return Err(ReplayError::NotLockstep(clock.clone()));
        }
        let mut frames: Vec<IrFrame> = Vec::new();
        let mut commands: Vec<MotorCommand> = Vec::new();
        let mut resets: Vec<Reset> = Vec::new();
        let mut task = None;
        for m in recording.messages()? {
            match m.channel.topic.as_str() {
                ServiceNames::IR_FRAMES => frames.extend(payload_from_bytes::<IrFrame>(&m.data)),
                ServiceNames::MOTOR_COMMANDS => {
                    commands.extend(payload_from_bytes::<MotorCommand>(&m.data));
                }
                ServiceNames::RESETS => resets.extend(payload_from_bytes::<Reset>(&m.data)),
                ServiceNames::TASK => {
                    if let Some(t) = payload_from_bytes::<Task>(&m.data) {
                        task = Some(t);
                    }
                }
                _ => {}
            }
        }
        Self::plan(&frames, &commands, &resets, task)
    }

    /// The plan from the recorded frames, commands and resets (each in the order recorded).
    pub fn plan(
        frames: &[IrFrame],
        commands: &[MotorCommand],
        resets: &[Reset],
        task: Option<Task>,
    ) -> Result<Self, ReplayError> {
        let first = *frames.first().ok_or(ReplayError::NoFrames)?;
        if first.step != 0 {
            return Err(ReplayError::NotFromStart(first.step));
        }
        if frames.windows(2).any(|w| w[1].step < w[0].step) {
            return Err(ReplayError::PhysicsRestarted);
        }
        // The step each reset was applied at, and who drove each step.
        let mut reset_step: HashMap<u64, u64> = HashMap::new();
        let mut by_key: HashMap<(u64, u64), IrFrame> = HashMap::new();
        let mut epoch_after: HashMap<u64, u64> = HashMap::new();
        for f in frames {
            if f.reset_seq != 0 {
                reset_step.entry(f.reset_seq).or_insert(f.step);
            }
            by_key.entry((f.step, f.reset_seq)).or_insert(*f);
            if f.step > 0 {
                epoch_after.entry(f.step - 1).or_insert(f.active_epoch);
            }
        }
        let mut chosen: BTreeMap<u64, MotorCommand> = BTreeMap::new();
        for c in commands {
            let driver = epoch_after.get(&c.step).copied();
            match chosen.get(&c.step) {
                // The first command of the epoch that drove is the one physics took.
                Some(prev) if driver == Some(prev.epoch) => {}
                Some(_) if driver.is_some() && driver != Some(c.epoch) => {}
                _ => {
                    chosen.insert(c.step, *c);
                }
            }
        }
        let commands_not_applied = commands.len() - chosen.len();
        let last = chosen.keys().next_back().copied();
        if let Some(last) = last {
            let missing = (last + 1) - chosen.len() as u64;
            if missing > 0 {
                let first = (0..=last).find(|s| !chosen.contains_key(s)).unwrap_or(0);
                return Err(ReplayError::MissingCommands {
                    missing,
                    first,
                    last,
                });
            }
        }
        let mut applied: Vec<(u64, usize, Reset)> = Vec::new();
        let mut resets_not_applied = 0;
        for (k, r) in resets.iter().enumerate() {
            match reset_step.get(&r.seq) {
                Some(&s) => applied.push((s, k, *r)),
                None => resets_not_applied += 1,
            }
        }
        applied.sort_by_key(|(s, k, _)| (*s, *k));

        let mut actions = Vec::with_capacity(chosen.len() + applied.len());
        let mut expected = Vec::with_capacity(actions.capacity());
        let mut world = 0u64;
        let mut next_reset = applied.iter().peekable();
        let end = last.map_or(0, |l| l + 1);
        for step in 0..=end {
            while let Some((_, _, r)) = next_reset.next_if(|(s, _, _)| *s == step) {
                world = r.seq;
                actions.push(ReplayAction::Reset {
                    seq: r.seq,
                    object: r.object,
                    robot: r.robot,
                    seed: r.seed,
                });
                expected.push(by_key.get(&(step, world)).copied());
            }
            if let Some(c) = chosen.get(&step) {
                actions.push(ReplayAction::Command {
                    step,
                    left_mps: c.left_mps,
                    right_mps: c.right_mps,
                });
                expected.push(by_key.get(&(step + 1, world)).copied());
            }
        }
        Ok(Self {
            actions,
            expected,
            first_frame: first,
            task,
            resets_not_applied,
            commands_not_applied,
            frames_recorded: frames.len(),
        })
    }
}

/// Whether two frames sensed the same to the bit: step, simulated time, IR sample counter
/// and readings, odometry, overhead fix counter and fix. Stamps, trace ids, reset sequence
/// numbers and epochs (which name the run, not the world) are left out.
pub fn same_sensing(a: &IrFrame, b: &IrFrame) -> bool {
    let pose = |p: &Pose2| [p.x.to_bits(), p.y.to_bits(), p.theta.to_bits()];
    a.step == b.step
        && a.sim_time_s.to_bits() == b.sim_time_s.to_bits()
        && a.ir_sample == b.ir_sample
        && a.ir_raw.map(f32::to_bits) == b.ir_raw.map(f32::to_bits)
        && pose(&a.odometry) == pose(&b.odometry)
        && a.fix_seq == b.fix_seq
        && pose(&a.fix) == pose(&b.fix)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(step: u64, reset_seq: u64) -> IrFrame {
        IrFrame {
            step,
            reset_seq,
            sim_time_s: step as f64 / 640.0,
            ..IrFrame::default()
        }
    }

    fn command(step: u64, left: f64) -> MotorCommand {
        MotorCommand {
            step,
            left_mps: left,
            right_mps: -left,
            ..MotorCommand::default()
        }
    }

    fn reset(seq: u64) -> Reset {
        Reset {
            seq,
            object: Pose2::new(0.1, 0.0, 0.0),
            ..Reset::default()
        }
    }

    #[test]
    fn a_reset_is_replayed_at_the_step_whose_frame_first_echoes_it_before_that_steps_command() {
        // Step 0, reset A, steps 0..2, reset B at step 2, step 2.
        let frames = [
            frame(0, 0),
            frame(0, 7),
            frame(1, 7),
            frame(2, 7),
            frame(2, 9),
            frame(3, 9),
        ];
        let commands = [command(0, 0.1), command(1, 0.2), command(2, 0.3)];
        let resets = [reset(7), reset(9), reset(11)];
        let plan = ReplayScript::plan(&frames, &commands, &resets, None).expect("a plan");
        let kinds: Vec<String> = plan
            .actions
            .iter()
            .map(|a| match a {
                ReplayAction::Reset { seq, .. } => format!("R{seq}"),
                ReplayAction::Command { step, .. } => format!("C{step}"),
            })
            .collect();
        assert_eq!(kinds, ["R7", "C0", "C1", "R9", "C2"]);
        assert_eq!(plan.resets_not_applied, 1, "reset 11 no frame echoes");
        let steps: Vec<Option<(u64, u64)>> = plan
            .expected
            .iter()
            .map(|f| f.map(|f| (f.step, f.reset_seq)))
            .collect();
        assert_eq!(
            steps,
            [
                Some((0, 7)),
                Some((1, 7)),
                Some((2, 7)),
                Some((2, 9)),
                Some((3, 9))
            ]
        );
    }

    #[test]
    fn a_missing_command_refuses_the_replay_naming_the_first_step_lacking() {
        let frames = [frame(0, 0), frame(1, 0), frame(2, 0), frame(3, 0)];
        let commands = [command(0, 0.1), command(2, 0.3)];
        match ReplayScript::plan(&frames, &commands, &[], None) {
            Err(ReplayError::MissingCommands {
                missing: 1,
                first: 1,
                last: 2,
            }) => {}
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_recording_that_does_not_start_at_step_0_is_refused() {
        let frames = [frame(5, 0), frame(6, 0)];
        assert!(matches!(
            ReplayScript::plan(&frames, &[command(5, 0.0)], &[], None),
            Err(ReplayError::NotFromStart(5))
        ));
    }

    #[test]
    fn the_command_of_the_epoch_that_drove_is_taken_over_another_epochs() {
        let mut after = frame(1, 0);
        after.active_epoch = 1;
        let frames = [frame(0, 0), after];
        let mut old = command(0, 0.1);
        old.epoch = 0;
        let mut new = command(0, 0.2);
        new.epoch = 1;
        let plan = ReplayScript::plan(&frames, &[old, new], &[], None).expect("a plan");
        assert_eq!(
            plan.actions,
            [ReplayAction::Command {
                step: 0,
                left_mps: 0.2,
                right_mps: -0.2
            }]
        );
        assert_eq!(plan.commands_not_applied, 1);
    }

    #[test]
    fn frames_that_differ_in_one_bit_of_one_reading_do_not_sense_the_same() {
        let a = frame(3, 0);
        let mut b = a;
        b.timing.trace_id = 99;
        b.reset_seq = 5;
        assert!(
            same_sensing(&a, &b),
            "stamps and sequence numbers do not count"
        );
        b.ir_raw[4] = f32::from_bits(b.ir_raw[4].to_bits() ^ 1);
        assert!(!same_sensing(&a, &b));
    }
}
