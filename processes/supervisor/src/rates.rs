//! Message rates for `agp status`: the supervisor reads the instance's IR frames and motor
//! commands as one more subscriber and derives each stream's rate from the step numbers
//! the messages carry, so it needs to see only the latest message of each, not every one.

use std::time::{Duration, Instant};

use agp_runtime::{AgpIpc, Instance};
use agp_shared_types::{IrFrame, MotorCommand};
use anyhow::{Result, anyhow};
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::Node;

/// Samples kept per stream; with one every [`SAMPLE_EVERY`], the rate covers about a second.
const WINDOW: usize = 11;
const SAMPLE_EVERY: Duration = Duration::from_millis(100);

/// The step numbers of one stream over the last second.
#[derive(Debug)]
struct StepWindow {
    samples: [(Instant, u64); WINDOW],
    len: usize,
    next: usize,
    latest: Option<u64>,
}

impl StepWindow {
    fn new() -> Self {
        Self {
            samples: [(Instant::now(), 0); WINDOW],
            len: 0,
            next: 0,
            latest: None,
        }
    }

    /// Notes the newest step seen.
    fn see(&mut self, step: u64) {
        if self.latest.is_some_and(|l| step < l) {
            // The stream started over (a restarted physics counts from 0): so does the rate.
            self.len = 0;
            self.next = 0;
        }
        self.latest = Some(step);
    }

    /// Takes a sample of the latest step when one is due.
    fn tick(&mut self, now: Instant) {
        let Some(step) = self.latest else { return };
        if self.len > 0 {
            let last = self.samples[(self.next + WINDOW - 1) % WINDOW];
            if now - last.0 < SAMPLE_EVERY {
                return;
            }
        }
        self.samples[self.next] = (now, step);
        self.next = (self.next + 1) % WINDOW;
        self.len = (self.len + 1).min(WINDOW);
    }

    /// Steps per second over the window; 0 before two samples.
    fn rate(&self) -> f64 {
        if self.len < 2 {
            return 0.0;
        }
        let newest = self.samples[(self.next + WINDOW - 1) % WINDOW];
        let oldest = self.samples[(self.next + WINDOW - self.len) % WINDOW];
        let dt = (newest.0 - oldest.0).as_secs_f64();
        if dt <= 0.0 {
            return 0.0;
        }
        newest.1.saturating_sub(oldest.1) as f64 / dt
    }
}

/// The rates of the instance's streams that `agp status` shows.
pub(crate) struct MessageRates {
    frames: Subscriber<AgpIpc, IrFrame, ()>,
    commands: Subscriber<AgpIpc, MotorCommand, ()>,
    frame_steps: StepWindow,
    /// Motor commands of the active epoch only: the planner that drives.
    command_steps: StepWindow,
}

impl MessageRates {
    pub(crate) fn open(instance: &Instance, node: &Node<AgpIpc>) -> Result<Self> {
        let frames = instance
            .ir_frames(node)
            .map_err(|e| anyhow!("cannot open the IR frames: {e}"))?
            .subscriber()
            .create()
            .map_err(|e| anyhow!("cannot subscribe to the IR frames: {e:?}"))?;
        let commands = instance
            .motor_commands(node)
            .map_err(|e| anyhow!("cannot open the motor commands: {e}"))?
            .subscriber()
            .create()
            .map_err(|e| anyhow!("cannot subscribe to the motor commands: {e:?}"))?;
        Ok(Self {
            frames,
            commands,
            frame_steps: StepWindow::new(),
            command_steps: StepWindow::new(),
        })
    }

    /// Reads what arrived since the last call.
    pub(crate) fn poll(&mut self, active_epoch: u64) {
        while let Ok(Some(f)) = self.frames.receive() {
            self.frame_steps.see(f.step);
        }
        while let Ok(Some(c)) = self.commands.receive() {
            if c.epoch == active_epoch {
                self.command_steps.see(c.step);
            }
        }
        let now = Instant::now();
        self.frame_steps.tick(now);
        self.command_steps.tick(now);
    }

    /// IR frames published per second (physics).
    pub(crate) fn frames_per_s(&self) -> f64 {
        self.frame_steps.rate()
    }

    /// Motor commands of the driving planner per second.
    pub(crate) fn commands_per_s(&self) -> f64 {
        self.command_steps.rate()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stream_of_steps_gives_its_rate_and_starts_over_when_the_steps_do() {
        let mut w = StepWindow::new();
        let t0 = Instant::now();
        assert_eq!(w.rate(), 0.0);
        for k in 0..=20u64 {
            w.see(k * 50);
            w.tick(t0 + Duration::from_millis(100 * k));
        }
        // 50 steps every 100 ms.
        assert!((w.rate() - 500.0).abs() < 1e-6, "{}", w.rate());
        w.see(3);
        w.tick(t0 + Duration::from_millis(2200));
        assert_eq!(w.rate(), 0.0, "one sample after the restart");
    }
}
