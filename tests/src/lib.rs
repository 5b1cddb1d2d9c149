//! Helpers of the cross-process tests: the workspace's binaries, an instance's files, launch files in temporary folders and a running `agp up` watched line by line.

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

use agp_shared_types::Instance;

/// The binary `name` of the workspace in the test's own target folder
/// (`target/debug/deps/<test>` -> `target/debug/<name>`). The README's test command builds
/// every binary first (`cargo build --workspace --bins`).
#[track_caller]
pub fn bin_path(name: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("the test executable has a path");
    let dir = exe
        .parent()
        .and_then(Path::parent)
        .expect("the test executable sits in target/<profile>/deps");
    let path = dir.join(name);
    assert!(
        path.is_file(),
        "`{}` is missing: run `cargo build --workspace --bins` first",
        path.display()
    );
    path
}

/// How many files instance `name` has on the machine: its `/dev/shm` entries plus its
/// iceoryx2 root folder, if present.
#[track_caller]
pub fn count_instance_files(name: &str) -> usize {
    Instance::new(name)
        .expect("a valid instance name")
        .files()
        .len()
}

/// A temporary folder holding a `launch.toml`; removed on drop.
pub struct LaunchDir {
    dir: tempfile::TempDir,
}

impl LaunchDir {
    /// A folder holding `launch.toml` with `text`.
    pub fn new(text: &str) -> Self {
        let dir = tempfile::tempdir().expect("a temporary folder");
        std::fs::write(dir.path().join("launch.toml"), text).expect("write launch.toml");
        Self { dir }
    }

    pub fn path(&self) -> &Path {
        self.dir.path()
    }

    /// The launch file.
    pub fn launch(&self) -> PathBuf {
        self.dir.path().join("launch.toml")
    }

    /// The default results folder of the launch file.
    pub fn results(&self) -> PathBuf {
        self.dir.path().join("results")
    }
}

/// What an `agp` run printed and how it ended.
#[derive(Debug)]
pub struct Finished {
    /// The pid `agp` ran as (the probe's private instance is `probe-<pid>`).
    pub pid: u32,
    pub status: ExitStatus,
    pub stdout: String,
    pub stderr: String,
}

/// A running `agp up`: its stdout read line by line as it comes (children share it),
/// its stderr collected.
pub struct AgpUp {
    child: Child,
    lines: Receiver<String>,
    stdout: Vec<String>,
    stderr: Receiver<String>,
}

impl AgpUp {
    /// Starts `agp up <launch> <extra...>` in the launch file's folder.
    pub fn start(launch: &Path, extra: &[&str]) -> Self {
        let mut args = vec!["up", launch.to_str().expect("a UTF-8 launch path")];
        args.extend_from_slice(extra);
        Self::spawn(launch.parent().unwrap_or_else(|| Path::new(".")), &args)
    }

