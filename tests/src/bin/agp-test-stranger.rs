//! A stranger for the intruder tests: a process the supervisor did not start that joins the
//! instance named by `--instance` and tries to drive its physics, as another program of the
//! same user could.
//!
//! It follows the IR frames and, for each new frame, sends a motor command for that frame's
//! step in the frame's active epoch (the `step` and `epoch` physics expects), and every tenth
//! frame a reset, all without a token (it has none) and marked: each command carries the
//! trace id [`MARK`], each reset the seq [`MARK`]. Physics hands a command's whole timing
//! back in the frame it makes (`IrFrame::cause`) and a reset's seq in every frame after it
//! (`IrFrame::reset_seq`), so the stranger sees whether any of its messages was applied.
//!
//! It stops after `--commands N` commands (or when no new frame came for 5 s) and prints
//! one line: `stranger: sent C commands and R resets; A applied`; status 0.

use std::time::{Duration, Instant};

use agp_runtime::Instance;
use agp_shared_types::{MotorCommand, Reset};

/// The trace id and reset seq of everything the stranger sends.
const MARK: u64 = 0x5354_5241_4e47_4552;

fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("agp-test-stranger: error: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut instance = None;
    let mut commands = 200u64;
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--instance" => instance = it.next().cloned(),
            "--commands" => {
                commands = it
                    .next()
                    .and_then(|v| v.parse().ok())
                    .ok_or("`--commands` needs a number")?
            }
            other => return Err(format!("unknown argument `{other}`")),
        }
    }
    let instance = Instance::new(&instance.ok_or("give `--instance NAME`")?)
        .map_err(|e| format!("bad instance name: {e}"))?;
    let node = instance
        .node("stranger", false)
        .map_err(|e| format!("cannot create a node: {e:?}"))?;
    let frames = instance
        .ir_frames(&node)
        .map_err(|e| format!("cannot open the frames: {e:?}"))?
        .subscriber()
        .create()
        .map_err(|e| format!("cannot subscribe to the frames: {e:?}"))?;
    let command_topic = instance
        .motor_commands(&node)
        .map_err(|e| format!("cannot open the commands: {e:?}"))?;
    let command_pub = command_topic
        .data
        .publisher_builder()
        .create()
        .map_err(|e| format!("cannot publish commands: {e:?}"))?;
    let inbox = command_topic
        .event
        .notifier_builder()
        .create()
        .map_err(|e| format!("cannot notify physics: {e:?}"))?;
    let reset_pub = instance
        .resets(&node)
        .map_err(|e| format!("cannot open the resets: {e:?}"))?
        .data
        .publisher_builder()
        .create()
        .map_err(|e| format!("cannot publish resets: {e:?}"))?;

    let (mut sent, mut resets, mut applied) = (0u64, 0u64, 0u64);
    let mut last_step = None;
    let mut last_new = Instant::now();
    while sent < commands && last_new.elapsed() < Duration::from_secs(5) {
        let mut newest = None;
        while let Ok(Some(f)) = frames.receive() {
            if f.cause.trace_id == MARK || f.reset_seq == MARK {
                applied += 1;
            }
            newest = Some(*f);
        }
        let Some(f) = newest else {
            std::thread::sleep(Duration::from_micros(200));
            continue;
        };
        if last_step == Some(f.step) {
            continue;
        }
        last_step = Some(f.step);
        last_new = Instant::now();
        let mut cmd = MotorCommand {
            step: f.step,
            epoch: f.active_epoch,
            left_mps: -0.1,
            right_mps: 0.1,
            ..MotorCommand::default()
        };
        cmd.timing.trace_id = MARK;
        let sample = command_pub
            .loan_uninit()
            .map_err(|e| format!("cannot loan a command: {e:?}"))?;
        sample
            .write_payload(cmd)
            .send()
            .map_err(|e| format!("cannot send a command: {e:?}"))?;
        sent += 1;
        if sent % 10 == 0 {
            let sample = reset_pub
                .loan_uninit()
                .map_err(|e| format!("cannot loan a reset: {e:?}"))?;
            sample
                .write_payload(Reset {
                    seq: MARK,
                    epoch: f.active_epoch,
                    ..Reset::default()
                })
                .send()
                .map_err(|e| format!("cannot send a reset: {e:?}"))?;
            resets += 1;
        }
        let _ = inbox.notify();
    }
    // Whatever it sent last had a chance to be applied: look at the frames once more.
    std::thread::sleep(Duration::from_millis(100));
    while let Ok(Some(f)) = frames.receive() {
        if f.cause.trace_id == MARK || f.reset_seq == MARK {
            applied += 1;
        }
    }
    println!("stranger: sent {sent} commands and {resets} resets; {applied} applied");
    Ok(())
}
