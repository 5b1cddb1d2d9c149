//! Child processes a command starts for itself (the probe's and the benchmarks' private
//! pipelines): each in its own process group, killed if `agp` dies, stopped with SIGTERM, a
//! grace period and SIGKILL, and always reaped.

use std::path::PathBuf;
use std::process::{Child, Command, ExitStatus};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};

use std::os::unix::process::CommandExt;

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

/// Spawns `cmd` in a process group of its own, killed by the kernel if `agp` dies.
pub fn spawn_guarded(cmd: &mut Command) -> std::io::Result<Child> {
    cmd.process_group(0);
    let parent = libc::pid_t::try_from(std::process::id()).unwrap_or(0);
    // SAFETY: between fork and exec only async-signal-safe calls: prctl, getppid, _exit.
    unsafe {
        cmd.pre_exec(move || {
            if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            // The supervisor died before prctl took effect: nobody would ever stop us.
            if libc::getppid() != parent {
                libc::_exit(1);
            }
            Ok(())
        });
    }
    cmd.spawn()
}

/// Sends `signal` to the process group of `child` (the child and anything it started).
pub fn signal_group(child: &Child, signal: libc::c_int) {
    let Ok(pid) = libc::pid_t::try_from(child.id()) else {
        return;
    };
    // SAFETY: plain kill(2); the child is not reaped yet, so its pid is still ours.
    unsafe {
        if libc::kill(-pid, signal) != 0 {
            libc::kill(pid, signal);
        }
    }
}
