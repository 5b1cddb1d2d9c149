//! A pipeline run by the real `agp up` and watched from outside, as a user would: launch files, the supervisor, `agp status`, signals, resident memory, and a cleanup that leaves no process and no file behind.
//!
//! Used by `bench-faults` (the fault campaign) and `bench-soak` (the long run). Nothing
//! here joins the instance over iceoryx2: everything goes through the `agp` CLI, physics's
//! step log and `/proc`, so the tools see the pipeline as a user does and never count as a
//! stranger on the instance.

use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use agp_runtime::{Instance, shutdown_requested};
use anyhow::{Context, Result, anyhow, bail};
use serde_json::Value;

/// The release binaries a campaign runs.
#[derive(Debug, Clone)]
pub struct Bins {
    dir: PathBuf,
}

/// The executables every launch file of the tools names.
pub const PIPELINE_BINS: [&str; 4] = ["agp", "agp-physics", "agp-estimator", "agp-planner"];

impl Bins {
    /// The binaries in `dir`, or next to the running executable; each must be there.
    pub fn new(dir: Option<PathBuf>) -> Result<Self> {
        let dir = match dir {
            Some(d) => d,
            None => std::env::current_exe()
                .context("cannot find the running executable")?
                .parent()
                .map(Path::to_path_buf)
                .ok_or_else(|| anyhow!("the running executable has no folder"))?,
        };
        let dir = dir
            .canonicalize()
            .with_context(|| format!("no binary folder {}", dir.display()))?;
        for name in PIPELINE_BINS {
            let path = dir.join(name);
            if !path.is_file() {
                bail!(
                    "no `{name}` in {}: build it with `cargo build --release --workspace --bins` or pass `--bin-dir`",
                    dir.display()
                );
            }
        }
        Ok(Self { dir })
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    pub fn path(&self, name: &str) -> PathBuf {
        self.dir.join(name)
    }

    /// An `agp` command in `cwd`, in a process group of its own (a Ctrl-C at the terminal
    /// reaches the tool only, which then stops what it started in order), with no stdin.
    pub fn agp(&self, cwd: &Path) -> Command {
        let mut cmd = Command::new(self.path("agp"));
        cmd.current_dir(cwd).stdin(Stdio::null()).process_group(0);
        cmd
    }

    /// Whether process `pid` runs one of these binaries (so a recycled pid is never
    /// signalled).
    pub fn owns(&self, pid: u32) -> bool {
        std::fs::read_link(format!("/proc/{pid}/exe")).is_ok_and(|exe| exe.starts_with(&self.dir))
    }
}

/// What a pipeline run does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Phase {
    /// The learning phase in lockstep (`agp-planner --mode learn`), shortened to a few
    /// trials per alpha; its verdict is the saved AG file.
    Learn,
    /// The placement task in lockstep, the estimator serving a learned AG file; its
    /// verdict is the judge's.
    Place,
    /// A long-running session on the realtime clock: physics stepping on the wall clock
    /// and the estimator reading and acknowledging every frame, until `agp down`. No
    /// planner runs in it (`bench-soak` measures the pipeline's steady state so);
    /// `bench-faults` adds a planner serving goals (`--mode serve`) for its live phase.
    Live,
}

impl Phase {
    pub const ALL: [Phase; 3] = [Phase::Learn, Phase::Place, Phase::Live];

    pub fn as_str(self) -> &'static str {
        match self {
            Phase::Learn => "learn",
            Phase::Place => "place",
            Phase::Live => "live",
        }
    }

    /// The children a run of this phase has.
    pub fn children(self) -> &'static [&'static str] {
        match self {
            Phase::Learn | Phase::Place => &["physics", "estimator", "planner"],
            Phase::Live => &["physics", "estimator"],
        }
    }

    /// Whether physics logs its steps (lockstep only), so progress can be watched.
    pub fn has_step_log(self) -> bool {
        self != Phase::Live
    }
}

/// One run's launch file, written by [`LaunchSpec::write`].
#[derive(Debug, Clone)]
pub struct LaunchSpec<'a> {
    pub phase: Phase,
    pub instance: &'a str,
    /// Learn: trials per alpha.
    pub trials_per_alpha: u32,
    /// Place: the AG file the estimator serves.
    pub ag_file: Option<&'a Path>,
    /// Restarts each child may take (every child restarts on failure, 10 ms backoff).
    pub max_restarts: u32,
}

