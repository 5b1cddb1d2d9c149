//! Child processes a command starts for itself (the probe's and the benchmarks' private
//! pipelines): each in its own process group, killed if `agp` dies, stopped with SIGTERM, a
//! grace period and SIGKILL, and always reaped.

use std::path::PathBuf;
use std::process::{Child, Command, ExitStatus};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};

use crate::up::{signal_group, spawn_guarded};

/// A child that is stopped and reaped when dropped.
pub struct GuardedChild {
    name: String,
    child: Option<Child>,
}

impl GuardedChild {
    /// Starts `cmd`; `name` says which process it is in messages.
    pub fn spawn(name: &str, cmd: &mut Command) -> Result<Self> {
        let child = spawn_guarded(cmd).with_context(|| format!("cannot start `{name}`"))?;
        Ok(Self {
            name: name.to_owned(),
            child: Some(child),
        })
    }

    /// Its exit status if it has ended.
    pub fn try_wait(&mut self) -> Result<Option<ExitStatus>> {
        match &mut self.child {
            Some(c) => c
                .try_wait()
                .with_context(|| format!("cannot watch `{}`", self.name)),
            None => Ok(None),
        }
    }

    /// SIGTERM, a grace period of `grace`, then SIGKILL; always reaped. Its exit status.
    pub fn stop(&mut self, grace: Duration) -> Result<Option<ExitStatus>> {
        let Some(mut child) = self.child.take() else {
            return Ok(None);
        };
        if child.try_wait()?.is_none() {
            signal_group(&child, libc::SIGTERM);
            let deadline = Instant::now() + grace;
            while child.try_wait()?.is_none() && Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(5));
            }
            if child.try_wait()?.is_none() {
                signal_group(&child, libc::SIGKILL);
            }
        }
        let status = child
            .wait()
            .with_context(|| format!("cannot reap `{}`", self.name))?;
        Ok(Some(status))
    }
}

impl Drop for GuardedChild {
    fn drop(&mut self) {
        let _ = self.stop(Duration::from_secs(5));
    }
}

/// A binary installed next to the running `agp`.
pub fn sibling_executable(name: &str) -> Result<PathBuf> {
    let exe = std::env::current_exe().context("cannot find the running `agp` executable")?;
    let path = exe.with_file_name(name);
    if !path.is_file() {
        bail!(
            "cannot find `{name}` next to {}: build every binary with `cargo build --release --workspace --bins`",
            exe.display()
        );
    }
    Ok(path)
}
