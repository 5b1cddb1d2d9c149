//! How `agp bench` stops on a signal, and the leftovers of benches that could not.
//!
//! [`guarded`] runs a benchmark under a signal front: SIGINT, SIGTERM and SIGHUP set a flag
//! ([`requested`], and `agp_runtime`'s shutdown flag, which every pipeline wait polls).
//! The episode loops check it between episodes, and an episode under way ends early (its
//! planner is stopped); each private pipeline is then stopped and its files removed, the
//! episodes finished are written as a JSON marked `"partial": true`, and `agp` exits
//! 128 + N. A second signal forces the exit at once: a watcher thread kills the bench's
//! children, removes the files of every instance of this bench (`bench-<pid>-*`) and
//! exits 128 + N. The learning (in-process) polls the flag at every simulated step and
//! writes the (seed, object) pairs it learned; `agp bench adapt` (in-process) between its
//! episodes. A phase that polls no flag holds no pipeline and no file: the first signal
//! ends it at once (after 200 ms), with no partial JSON.
//!
//! [`sweep_stale`] removes the instances of benches that died without cleaning (`kill
//! -9`): `bench-<pid>-*` whose pid no process runs any more, owned by this user. Every `agp
//! bench` sweeps first; `agp down --stale` does it by hand.

use std::collections::BTreeSet;
use std::os::unix::fs::MetadataExt;
use std::path::Path;
use std::path::PathBuf;
use std::sync::Mutex;
use std::sync::atomic::{AtomicI32, AtomicU32, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use agp_runtime::Instance;
use anyhow::{Context, Result};
use serde_json::{Value, json};

/// The signals that stop a bench cleanly.
pub const BENCH_STOP_SIGNALS: [libc::c_int; 3] = [libc::SIGINT, libc::SIGTERM, libc::SIGHUP];

/// The first stop signal received, 0 while none.
static FIRST: AtomicI32 = AtomicI32::new(0);
/// How many stop signals arrived.
static COUNT: AtomicU32 = AtomicU32::new(0);
/// How many loops that poll [`requested`] run now ([`checked`]).
static CHECKED: AtomicUsize = AtomicUsize::new(0);

extern "C" fn on_stop_signal(signal: libc::c_int) {
    // Only atomic stores: async-signal-safe.
    let _ = FIRST.compare_exchange(0, signal, Ordering::SeqCst, Ordering::SeqCst);
    COUNT.fetch_add(1, Ordering::SeqCst);
    agp_runtime::request_shutdown();
}

/// A benchmark stopped by a signal, after it wrote what it finished: the error its run
/// returns so that callers (`agp bench paper`) stop too.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("stopped by {}", signal_name(*.signal))]
pub struct Stopped {
    pub signal: i32,
}

impl Stopped {
    /// The stop that arrived, if one did.
    pub fn now() -> Option<Self> {
        signal().map(|signal| Self { signal })
    }

    /// The JSON's `partial_reason`.
    pub fn reason(&self) -> String {
        self.to_string()
    }
}

/// Whether a stop signal arrived.
pub fn requested() -> bool {
    FIRST.load(Ordering::SeqCst) != 0
}

/// The first stop signal, if any.
pub fn signal() -> Option<i32> {
    match FIRST.load(Ordering::SeqCst) {
        0 => None,
        s => Some(s),
    }
}

/// The name of a stop signal, for messages and the JSON.
pub fn signal_name(signal: i32) -> String {
    match signal {
        libc::SIGINT => "SIGINT".into(),
        libc::SIGTERM => "SIGTERM".into(),
        libc::SIGHUP => "SIGHUP".into(),
        s => format!("signal {s}"),
    }
}

/// While held, a loop polls [`requested`] and stops cleanly on its own: the first signal
/// then waits for it (a second one still forces the exit).
#[must_use = "the loop polls the flag only while the guard lives"]
pub struct Checked(());

/// Marks the caller as polling [`requested`] until the guard is dropped.
pub fn checked() -> Checked {
    CHECKED.fetch_add(1, Ordering::SeqCst);
    Checked(())
}

impl Drop for Checked {
    fn drop(&mut self) {
        CHECKED.fetch_sub(1, Ordering::SeqCst);
    }
}

/// Installs the handlers of [`BENCH_STOP_SIGNALS`] and starts the watcher thread that
/// forces the exit on a second signal (or on the first, when no loop polls the flag).
pub fn install() -> std::io::Result<()> {
    for signal in BENCH_STOP_SIGNALS {
        // SAFETY: the handler only touches atomics; the sigaction struct is ours and zeroed.
        let rc = unsafe {
            let mut action: libc::sigaction = std::mem::zeroed();
            action.sa_sigaction = on_stop_signal as extern "C" fn(libc::c_int) as usize;
            libc::sigemptyset(&mut action.sa_mask);
            action.sa_flags = libc::SA_RESTART;
            libc::sigaction(signal, &action, std::ptr::null_mut())
        };
        if rc != 0 {
            return Err(std::io::Error::last_os_error());
        }
    }
    std::thread::Builder::new()
        .name("bench-stop".into())
        .spawn(watch)?;
    Ok(())
}

/// The watcher: polls the counters (20 ms) and forces the exit when asked.
fn watch() {
    let mut said = false;
    loop {
        std::thread::sleep(Duration::from_millis(20));
        let count = COUNT.load(Ordering::SeqCst);
        let Some(sig) = signal() else { continue };
        if !said && count < 2 && CHECKED.load(Ordering::SeqCst) > 0 {
            said = true;
            eprintln!(
                "agp bench: {}: stopping, then writing what finished (a second signal stops at once)",
                signal_name(sig)
            );
        }
        if count >= 2 {
            force_exit(sig, "again: stopping at once");
        }
        if CHECKED.load(Ordering::SeqCst) == 0 {
            // Give a loop that is just starting its check a moment to take it.
            std::thread::sleep(Duration::from_millis(200));
            if CHECKED.load(Ordering::SeqCst) == 0 && COUNT.load(Ordering::SeqCst) < 2 {
                force_exit(
                    sig,
                    "during a phase that holds no pipeline: stopping at once",
                );
            }
        }
    }
}

/// Kills this process's children (each in its group), removes every file of this bench's
/// instances and exits 128 + `sig`.
fn force_exit(sig: i32, why: &str) -> ! {
    let killed = kill_children();
    let (instances, files) = remove_instances_of(std::process::id());
    eprintln!(
        "agp bench: {} {why}; killed {killed} process(es), removed {files} file(s) of {instances} pipeline(s)",
        signal_name(sig)
    );
    // The last checkpoint holds the episodes finished: it says why it is the last.
    let mut slot = CHECKPOINT
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    if let Some(path) = slot.take()
        && let Ok(text) = std::fs::read_to_string(&path)
        && let Ok(mut doc) = serde_json::from_str::<Value>(&text)
    {
        doc["partial_reason"] = json!(format!("{} twice (forced)", Stopped { signal: sig }));
        if write_atomically(&path, &doc).is_ok() {
            eprintln!(
                "agp bench: {} of {} episodes finished, partial JSON {}",
                doc["episodes_finished"],
                doc["episodes_planned"],
                path.display()
            );
        }
    }
    // SAFETY: _exit(2) ends the process at once; nothing of it is used after.
    unsafe { libc::_exit(128 + sig) }
}

/// The pids whose parent is this process.
fn children() -> Vec<u32> {
    let me = std::process::id();
    let Ok(entries) = std::fs::read_dir("/proc") else {
        return Vec::new();
    };
    entries
        .filter_map(Result::ok)
        .filter_map(|e| e.file_name().to_str()?.parse::<u32>().ok())
        .filter(|&pid| parent_of(pid) == Some(me) && !is_gone(pid))
        .collect()
}

/// `PPid` of `/proc/PID/stat`.
fn parent_of(pid: u32) -> Option<u32> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let (_, rest) = stat.rsplit_once(')')?;
    rest.split_whitespace().nth(1)?.parse().ok()
}

