//! `agp up --detach`: the supervisor in the background, returned from only once every
//! process is past start-up.

use std::path::Path;

use agp_launch::LaunchConfig;
use agp_runtime::{InstanceLock, control_client};
use anyhow::{Context, Result};

use crate::console;

/// How long every process of a detached run must have run, none restarted, before
/// `agp up --detach` calls it started: a planner with no AG file, a bad argument or a
/// missing service fails well within it (the one seen: restarted three times, gone in 1.7 s).
const DETACH_SETTLE: std::time::Duration = std::time::Duration::from_secs(2);

/// Set in the environment of the background supervisor `--detach` starts.
pub const DETACHED_ENV: &str = "AGP_DETACHED";

/// `agp up --detach`: starts `agp up` again in a session of its own with its output in a
/// log file, and returns once its status says every process has run for [`DETACH_SETTLE`]
/// and none was restarted. A process restarted before then failed at start-up: the run is
/// stopped, the error lines of its log are printed, and the exit is 1. An instance another
/// supervisor holds is refused at once, naming that supervisor's pid; and only the status
/// of the supervisor it started (its pid) counts as started.
pub fn detach(launch: &Path, instance_arg: Option<&str>, config: &LaunchConfig) -> Result<u8> {
    use std::os::unix::process::CommandExt;
    let instance = crate::control::instance_named(&config.instance)?;
    // Whoever holds the lock is named by it; released at once when no one does.
    drop(InstanceLock::acquire(&instance)?);
    std::fs::create_dir_all(&config.results).with_context(|| {
        format!(
            "cannot create the results folder {}",
            config.results.display()
        )
    })?;
    let log_path = config
        .results
        .join(format!("agp-up-{}.log", config.instance));
    let log = std::fs::File::create(&log_path)
        .with_context(|| format!("cannot create {}", log_path.display()))?;
    let exe = std::env::current_exe().context("cannot find the running `agp` executable")?;
    let mut cmd = std::process::Command::new(exe);
    cmd.arg("up").arg(launch);
    if let Some(i) = instance_arg {
        cmd.args(["--instance", i]);
    }
    cmd.env(DETACHED_ENV, "1")
        .stdin(std::process::Stdio::null())
        .stdout(log.try_clone().context("cannot share the log file")?)
        .stderr(log);
    // SAFETY: setsid is async-signal-safe; the child leaves our session and terminal.
    unsafe {
        cmd.pre_exec(|| {
            if libc::setsid() < 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    let mut child = cmd
        .spawn()
        .context("cannot start the background supervisor")?;
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    let mut started_and_failed: Option<String> = None;
    loop {
        if let Some(status) = child
            .try_wait()
            .context("cannot watch the background supervisor")?
        {
            let text = std::fs::read_to_string(&log_path).unwrap_or_default();
            eprint!("{text}");
            anyhow::bail!(
                "the background supervisor ended ({status}) before every process ran; its log: {}",
                log_path.display()
            );
        }
        if let Some(failing) = started_and_failed.as_deref() {
            // Stop what is left of the run; its log holds each failure's line.
            let _ = crate::control::down(&config.instance, std::time::Duration::from_secs(20));
            let _ = child.wait();
            let text = std::fs::read_to_string(&log_path).unwrap_or_default();
            for line in error_lines(&text) {
                console::warn(format_args!("{line}"));
            }
            anyhow::bail!(
                "process `{failing}` of instance `{}` failed at start-up and was restarted; the run was stopped; its log: {}",
                config.instance,
                log_path.display()
            );
        }
        if let Ok(r) = control_client::ask(&config.instance, agp_shared_types::ControlKind::Status)
        {
            let report = crate::control::StatusReport::new(&config.instance, &r);
            if report.supervisor_pid != child.id() {
                anyhow::bail!(
                    "instance `{}` is already up under supervisor pid {}; stop it first or pick another name with `--instance`",
                    config.instance,
                    report.supervisor_pid
                );
            }
            if let Some(p) = report.processes.iter().find(|p| p.restarts > 0) {
                started_and_failed = Some(p.name.clone());
                continue;
            }
            if report.all_running()
                && report
                    .processes
                    .iter()
                    .all(|p| p.uptime_s >= DETACH_SETTLE.as_secs_f64())
            {
                report.print();
                println!(
                    "agp: instance `{}` runs in the background; log {}; stop it with `agp down --instance {}`",
                    config.instance,
                    log_path.display(),
                    config.instance
                );
                return Ok(0);
            }
        }
        if std::time::Instant::now() >= deadline {
            anyhow::bail!(
                "not every process of instance `{}` runs after 60 s; see {} and `agp status --instance {}`",
                config.instance,
                log_path.display(),
                config.instance
            );
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

/// The lines of a run's log that say an error, each once, in the order they came: a
/// process restarted for the same fault says the same line again, and a reader needs it
/// once.
fn error_lines(log: &str) -> Vec<&str> {
    let mut seen = std::collections::HashSet::new();
    log.lines()
        .filter(|l| l.contains("error") && seen.insert(*l))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::error_lines;

    #[test]
    fn a_process_restarted_for_the_same_error_has_its_line_printed_once() {
        let log = "agp-planner: error: no AG file at results/triangle.ag\n\
                   [   0.250 s] planner: exited with status 1, restarting\n\
                   agp-planner: error: no AG file at results/triangle.ag\n\
                   agp-estimator: error: another fault\n";
        assert_eq!(
            error_lines(log),
            [
                "agp-planner: error: no AG file at results/triangle.ag",
                "agp-estimator: error: another fault"
            ]
        );
    }
}