impl LaunchSpec<'_> {
    /// The launch file's text; `dir` is the run's folder (step log and results go there).
    pub fn text(&self, bins: &Bins, dir: &Path) -> Result<String> {
        let exec = |name: &str| toml_str(&bins.path(name));
        let restart = format!(
            "restart = {{ policy = \"on-failure\", max_restarts = {}, backoff_ms = 10 }}\nstop_grace_ms = 1000\n",
            self.max_restarts
        );
        let clock = if self.phase == Phase::Live {
            "realtime"
        } else {
            "lockstep"
        };
        let mut text = format!(
            "instance = \"{}\"\nscenario = \"triangle\"\nresults = \"results\"\n\n[clock]\nmode = \"{clock}\"\nrate_hz = 640\n\n",
            self.instance
        );
        let physics_args = if self.phase.has_step_log() {
            format!(
                "args = [\"--step-log\", {}]\n",
                toml_str(&step_log_path(dir))
            )
        } else {
            String::new()
        };
        text += &format!(
            "[[process]]\nname = \"physics\"\nexec = {}\n{physics_args}{restart}\n",
            exec("agp-physics")
        );
        let estimator_args = match (self.phase, self.ag_file) {
            (Phase::Place, Some(ag)) => format!("args = [\"--load\", {}]\n", toml_str(ag)),
            (Phase::Place, None) => bail!("a placement run needs an AG file"),
            _ => String::new(),
        };
        text += &format!(
            "[[process]]\nname = \"estimator\"\nexec = {}\n{estimator_args}{restart}\n",
            exec("agp-estimator")
        );
        let planner_args = match self.phase {
            Phase::Learn => format!(
                "[\"--mode\", \"learn\", \"--trials-per-alpha\", \"{}\"]",
                self.trials_per_alpha
            ),
            Phase::Place => "[\"--mode\", \"place\", \"--planner\", \"affordance\"]".to_owned(),
            Phase::Live => return Ok(text),
        };
        text += &format!(
            "[[process]]\nname = \"planner\"\nexec = {}\nargs = {planner_args}\n{restart}ends_run = true\n",
            exec("agp-planner")
        );
        Ok(text)
    }

    /// Writes `<dir>/launch.toml` and returns its path.
    pub fn write(&self, bins: &Bins, dir: &Path) -> Result<PathBuf> {
        let path = dir.join("launch.toml");
        std::fs::write(&path, self.text(bins, dir)?)
            .with_context(|| format!("cannot write {}", path.display()))?;
        Ok(path)
    }
}

/// Physics's step log in a run folder.
pub fn step_log_path(dir: &Path) -> PathBuf {
    dir.join("steps.log")
}

/// A path as a TOML basic string.
fn toml_str(path: &Path) -> String {
    let s = path.to_string_lossy();
    format!("\"{}\"", s.replace('\\', "\\\\").replace('"', "\\\""))
}

/// One child as `agp status --json` lists it.
#[derive(Debug, Clone, PartialEq)]
pub struct ChildStatus {
    pub name: String,
    pub state: String,
    pub pid: Option<u32>,
    pub restarts: u32,
    /// Messages per second it published over the last second (physics: IR frames).
    pub rate_per_s: Option<f64>,
}

impl ChildStatus {
    pub fn running(&self) -> bool {
        self.state == "running" && self.pid.is_some()
    }
}

/// `agp status --json`, the parts the tools read.
#[derive(Debug, Clone, PartialEq)]
pub struct Status {
    pub supervisor_pid: u32,
    pub processes: Vec<ChildStatus>,
}

impl Status {
    pub fn child(&self, name: &str) -> Option<&ChildStatus> {
        self.processes.iter().find(|p| p.name == name)
    }

    /// Whether every child of `names` is listed and running.
    pub fn all_running(&self, names: &[&str]) -> bool {
        names
            .iter()
            .all(|n| self.child(n).is_some_and(ChildStatus::running))
    }