/// Whether `pid` is gone (no such process, or a zombie).
fn is_gone(pid: u32) -> bool {
    match std::fs::read_to_string(format!("/proc/{pid}/stat")) {
        Err(_) => true,
        Ok(stat) => stat
            .rsplit_once(')')
            .and_then(|(_, rest)| rest.split_whitespace().next())
            .is_some_and(|state| state == "Z" || state == "X"),
    }
}

/// SIGKILLs every child and its process group, and waits (at most 2 s) until they are
/// gone. How many there were.
fn kill_children() -> usize {
    let pids = children();
    for &pid in &pids {
        let Ok(p) = libc::pid_t::try_from(pid) else {
            continue;
        };
        // SAFETY: plain kill(2) of our own children (not reaped, so their pids are ours)
        // and of the process groups they lead.
        unsafe {
            libc::kill(-p, libc::SIGKILL);
            libc::kill(p, libc::SIGKILL);
        }
    }
    let deadline = Instant::now() + Duration::from_secs(2);
    while pids.iter().any(|&p| !is_gone(p)) && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(5));
    }
    pids.len()
}

/// The pid in an instance name `bench-<pid>-<tag>`.
fn bench_pid(name: &str) -> Option<u32> {
    let rest = name.strip_prefix("bench-")?;
    let (pid, tag) = rest.split_once('-')?;
    if tag.is_empty() || Instance::validate_name(name).is_err() {
        return None;
    }
    pid.parse().ok()
}