    /// Starts `agp <args...>` in `dir`, for a command that runs until stopped (such as
    /// `agp swap --watch`).
    pub fn spawn(dir: &Path, args: &[&str]) -> Self {
        let mut child = Command::new(bin_path("agp"))
            .args(args)
            .current_dir(dir)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start agp");
        let out = child.stdout.take().expect("piped stdout");
        let err = child.stderr.take().expect("piped stderr");
        let (line_tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(out).lines() {
                let Ok(line) = line else { break };
                if line_tx.send(line).is_err() {
                    break;
                }
            }
        });
        let (err_tx, stderr) = mpsc::channel();
        std::thread::spawn(move || {
            let mut text = String::new();
            let _ = BufReader::new(err).read_to_string(&mut text);
            let _ = err_tx.send(text);
        });
        Self {
            child,
            lines,
            stdout: Vec::new(),
            stderr,
        }
    }

    /// The pid of `agp`.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Sends `signal` to the supervisor.
    pub fn signal(&self, signal: libc::c_int) {
        let pid = libc::pid_t::try_from(self.child.id()).expect("pid fits");
        // SAFETY: plain kill(2) of our own child, not reaped yet.
        let rc = unsafe { libc::kill(pid, signal) };
        assert_eq!(rc, 0, "kill({pid}, {signal}) failed");
    }

    /// Waits (at most `timeout`, a safety net) until `count` lines of stdout contain
    /// `needle`, and returns those lines. Panics with everything seen on timeout.
    #[track_caller]
    pub fn wait_for_lines(&mut self, needle: &str, count: usize, timeout: Duration) -> Vec<String> {
        let deadline = Instant::now() + timeout;
        loop {
            let found: Vec<String> = self
                .stdout
                .iter()
                .filter(|l| l.contains(needle))
                .cloned()
                .collect();
            if found.len() >= count {
                return found;
            }
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(line) => self.stdout.push(line),
                Err(RecvTimeoutError::Timeout) => panic!(
                    "no {count} line(s) with `{needle}` within {timeout:?}; stdout so far:\n{}",
                    self.stdout.join("\n")
                ),
                Err(RecvTimeoutError::Disconnected) => panic!(
                    "stdout closed before {count} line(s) with `{needle}`; stdout:\n{}",
                    self.stdout.join("\n")
                ),
            }
        }
    }

    /// Waits (at most `timeout`, a safety net) for the supervisor to exit, and collects
    /// what it printed. Kills it and panics on timeout.
    #[track_caller]
    pub fn wait(mut self, timeout: Duration) -> Finished {
        let deadline = Instant::now() + timeout;
        let status = loop {
            if let Some(status) = self.child.try_wait().expect("watch agp") {
                break status;
            }
            if Instant::now() >= deadline {
                let _ = self.child.kill();
                let _ = self.child.wait();
                panic!(
                    "agp did not exit within {timeout:?}; stdout:\n{}",
                    self.stdout.join("\n")
                );
            }
            std::thread::sleep(Duration::from_millis(10));
        };
        // The pipe closes when the supervisor and every child are gone.
        let drain_deadline = Instant::now() + Duration::from_secs(10);
        loop {
            let left = drain_deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(line) => self.stdout.push(line),
                Err(_) => break,
            }
        }
        let stderr = self
            .stderr
            .recv_timeout(drain_deadline.saturating_duration_since(Instant::now()))
            .unwrap_or_default();
        Finished {
            pid: self.child.id(),
            status,
            stdout: self.stdout.join("\n"),
            stderr,
        }
    }
}

/// Runs `agp <args...>` in `dir` to its end (at most `timeout`, a safety net).
#[track_caller]
pub fn run_agp(dir: &Path, args: &[&str], timeout: Duration) -> Finished {
    let mut child = Command::new(bin_path("agp"))
        .args(args)
        .current_dir(dir)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start agp");
    let pid = child.id();
    let mut out = child.stdout.take().expect("piped stdout");
    let mut err = child.stderr.take().expect("piped stderr");
    let out_thread = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = out.read_to_string(&mut s);
        s
    });
    let err_thread = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = err.read_to_string(&mut s);
        s
    });
    let deadline = Instant::now() + timeout;
    let status = loop {
        if let Some(status) = child.try_wait().expect("watch agp") {
            break status;
        }
        if Instant::now() >= deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!("`agp {}` did not exit within {timeout:?}", args.join(" "));
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    Finished {
        pid,
        status,
        stdout: out_thread.join().unwrap_or_default(),
        stderr: err_thread.join().unwrap_or_default(),
    }
}

/// Whether process `pid` is gone (no such process, or a zombie nobody reaped yet).
pub fn process_is_gone(pid: u32) -> bool {
    match std::fs::read_to_string(format!("/proc/{pid}/stat")) {
        Err(_) => true,
        // The state follows the parenthesised command name: `pid (comm) S ...`.
        Ok(stat) => stat
            .rsplit_once(')')
            .and_then(|(_, rest)| rest.split_whitespace().next())
            .is_some_and(|state| state == "Z" || state == "X"),
    }
}

/// The pid in a status line `... started, pid N` or `... restarted (..), pid N`.
pub fn pid_in(line: &str) -> Option<u32> {
    line.rsplit_once("pid ")
        .and_then(|(_, rest)| rest.split_whitespace().next())
        .and_then(|n| n.parse().ok())
}