    fn parse(text: &str) -> Result<Self> {
        let v: Value = serde_json::from_str(text).context("`agp status --json` printed no JSON")?;
        let supervisor_pid = v["supervisor_pid"]
            .as_u64()
            .and_then(|p| u32::try_from(p).ok())
            .ok_or_else(|| anyhow!("`agp status --json` has no supervisor_pid"))?;
        let processes = v["processes"]
            .as_array()
            .ok_or_else(|| anyhow!("`agp status --json` has no processes"))?
            .iter()
            .map(|p| ChildStatus {
                name: p["name"].as_str().unwrap_or_default().to_owned(),
                state: p["state"].as_str().unwrap_or_default().to_owned(),
                pid: p["pid"].as_u64().and_then(|n| u32::try_from(n).ok()),
                restarts: p["restarts"]
                    .as_u64()
                    .and_then(|n| u32::try_from(n).ok())
                    .unwrap_or(0),
                rate_per_s: p["rate_per_s"].as_f64(),
            })
            .collect();
        Ok(Self {
            supervisor_pid,
            processes,
        })
    }
}

/// Runs `agp status --instance NAME --json`; `Ok(None)` when it answers no status (not up,
/// still starting, not answering). `timeout` is a safety net: `agp status` bounds its own
/// wait for an answer.
pub fn status(
    bins: &Bins,
    cwd: &Path,
    instance: &str,
    timeout: Duration,
) -> Result<Option<Status>> {
    let mut child = bins
        .agp(cwd)
        .args(["status", "--instance", instance, "--json"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .context("cannot start `agp status`")?;
    let mut out = child.stdout.take().context("piped stdout")?;
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = out.read_to_string(&mut s);
        s
    });
    let deadline = Instant::now() + timeout;
    let exit = loop {
        if let Some(s) = child.try_wait().context("cannot watch `agp status`")? {
            break s;
        }
        if Instant::now() >= deadline {
            // SIGTERM, so it can let go of its node; then SIGKILL.
            signal(child.id(), libc::SIGTERM);
            std::thread::sleep(Duration::from_millis(200));
            let _ = child.kill();
            let _ = child.wait();
            let _ = reader.join();
            return Ok(None);
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    let text = reader.join().unwrap_or_default();
    if !exit.success() {
        return Ok(None);
    }
    Status::parse(&text).map(Some)
}

/// A running `agp up`, its output appended to `up.log` and `up.err` in its folder. It gets
/// SIGTERM if the tool dies (`PR_SET_PDEATHSIG`), so even a tool killed hard leaves the
/// supervisor to stop its children and remove the instance's files.
pub struct Supervisor {
    child: Child,
    exit: Option<ExitStatus>,
}

impl Supervisor {
    /// Starts `agp up <launch>` in the launch file's folder. Call from the main thread
    /// (the death signal follows the thread that started it).
    pub fn start(bins: &Bins, launch: &Path) -> Result<Self> {
        let dir = launch
            .parent()
            .ok_or_else(|| anyhow!("{} has no folder", launch.display()))?;
        let append = |name: &str| -> Result<File> {
            let p = dir.join(name);
            std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(&p)
                .with_context(|| format!("cannot open {}", p.display()))
        };
        let mut cmd = bins.agp(dir);
        cmd.arg("up")
            .arg(launch)
            .stdout(append("up.log")?)
            .stderr(append("up.err")?);
        // SAFETY: prctl(2) is async-signal-safe; nothing else runs between fork and exec.
        unsafe {
            cmd.pre_exec(|| {
                if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
                Ok(())
            });
        }
        let child = cmd.spawn().context("cannot start `agp up`")?;
        Ok(Self { child, exit: None })
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// How it ended, once it did.
    pub fn exited(&mut self) -> Option<ExitStatus> {
        if self.exit.is_none() {
            self.exit = self.child.try_wait().ok().flatten();
        }
        self.exit
    }

    pub fn signal(&self, sig: libc::c_int) -> bool {
        self.exit.is_none() && signal(self.pid(), sig)
    }

    /// Waits until it exits or `timeout` passes.
    pub fn wait_exit(&mut self, timeout: Duration) -> Option<ExitStatus> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(s) = self.exited() {
                return Some(s);
            }
            if Instant::now() >= deadline {
                return None;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// Stops it as `agp down` would (SIGCONT first, in case it is stopped; SIGTERM, SIGKILL
    /// 15 s later) and reaps it.
    pub fn stop(&mut self) -> Option<ExitStatus> {
        if let Some(s) = self.exited() {
            return Some(s);
        }
        self.signal(libc::SIGCONT);
        self.signal(libc::SIGTERM);
        if let Some(s) = self.wait_exit(Duration::from_secs(15)) {
            return Some(s);
        }
        let _ = self.child.kill();
        self.exit = self.child.wait().ok();
        self.exit
    }
}

impl Drop for Supervisor {
    fn drop(&mut self) {
        self.stop();
    }
}

/// Sends `sig` to `pid`; whether it was delivered.
pub fn signal(pid: u32, sig: libc::c_int) -> bool {
    let Ok(pid) = libc::pid_t::try_from(pid) else {
        return false;
    };
    // SAFETY: plain kill(2); callers pass pids of processes the tool started or read from
    // `agp status` and checked with `Bins::owns`.
    unsafe { libc::kill(pid, sig) == 0 }
}

/// Whether `pid` is gone (no such process, or a zombie).
pub fn is_gone(pid: u32) -> bool {
    match std::fs::read_to_string(format!("/proc/{pid}/stat")) {
        Err(_) => true,
        Ok(stat) => stat
            .rsplit_once(')')
            .and_then(|(_, rest)| rest.split_whitespace().next())
            .is_some_and(|state| state == "Z" || state == "X"),
    }
}

/// Resident memory of `pid`, kB (`VmRSS` of `/proc/PID/status`).
pub fn rss_kb(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.split_whitespace().next())
        .and_then(|n| n.parse().ok())
}

/// The files instance `name` has on the machine (`/dev/shm` entries and its root folder).
pub fn instance_files(name: &str) -> Result<Vec<PathBuf>> {
    Ok(Instance::new(name)
        .map_err(|e| anyhow!("bad instance name `{name}`: {e}"))?
        .files())
}

/// Of those, the ones in `/dev/shm`.
pub fn shm_file_count(name: &str) -> Result<usize> {
    Ok(instance_files(name)?
        .iter()
        .filter(|p| p.starts_with("/dev/shm"))
        .count())
}

/// Waits until every pid of `pids` is gone, at most `timeout`; then kills what remains of
/// them (only pids that still run one of `bins`). Returns how many had to be killed.
pub fn reap_children(bins: &Bins, pids: &[u32], timeout: Duration) -> usize {
    let deadline = Instant::now() + timeout;
    while pids.iter().any(|&p| !is_gone(p)) && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(10));
    }
    let mut killed = 0;
    for &p in pids {
        if !is_gone(p) && bins.owns(p) {
            signal(p, libc::SIGCONT);
            if signal(p, libc::SIGKILL) {
                killed += 1;
            }
        }
    }
    killed
}

/// Removes what is left of instance `name` once no process of it runs; how many entries.
pub fn remove_instance_files(name: &str) -> Result<usize> {
    let instance = Instance::new(name).map_err(|e| anyhow!("bad instance name `{name}`: {e}"))?;
    instance
        .remove_files()
        .with_context(|| format!("cannot remove the files of instance `{name}`"))
}

/// Counts the lines physics appended to its step log, reading only what is new.
pub struct StepCounter {
    path: PathBuf,
    file: Option<File>,
    read: u64,
    lines: u64,
    buf: Vec<u8>,
}

impl StepCounter {
    pub fn new(path: PathBuf) -> Self {
        Self {
            path,
            file: None,
            read: 0,
            lines: 0,
            buf: Vec::with_capacity(1 << 16),
        }
    }

    /// Steps logged so far (over every physics of the run).
    pub fn count(&mut self) -> u64 {
        if self.file.is_none() {
            self.file = File::open(&self.path).ok();
        }
        let Some(file) = &mut self.file else {
            return self.lines;
        };
        if file.seek(SeekFrom::Start(self.read)).is_err() {
            return self.lines;
        }
        self.buf.clear();
        if let Ok(n) = file.read_to_end(&mut self.buf) {
            self.read += n as u64;
            self.lines += self.buf.iter().filter(|&&b| b == b'\n').count() as u64;
        }
        self.lines
    }
}

/// Sleeps `d` in slices, returning `Err` as soon as SIGINT or SIGTERM arrived.
pub fn sleep_checked(d: Duration) -> Result<()> {
    let end = Instant::now() + d;
    loop {
        if shutdown_requested() {
            bail!("interrupted");
        }
        let now = Instant::now();
        if now >= end {
            return Ok(());
        }
        std::thread::sleep((end - now).min(Duration::from_millis(20)));
    }
}

/// Whether an error is the one [`sleep_checked`] returns on a signal.
pub fn is_interrupt(e: &anyhow::Error) -> bool {
    shutdown_requested() && e.to_string() == "interrupted"
}

/// The last line of `up.log`/`up.err` in `dir` holding `needle`, for notes.
pub fn last_line_with(dir: &Path, file: &str, needle: &str) -> Option<String> {
    let text = std::fs::read_to_string(dir.join(file)).ok()?;
    text.lines()
        .rev()
        .find(|l| l.contains(needle))
        .map(|l| l.trim().to_owned())
}

/// One instance under way: its supervisor, folder and every child pid seen, so that every
/// way out (an error, a panic, Ctrl-C) stops it and leaves nothing behind.
pub struct Session<'a> {
    pub bins: &'a Bins,
    pub instance: String,
    pub dir: PathBuf,
    pub launch: PathBuf,
    sup: Option<Supervisor>,
    /// Every child pid seen in a status.
    pub seen: Vec<u32>,
    /// A process stopped just now, continued if the tool is interrupted mid-pause.
    pub stopped: Option<u32>,
}