/// Every bench instance on the machine owned by this user (`/dev/shm` files
/// `agp_bench-<pid>-<tag>.…` and root folders `<base>/bench-<pid>-<tag>`), with its pid.
fn bench_instances() -> BTreeSet<(u32, String)> {
    // SAFETY: geteuid(2) has no preconditions and cannot fail.
    let uid = unsafe { libc::geteuid() };
    let ours = |p: &Path| std::fs::symlink_metadata(p).is_ok_and(|m| m.uid() == uid);
    let mut found = BTreeSet::new();
    if let Ok(entries) = std::fs::read_dir("/dev/shm") {
        for e in entries.filter_map(Result::ok) {
            let file = e.file_name();
            let Some(name) = file
                .to_str()
                .and_then(|f| f.strip_prefix("agp_"))
                .and_then(|f| f.split_once('.'))
                .map(|(n, _)| n)
            else {
                continue;
            };
            if let Some(pid) = bench_pid(name)
                && ours(&e.path())
            {
                found.insert((pid, name.to_owned()));
            }
        }
    }
    if let Some(base) = root_base()
        && let Ok(entries) = std::fs::read_dir(&base)
    {
        for e in entries.filter_map(Result::ok) {
            let file = e.file_name();
            let Some(name) = file.to_str() else { continue };
            if let Some(pid) = bench_pid(name)
                && ours(&e.path())
            {
                found.insert((pid, name.to_owned()));
            }
        }
    }
    found
}

/// The folder instance roots live in (`/tmp/agp` or `$AGP_IOX2_ROOT`).
fn root_base() -> Option<PathBuf> {
    Instance::new("bench-0-x")
        .ok()
        .and_then(|i| i.root_dir().parent().map(Path::to_path_buf))
}

/// Removes the instances of the bench of `pid`; (instances, files) removed.
fn remove_instances_of(pid: u32) -> (usize, usize) {
    let mut instances = 0;
    let mut files = 0;
    for (_, name) in bench_instances().into_iter().filter(|(p, _)| *p == pid) {
        if let Ok(instance) = Instance::new(&name)
            && let Ok(n) = instance.remove_files()
        {
            instances += 1;
            files += n;
        }
    }
    (instances, files)
}

