//! Helpers of the cross-process tests: the workspace's binaries, an instance's files, launch files in temporary folders and a running `agp up` watched line by line.

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStderr, ChildStdout, Command, ExitStatus, Stdio};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

use agp_runtime::Instance;
use agp_world::Scenario;
use serde_json::Value;

/// The binary `name` of the workspace in the test's own target folder
/// (`target/debug/deps/<test>` -> `target/debug/<name>`). The README's test command builds
/// every binary first (`cargo build --workspace --bins`).
#[track_caller]
pub fn bin_path(name: &str) -> PathBuf {
    let path = profile_dir().join(name);
    assert!(
        path.is_file(),
        "`{}` is missing: run `cargo build --workspace --bins` first",
        path.display()
    );
    path
}

/// The test's target folder of its profile (`target/debug/deps/<test>` -> `target/debug`),
/// where the workspace's binaries are.
#[track_caller]
fn profile_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("the test executable has a path");
    exe.parent()
        .and_then(Path::parent)
        .expect("the test executable sits in target/<profile>/deps")
        .to_path_buf()
}

/// The AG file of built-in scenario `scenario` (`triangle`, `square`, ...) learned with the
/// paper's protocol by the real `agp bench learn` (seed 7, 60 trials at each alpha 0, +15,
/// -15 deg), shared by every test binary: kept in `target/<profile>/agp-test-cache/`, next to
/// the binaries.
///
/// Cost: the first call after `agp` was built runs `agp bench learn` once, about 7 s of
/// one core in the debug test build (its dependencies are optimised; 6.7 s measured for the
/// triangle on the project's 2-core machine, about 6 s in release); later calls cost
/// nothing. A file older than `agp` is learned again, so a changed learner or AG format is
/// never served stale.
///
/// Safe when several tests or test binaries ask at once: they take turns on a lock file
/// (a lock held by a test that died is released with it), and each learning goes into a
/// temporary folder of the cache and is renamed into place whole, so a reader never sees a
/// torn file, even from a learner killed half-way.
#[track_caller]
pub fn learned_ag(scenario: &str) -> PathBuf {
    use std::os::fd::AsRawFd;

    let cache = profile_dir().join("agp-test-cache");
    std::fs::create_dir_all(&cache).expect("create the test cache folder");
    let file = cache.join(format!("{scenario}.ag"));
    let lock = std::fs::File::create(cache.join(format!("{scenario}.lock")))
        .expect("create the cache's lock file");
    // SAFETY: flock(2) on a descriptor this function owns; released when it is closed.
    let rc = unsafe { libc::flock(lock.as_raw_fd(), libc::LOCK_EX) };
    assert_eq!(
        rc,
        0,
        "cannot lock the AG cache: {}",
        std::io::Error::last_os_error()
    );
    let agp = bin_path("agp");
    let built = |p: &Path| std::fs::metadata(p).and_then(|m| m.modified()).ok();
    if let (Some(learned), Some(agp_built)) = (built(&file), built(&agp))
        && learned >= agp_built
    {
        return file;
    }
    let tmp = tempfile::tempdir_in(&cache).expect("a temporary folder in the cache");
    let out = tmp.path().to_str().expect("a UTF-8 cache path");
    let run = run_agp(
        &cache,
        // One seed, 7: the AG every test was written against (the default is 5 seeds).
        &[
            "bench",
            "learn",
            "--scenario",
            scenario,
            "--seed",
            "7",
            "--out",
            out,
        ],
        // Safety net only: one learning takes seconds.
        Duration::from_secs(600),
    );
    run.assert_success(&format!("`agp bench learn --scenario {scenario}`"));
    let learned = tmp.path().join(format!("{scenario}.ag"));
    assert!(
        learned.is_file(),
        "`agp bench learn` wrote no {}:\n{}",
        learned.display(),
        run.stdout
    );
    std::fs::rename(&learned, &file).expect("rename the learned AG file into place");
    file
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

impl Finished {
    /// Panics, with the status and everything the run printed, unless it exited 0.
    pub fn assert_success(&self, what: &str) {
        assert!(
            self.status.success(),
            "{what} ended with {}\nstdout:\n{}\nstderr:\n{}",
            self.status,
            self.stdout,
            self.stderr
        );
    }

    /// Panics, with everything the run printed, unless it exited with `code`.
    #[track_caller]
    pub fn assert_exit(&self, code: i32) {
        assert_eq!(
            self.status.code(),
            Some(code),
            "stdout:\n{}\nstderr:\n{}",
            self.stdout,
            self.stderr
        );
    }

    /// Panics, showing stdout, unless stdout holds each of `needles`.
    #[track_caller]
    pub fn assert_stdout_says(&self, needles: &[&str]) {
        assert_says("stdout", &self.stdout, needles);
    }

    /// Panics, showing stderr, unless stderr holds each of `needles`.
    #[track_caller]
    pub fn assert_stderr_says(&self, needles: &[&str]) {
        assert_says("stderr", &self.stderr, needles);
    }

    /// How many lines of stdout hold `needle`.
    pub fn stdout_lines_with(&self, needle: &str) -> usize {
        self.stdout.lines().filter(|l| l.contains(needle)).count()
    }
}

#[track_caller]
fn assert_says(stream: &str, text: &str, needles: &[&str]) {
    for needle in needles {
        assert!(
            text.contains(needle),
            "`{needle}` missing from {stream}:\n{text}"
        );
    }
}

/// A launch file of instance `instance`, triangle, lockstep, running `processes` (TOML
/// `[[process]]` entries, such as [`test_child`]'s): the process lines start at line 8.
pub fn child_launch(instance: &str, processes: &str) -> String {
    format!(
        "instance = \"{instance}\"\nscenario = \"triangle\"\n\n[clock]\nmode = \"lockstep\"\n\n{processes}"
    )
}

/// A `[[process]]` entry named `name` running `agp-test-child` (found next to `agp`) with
/// `args` (TOML strings, comma-separated) and `extra` TOML lines.
pub fn test_child(name: &str, args: &str, extra: &str) -> String {
    format!("[[process]]\nname = \"{name}\"\nexec = \"agp-test-child\"\nargs = [{args}]\n{extra}\n")
}

/// Panics unless instance `name` has no file left (shared memory, iceoryx2 folder, lock
/// file) after `run`, whose output the message shows.
#[track_caller]
pub fn assert_instance_clean(name: &str, run: &Finished) {
    let instance = Instance::new(name).expect("a valid instance name");
    assert_eq!(
        count_instance_files(name),
        0,
        "files of `{name}` remain: {:?}\nstdout:\n{}\nstderr:\n{}",
        instance.files(),
        run.stdout,
        run.stderr
    );
    let lock = instance
        .root_dir()
        .parent()
        .expect("an instance's root has a parent")
        .join(format!("{name}.lock"));
    assert!(!lock.exists(), "the lock file of `{name}` remains");
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
        let (child, out, err) = spawn_agp(dir, args);
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

    /// Polls `ok` (an outcome, not the time it takes) until it holds, while the run goes
    /// on. Panics with everything the run printed if it ends first, or if `timeout` (a
    /// safety net) passes.
    #[track_caller]
    pub fn until(&mut self, what: &str, timeout: Duration, mut ok: impl FnMut() -> bool) {
        let deadline = Instant::now() + timeout;
        while !ok() {
            let ended = self.child.try_wait().expect("watch agp");
            if ended.is_none() && Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(2));
                continue;
            }
            // What it printed until now (all of it, once it exited and the pipe closed).
            let drain = if ended.is_some() {
                Duration::from_secs(2)
            } else {
                Duration::ZERO
            };
            while let Ok(line) = self.lines.recv_timeout(drain) {
                self.stdout.push(line);
            }
            let stderr = self.stderr.recv_timeout(drain).unwrap_or_default();
            match ended {
                Some(status) => panic!(
                    "the run ended ({status}) before {what}; stdout:\n{}\nstderr:\n{stderr}",
                    self.stdout.join("\n")
                ),
                None => panic!(
                    "{what} did not come within {timeout:?}; stdout so far:\n{}",
                    self.stdout.join("\n")
                ),
            }
        }
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

/// A test that fails half-way does not leave its run going: the supervisor is stopped the
/// way `agp down` would (SIGTERM: it stops its children and removes the instance's files),
/// killed if it is still there 10 s later.
impl Drop for AgpUp {
    fn drop(&mut self) {
        if !matches!(self.child.try_wait(), Ok(None)) {
            return;
        }
        if let Ok(pid) = libc::pid_t::try_from(self.child.id()) {
            // SAFETY: plain kill(2) of our own child, not reaped yet.
            unsafe { libc::kill(pid, libc::SIGTERM) };
        }
        let deadline = Instant::now() + Duration::from_secs(10);
        while matches!(self.child.try_wait(), Ok(None)) && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(10));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Brings instance `name` down (`agp down`) if the test panics while it is up: a detached
/// supervisor left running would disturb the next run of the test.
pub struct DownOnPanic {
    dir: PathBuf,
    name: String,
}

impl DownOnPanic {
    /// Guards instance `name`, brought down from `dir`.
    pub fn new(dir: &Path, name: &str) -> Self {
        Self {
            dir: dir.to_path_buf(),
            name: name.to_owned(),
        }
    }
}

impl Drop for DownOnPanic {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            return;
        }
        let agp = profile_dir().join("agp");
        let _ = Command::new(agp)
            .args(["down", "--instance", &self.name])
            .current_dir(&self.dir)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status();
    }
}