impl<'a> Session<'a> {
    /// Starts `agp up <launch>` for `instance`; the launch file's folder is the session's.
    pub fn start(bins: &'a Bins, instance: &str, launch: PathBuf) -> Result<Self> {
        let dir = launch
            .parent()
            .ok_or_else(|| anyhow!("{} has no folder", launch.display()))?
            .to_path_buf();
        let sup = Supervisor::start(bins, &launch)?;
        Ok(Self {
            bins,
            instance: instance.to_owned(),
            dir,
            launch,
            sup: Some(sup),
            seen: Vec::new(),
            stopped: None,
        })
    }

    pub fn sup(&mut self) -> &mut Supervisor {
        self.sup
            .as_mut()
            .expect("a session has a supervisor until shut")
    }

    /// Starts a new `agp up` of the same launch file (after its supervisor died).
    pub fn up_again(&mut self) -> Result<()> {
        self.sup = Some(Supervisor::start(self.bins, &self.launch)?);
        Ok(())
    }

    /// The supervisor's exit code once it exited (`Some(None)`: by a signal).
    pub fn ended(&mut self) -> Option<Option<i32>> {
        self.sup
            .as_mut()
            .map_or(Some(None), |s| s.exited().map(|e| e.code()))
    }

    /// `agp status`, remembering the children's pids.
    pub fn status(&mut self) -> Result<Option<Status>> {
        let s = status(
            self.bins,
            &self.dir,
            &self.instance,
            Duration::from_secs(10),
        )?;
        if let Some(s) = &s {
            for pid in s.processes.iter().filter_map(|p| p.pid) {
                if !self.seen.contains(&pid) {
                    self.seen.push(pid);
                }
            }
        }
        Ok(s)
    }

    /// `agp down --instance NAME`, as a user stops a session; whether it said so.
    pub fn down(&self) -> Result<bool> {
        let status = self
            .bins
            .agp(&self.dir)
            .args(["down", "--instance", &self.instance])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .context("cannot run `agp down`")?;
        Ok(status.success())
    }

    /// Stops everything it started (continuing anything stopped first) and removes what
    /// the instance left. Returns how many files of the instance were there once every
    /// process was gone, before they were removed.
    pub fn shut(&mut self) -> usize {
        if let Some(pid) = self.stopped.take() {
            signal(pid, libc::SIGCONT);
        }
        for &pid in &self.seen {
            if !is_gone(pid) && self.bins.owns(pid) {
                signal(pid, libc::SIGCONT);
            }
        }
        if let Some(mut sup) = self.sup.take() {
            sup.stop();
        }
        reap_children(self.bins, &self.seen, Duration::from_secs(10));
        let left = instance_files(&self.instance).map_or(0, |f| f.len());
        if left > 0 {
            let _ = remove_instance_files(&self.instance);
        }
        left
    }
}

impl Drop for Session<'_> {
    fn drop(&mut self) {
        self.shut();
    }
}