/// Whether a process runs as `pid`. Any process counts, not only one named `agp` (a bench
/// started through a link of another name must keep its files): a pid recycled by another
/// program keeps a dead bench's leftovers until it ends, which is the safe side.
fn agp_runs(pid: u32) -> bool {
    !is_gone(pid)
}

/// What [`sweep_stale`] removed.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Swept {
    /// The instances removed, by name.
    pub instances: Vec<String>,
    /// Their files (`/dev/shm` entries and root folders).
    pub files: usize,
}

/// Removes every instance `bench-<pid>-*` of this user whose pid no process runs any more
/// (a bench killed with -9 could not clean); never this process's own.
pub fn sweep_stale() -> Result<Swept> {
    let me = std::process::id();
    let mut swept = Swept::default();
    for (pid, name) in bench_instances() {
        if pid == me || agp_runs(pid) {
            continue;
        }
        let instance =
            Instance::new(&name).map_err(|e| anyhow::anyhow!("bad instance name `{name}`: {e}"))?;
        let n = instance.remove_files().map_err(|e| {
            anyhow::anyhow!("cannot remove the leftovers of instance `{name}`: {e}")
        })?;
        swept.files += n;
        swept.instances.push(name);
    }
    Ok(swept)
}

impl Swept {
    /// One line for the user, or `None` when nothing was left.
    pub fn line(&self) -> Option<String> {
        if self.instances.is_empty() {
            return None;
        }
        Some(format!(
            "removed {} leftover instance(s) of benches that died ({}): {} file(s)",
            self.instances.len(),
            self.instances.join(", "),
            self.files
        ))
    }
}

/// Runs a benchmark under the signal front: sweeps the leftovers of dead benches (saying
/// how many), installs the handlers, runs `bench`, and turns a stop into the exit status
/// 128 + N. A benchmark stopped writes its partial JSON itself and returns [`Stopped`].
pub fn guarded<T>(bench: impl FnOnce() -> Result<T>) -> Result<u8> {
    install().map_err(|e| anyhow::anyhow!("cannot install the signal handlers: {e}"))?;
    match sweep_stale() {
        Ok(swept) => {
            if let Some(line) = swept.line() {
                eprintln!("agp bench: {line}");
            }
        }
        Err(e) => eprintln!("agp bench: warning: {e:#}"),
    }
    let result = bench();
    let Some(sig) = signal() else {
        return result.map(|_| 0);
    };
    if let Err(e) = &result
        && e.downcast_ref::<Stopped>().is_none()
    {
        eprintln!("agp bench: while stopping: {e:#}");
    }
    // Whatever the bench left (a pipeline it could not stop in time) goes too.
    let (_, files) = remove_instances_of(std::process::id());
    if files > 0 {
        eprintln!("agp bench: removed {files} file(s) left by its pipelines");
    }
    u8::try_from(128 + sig).map_err(|_| anyhow::anyhow!("stopped by signal {sig}"))
}

/// Where a benchmark run without `--json` keeps its checkpoint and partial JSON.
pub const PARTIAL_DIR: &str = "results/partial";

/// Where a stopped benchmark writes its partial JSON: `--json` when given (not `-`), else
/// `results/partial/<benchmark>-<pid>.json`.
pub fn partial_path(json: Option<&Path>, benchmark: &str) -> PathBuf {
    match json {
        Some(p) if p != Path::new("-") => p.to_path_buf(),
        _ => Path::new(PARTIAL_DIR).join(format!("{benchmark}-{}.json", std::process::id())),
    }
}

/// The checkpoint a running benchmark keeps of the episodes it finished, rewritten after
/// each; a forced exit marks it as the last.
static CHECKPOINT: Mutex<Option<PathBuf>> = Mutex::new(None);