/// Starts `agp <args...>` in `dir` with stdin closed, and hands back its piped stdout and
/// stderr.
#[track_caller]
fn spawn_agp(dir: &Path, args: &[&str]) -> (Child, ChildStdout, ChildStderr) {
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
    (child, out, err)
}

/// Runs `agp <args...>` in `dir` to its end (at most `timeout`, a safety net).
#[track_caller]
pub fn run_agp(dir: &Path, args: &[&str], timeout: Duration) -> Finished {
    let (mut child, mut out, mut err) = spawn_agp(dir, args);
    let pid = child.id();
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

/// Physics's step log (`agp-physics --step-log`: `step epoch` per applied command) read as
/// it grows: each poll reads only what was appended since the last, so a test can watch a
/// run of hundreds of thousands of steps without rereading it.
pub struct StepLog {
    path: PathBuf,
    file: Option<std::fs::File>,
    /// The end of a line physics is still writing.
    partial: Vec<u8>,
    entries: Vec<(u64, u64)>,
}

impl StepLog {
    /// The log at `path` (it may not exist yet).
    pub fn new(path: impl Into<PathBuf>) -> Self {
        Self {
            path: path.into(),
            file: None,
            partial: Vec::new(),
            entries: Vec::new(),
        }
    }

    /// Reads what was appended; every complete `(step, epoch)` line so far, in order.
    /// (Physics writes through a buffer: the lines are there up to its last flush.)
    #[track_caller]
    pub fn poll(&mut self) -> &[(u64, u64)] {
        if self.file.is_none() {
            self.file = std::fs::File::open(&self.path).ok();
        }
        let Some(file) = &mut self.file else {
            return &self.entries;
        };
        let start = self.partial.len();
        file.read_to_end(&mut self.partial)
            .expect("read the step log");
        if let Some(end) = self.partial[start..].iter().rposition(|&b| b == b'\n') {
            let complete: Vec<u8> = self.partial.drain(..=start + end).collect();
            for line in complete.split(|&b| b == b'\n').filter(|l| !l.is_empty()) {
                let text = std::str::from_utf8(line).expect("a UTF-8 step log");
                let mut it = text.split_whitespace().map(|v| {
                    v.parse::<u64>()
                        .unwrap_or_else(|e| panic!("step log line `{text}`: {e}"))
                });
                match (it.next(), it.next()) {
                    (Some(step), Some(epoch)) => self.entries.push((step, epoch)),
                    _ => panic!("step log line `{text}`: expected `step epoch`"),
                }
            }
        }
        &self.entries
    }

    /// How many steps were applied (complete lines so far).
    pub fn len(&mut self) -> usize {
        self.poll().len()
    }

    /// Whether no step was applied yet.
    pub fn is_empty(&mut self) -> bool {
        self.len() == 0
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

/// `agp status --instance <name> --json` run in `dir` (at most `timeout`, a safety net),
/// parsed; panics if it fails.
#[track_caller]
pub fn status_json(dir: &Path, name: &str, timeout: Duration) -> Value {
    let run = run_agp(dir, &["status", "--instance", name, "--json"], timeout);
    assert!(run.status.success(), "{}", run.stderr);
    serde_json::from_str(&run.stdout).expect("`agp status --json` prints JSON")
}

/// The entry of process `name` in a parsed status, or `Null` when it is not listed.
pub fn status_entry<'a>(status: &'a Value, name: &str) -> &'a Value {
    status["processes"]
        .as_array()
        .and_then(|a| a.iter().find(|p| p["name"] == name))
        .unwrap_or(&Value::Null)
}

/// Every step of a physics step log (`StepLog`: step, epoch) from the first to the last was
/// applied exactly once, and the epochs never went back.
#[track_caller]
pub fn assert_every_step_applied_once(log: &[(u64, u64)]) {
    assert!(log.len() > 100, "only {} steps were applied", log.len());
    for (k, w) in log.windows(2).enumerate() {
        assert_eq!(
            w[1].0,
            w[0].0 + 1,
            "line {}: step {} follows step {}: a step was lost or applied twice",
            k + 2,
            w[1].0,
            w[0].0
        );
        assert!(w[1].1 >= w[0].1, "line {}: the epoch went back", k + 2);
    }
}

/// The verdict `agp up` wrote for the placement run of instance `instance` into
/// `results`, checked: success, and both errors within the tolerance of the built-in
/// scenario `scenario`. `stdout` (the run's) goes into the failure message. Returns the
/// final errors, mm and deg.
#[track_caller]
pub fn assert_placed(results: &Path, instance: &str, scenario: &str, stdout: &str) -> (f64, f64) {
    let verdict_path = results.join(format!("{instance}-place.json"));
    let verdict: Value = serde_json::from_str(
        &std::fs::read_to_string(&verdict_path)
            .unwrap_or_else(|e| panic!("no verdict at {}: {e}", verdict_path.display())),
    )
    .expect("JSON");
    let task = Scenario::resolve(scenario).expect("the built-in").task;
    let (mm, deg) = (
        verdict["position_error_mm"]
            .as_f64()
            .expect("position error"),
        verdict["orientation_error_deg"]
            .as_f64()
            .expect("orientation error"),
    );
    assert_eq!(verdict["success"], true, "{verdict}\n{stdout}");
    assert!(
        mm <= task.tolerance_m * 1e3 && deg <= task.tolerance_rad.to_degrees(),
        "final error {mm:.1} mm, {deg:.1} deg beyond the tolerance: {verdict}"
    );
    (mm, deg)
}

/// A launch file of the learning phase over the real pipeline on the triangle, in
/// lockstep: physics, `agp-estimator`, and `agp-planner --mode learn` with
/// `trials_per_alpha` (its end ends the run). `env` goes into every process's table as is
/// (such as `env = { AGP_COUNT_ALLOCS = "1" }`), or nothing when empty.
pub fn triangle_learning_launch(instance: &str, trials_per_alpha: u32, env: &str) -> String {
    let env = if env.is_empty() {
        String::new()
    } else {
        format!("{env}\n")
    };
    format!(
        "instance = \"{instance}\"\nscenario = \"triangle\"\n\n[clock]\nmode = \"lockstep\"\n\n\
         [[process]]\nname = \"physics\"\nexec = \"agp-physics\"\n{env}\n\
         [[process]]\nname = \"estimator\"\nexec = \"agp-estimator\"\n{env}\n\
         [[process]]\nname = \"planner\"\nexec = \"agp-planner\"\n{env}\
         args = [\"--mode\", \"learn\", \"--trials-per-alpha\", \"{trials_per_alpha}\"]\n\
         ends_run = true\n"
    )
}

/// A lockstep launch file of the triangle's ring: physics, `agp-estimator --load ag`, and
/// `agp-planner` with `planner_args` (the items of a TOML array, such as
/// `"--mode", "serve"`). `top` goes among the top-level keys as is (such as `view = 0\n`);
/// with `ends_run` the planner's exit ends the run.
pub fn triangle_ring_launch(
    instance: &str,
    ag: &Path,
    top: &str,
    planner_args: &str,
    ends_run: bool,
) -> String {
    let ends = if ends_run { "ends_run = true\n" } else { "" };
    format!(
        "instance = \"{instance}\"\nscenario = \"triangle\"\n{top}\n[clock]\nmode = \"lockstep\"\n\n\
         [[process]]\nname = \"physics\"\nexec = \"agp-physics\"\n\n\
         [[process]]\nname = \"estimator\"\nexec = \"agp-estimator\"\nargs = [\"--load\", \"{}\"]\n\n\
         [[process]]\nname = \"planner\"\nexec = \"agp-planner\"\n\
         args = [{planner_args}]\n{ends}",
        ag.display()
    )
}

/// A lockstep launch file of the triangle: physics, `agp-estimator --load ag`, and the
/// workspace's `planner` binary with `planner_args` (words for `sh`), ending the run, started
/// through `sh` once the file `gate` exists in the run's folder (a recorder or a reader the
/// test starts first makes it). `top` goes among the top-level keys as is (such as
/// `record = "run.mcap"\n`).
#[track_caller]
pub fn gated_triangle_launch(
    instance: &str,
    ag: &Path,
    top: &str,
    gate: &str,
    planner: &str,
    planner_args: &str,
) -> String {
    format!(
        "instance = \"{instance}\"\nscenario = \"triangle\"\n{top}\n[clock]\nmode = \"lockstep\"\n\n\
         [[process]]\nname = \"physics\"\nexec = \"agp-physics\"\n\n\
         [[process]]\nname = \"estimator\"\nexec = \"{}\"\nargs = [\"--load\", \"{}\"]\n\n\
         [[process]]\nname = \"planner\"\nexec = \"/bin/sh\"\n\
         args = [\"-c\", \"while [ ! -e {gate} ]; do sleep 0.01; done; exec {} {planner_args}\"]\n\
         ends_run = true\n",
        bin_path("agp-estimator").display(),
        ag.display(),
        bin_path(planner).display(),
    )
}

/// One process's steady-state allocation line (`agp_runtime::alloc_count::report`).
#[derive(Debug, Clone, Copy)]
pub struct AllocCounts {
    /// In the process's loop.
    pub looping: u64,
    /// In its own work (named by the line: simulation, learning, planning).
    pub work: u64,
    pub iceoryx2: u64,
    /// Messages counted, after the warm-up.
    pub messages: u64,
    /// Messages in which anything was allocated.
    pub allocating: u64,
}

/// The steady-state allocation line `process` printed in `output`, its own work named
/// `work`, if there is one.
pub fn alloc_counts(output: &str, process: &str, work: &str) -> Option<AllocCounts> {
    let prefix = format!("{process}: steady-state heap allocations: ");
    let line = output
        .lines()
        .find_map(|l| l.find(&prefix).map(|at| &l[at + prefix.len()..]))?;
    let number_after = |key: &str| -> Option<u64> {
        let (_, rest) = line.split_once(key)?;
        rest.split(|c: char| !c.is_ascii_digit())
            .find(|s| !s.is_empty())?
            .parse()
            .ok()
    };
    Some(AllocCounts {
        looping: number_after("loop ")?,
        work: number_after(&format!(", {work} "))?,
        iceoryx2: number_after("iceoryx2 ")?,
        messages: number_after("over ")?,
        allocating: number_after(", in ")?,
    })
}

/// `.venv-ci/bin/python` at the repository's root (or `AGP_PYTHON`) that can import each of
/// `modules` (`agp`, `iceoryx2`, ...); panics in one line naming the set-up command when it
/// cannot. `tools/setup.sh`, which the README's test command runs first, makes it.
#[track_caller]
pub fn python_with(modules: &[&str]) -> PathBuf {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ sits in the repository");
    let python = std::env::var_os("AGP_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo.join(".venv-ci/bin/python"));
    let ok = Command::new(&python)
        .args(["-c", &format!("import {}", modules.join(", "))])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    assert!(
        ok,
        "no Python with {} at {}: run `tools/setup.sh` at the repository's root (it makes .venv-ci and installs ./python), or set AGP_PYTHON to such an interpreter",
        modules.join(", "),
        python.display()
    );
    python
}