/// Writes `doc` to a temporary file beside `path`, then renames it into place: a reader (or
/// a bench killed half-way) never sees a torn file.
fn write_atomically(path: &Path, doc: &Value) -> Result<()> {
    if let Some(dir) = path.parent()
        && !dir.as_os_str().is_empty()
    {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the folder {}", dir.display()))?;
    }
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(format!(".{}.tmp", std::process::id()));
    let tmp = PathBuf::from(tmp);
    crate::seeds::write_json(&tmp, doc)?;
    std::fs::rename(&tmp, path)
        .with_context(|| format!("cannot rename {} to {}", tmp.display(), path.display()))
}

/// Marks `doc` partial: `"partial": true`, `"partial_reason"`, the episodes finished and
/// planned (for `learn`: the (seed, object) learnings).
fn mark_partial(doc: &mut Value, reason: &str, finished: usize, planned: usize) {
    doc["partial"] = json!(true);
    doc["partial_reason"] = json!(reason);
    doc["episodes_finished"] = json!(finished);
    doc["episodes_planned"] = json!(planned);
}

/// Writes the checkpoint of a running benchmark: what it finished so far, marked partial
/// ("running": a bench killed with -9 leaves it so), to [`partial_path`]. A failure to
/// write is said once and the run goes on.
pub fn checkpoint(
    mut doc: Value,
    json: Option<&Path>,
    benchmark: &str,
    finished: usize,
    planned: usize,
) {
    mark_partial(
        &mut doc,
        "running (the bench had not ended when this was written)",
        finished,
        planned,
    );
    let path = partial_path(json, benchmark);
    let mut slot = CHECKPOINT
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    if requested() && slot.is_none() {
        return;
    }
    match write_atomically(&path, &doc) {
        Ok(()) => *slot = Some(path),
        Err(e) => {
            if slot.is_some() || !requested() {
                eprintln!("agp bench {benchmark}: cannot write the checkpoint: {e:#}");
            }
        }
    }
}

/// Ends the checkpoints of a run that finished: the next write of the JSON is the result.
/// Removes the checkpoint file when the result goes elsewhere (no `--json`).
pub fn end_checkpoints(json: Option<&Path>, benchmark: &str) {
    let mut slot = CHECKPOINT
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    if let Some(path) = slot.take()
        && partial_path(json, benchmark) != json.map(Path::to_path_buf).unwrap_or_default()
    {
        let _ = std::fs::remove_file(path);
    }
}

/// Writes a partial document (`"partial": true`, `"partial_reason"`, the episodes
/// finished and planned), says where on one line, and returns the [`Stopped`] error.
pub fn write_partial(
    mut doc: Value,
    json: Option<&Path>,
    benchmark: &str,
    finished: usize,
    planned: usize,
) -> anyhow::Error {
    let stopped = Stopped::now().unwrap_or(Stopped {
        signal: libc::SIGINT,
    });
    mark_partial(&mut doc, &stopped.reason(), finished, planned);
    let path = partial_path(json, benchmark);
    let mut slot = CHECKPOINT
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    slot.take();
    match write_atomically(&path, &doc) {
        Ok(()) => eprintln!(
            "agp bench {benchmark}: {}: {finished} of {planned} {} finished, partial JSON {}",
            stopped.reason(),
            if benchmark == "learn" {
                "(seed, object) learnings"
            } else {
                "episodes"
            },
            path.display()
        ),
        Err(e) => eprintln!(
            "agp bench {benchmark}: {}: cannot write the partial JSON: {e:#}",
            stopped.reason()
        ),
    }
    stopped.into()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bench_instance_name_gives_its_pid_and_others_none() {
        assert_eq!(bench_pid("bench-1234-aff"), Some(1234));
        assert_eq!(bench_pid("bench-1234-bas100"), Some(1234));
        assert_eq!(bench_pid("bench-1234-"), None);
        assert_eq!(bench_pid("bench-x-aff"), None);
        assert_eq!(bench_pid("probe-1234-aff"), None);
        assert_eq!(bench_pid("bench-12-A"), None);
    }
}
