//! Stopping a benchmark loses nothing and leaves nothing behind (issue 35): a real `agp
//! bench place` over the pipeline, started in a process group of its own as a shell starts
//! a job, stopped by a signal during its placements. It exits 128 + N, no process of it is
//! left, no file of its pipelines stays in /dev/shm, and its partial JSON holds the
//! episodes it finished. A bench killed with -9 leaves files the next bench removes, and
//! says so.

use std::io::{BufRead, BufReader};
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc::{self, Receiver};
use std::time::{Duration, Instant};

use agp_tests::{bin_path, learned_ag, process_is_gone, run_agp};
use serde_json::Value;

/// Safety net of every wait: an episode takes seconds.
const TIMEOUT: Duration = Duration::from_secs(120);

/// The tests take turns: a bench sweeps the leftovers of dead benches when it starts, and
/// the test of `kill -9` must see its killed bench's files before the next bench does.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn one_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    ONE_AT_A_TIME
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// A running `agp bench place`, its stderr read line by line.
struct Bench {
    child: Child,
    lines: Receiver<String>,
    seen: Vec<String>,
    dir: PathBuf,
}

impl Bench {
    /// `agp bench place` of the triangle over the pipeline (two planners, many episodes: it
    /// is stopped long before the end), leader of its own process group, its JSON to
    /// `place.json`.
    fn start(dir: &Path) -> Self {
        let ag = learned_ag("triangle");
        let mut child = Command::new(bin_path("agp"))
            .args([
                "bench",
                "place",
                "--scenario",
                "triangle",
                "--episodes",
                "40",
            ])
            .args(["--seed", "5", "--planners", "affordance,baseline", "--ag"])
            .arg(&ag)
            .args(["--json", "place.json"])
            .current_dir(dir)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .process_group(0)
            .spawn()
            .expect("start agp bench place");
        let err = child.stderr.take().expect("piped stderr");
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(err).lines() {
                let Ok(line) = line else { break };
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        Self {
            child,
            lines,
            seen: Vec::new(),
            dir: dir.to_path_buf(),
        }
    }

    fn pid(&self) -> u32 {
        self.child.id()
    }

    fn json_path(&self) -> PathBuf {
        self.dir.join("place.json")
    }

    /// Waits until a line of stderr holds `needle` (at most [`TIMEOUT`]).
    #[track_caller]
    fn wait_for(&mut self, needle: &str) {
        let deadline = Instant::now() + TIMEOUT;
        while !self.seen.iter().any(|l| l.contains(needle)) {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(line) => self.seen.push(line),
                Err(_) => panic!(
                    "no line with `{needle}` within {TIMEOUT:?}; stderr:\n{}",
                    self.seen.join("\n")
                ),
            }
        }
    }

    /// Waits until an episode finished (the bench says so on stderr).
    #[track_caller]
    fn wait_for_an_episode(&mut self) {
        self.wait_for("episode 0 done");
    }

    /// Sends `signal` to the bench's process group (as Ctrl-C at a terminal does) or to
    /// the bench alone.
    fn signal(&self, signal: libc::c_int, group: bool) {
        let pid = libc::pid_t::try_from(self.pid()).expect("pid fits");
        let target = if group { -pid } else { pid };
        // SAFETY: plain kill(2) of our own child (not reaped) or the group it leads.
        let rc = unsafe { libc::kill(target, signal) };
        assert_eq!(rc, 0, "kill({target}, {signal}) failed");
    }

    /// Waits for the exit (at most [`TIMEOUT`]), then reads the rest of stderr.
    #[track_caller]
    fn wait(&mut self) -> ExitStatus {
        let deadline = Instant::now() + TIMEOUT;
        let status = loop {
            if let Some(s) = self.child.try_wait().expect("watch agp") {
                break s;
            }
            if Instant::now() >= deadline {
                let _ = self.child.kill();
                let _ = self.child.wait();
                panic!(
                    "agp bench did not exit within {TIMEOUT:?}; stderr:\n{}",
                    self.seen.join("\n")
                );
            }
            std::thread::sleep(Duration::from_millis(10));
        };
        while let Ok(line) = self.lines.recv_timeout(Duration::from_secs(5)) {
            self.seen.push(line);
        }
        status
    }

    fn stderr(&self) -> String {
        self.seen.join("\n")
    }
}

impl Drop for Bench {
    fn drop(&mut self) {
        if matches!(self.child.try_wait(), Ok(None)) {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// The pids whose parent is `pid`.
fn children_of(pid: u32) -> Vec<u32> {
    std::fs::read_dir("/proc")
        .expect("read /proc")
        .filter_map(Result::ok)
        .filter_map(|e| e.file_name().to_str()?.parse::<u32>().ok())
        .filter(|&p| {
            std::fs::read_to_string(format!("/proc/{p}/stat"))
                .ok()
                .and_then(|s| {
                    let (_, rest) = s.rsplit_once(')')?;
                    rest.split_whitespace().nth(1)?.parse::<u32>().ok()
                })
                == Some(pid)
        })
        .collect()
}

/// Files of the bench of `pid`'s pipelines: `/dev/shm/agp_bench-<pid>-…` and root folders
/// `bench-<pid>-*` in the instance base folder.
fn bench_files(pid: u32) -> Vec<PathBuf> {
    let shm_prefix = format!("agp_bench-{pid}-");
    let dir_prefix = format!("bench-{pid}-");
    let base = std::env::var_os("AGP_IOX2_ROOT")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("/tmp/agp"));
    let list = |dir: &Path, prefix: &str| -> Vec<PathBuf> {
        std::fs::read_dir(dir)
            .map(|entries| {
                entries
                    .filter_map(Result::ok)
                    .filter(|e| e.file_name().to_string_lossy().starts_with(prefix))
                    .map(|e| e.path())
                    .collect()
            })
            .unwrap_or_default()
    };
    let mut files = list(Path::new("/dev/shm"), &shm_prefix);
    files.extend(list(&base, &dir_prefix));
    files
}

fn read_json(path: &Path) -> Value {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("no JSON at {}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: not JSON: {e}", path.display()))
}

/// How many episodes the document's planners hold.
fn episodes_in(doc: &Value) -> u64 {
    doc["planners"]
        .as_object()
        .map(|m| m.values().filter_map(|p| p["episodes"].as_u64()).sum())
        .unwrap_or(0)
}

/// Stops a bench during its placements with `signals` (each sent once the bench reacted
/// to the one before), to its group or to it alone, and checks everything the issue asks.
/// The bench runs in `dir`; returns its partial JSON's path.
fn stopped_bench_leaves_nothing_and_keeps_its_episodes(
    dir: &Path,
    signals: &[libc::c_int],
    group: bool,
) -> PathBuf {
    let _turn = one_at_a_time();
    let mut bench = Bench::start(dir);
    bench.wait_for_an_episode();
    let pid = bench.pid();
    let children = children_of(pid);
    assert!(
        !children.is_empty(),
        "a bench over the pipeline runs children; stderr:\n{}",
        bench.stderr()
    );
    assert!(
        !bench_files(pid).is_empty(),
        "its pipelines have files while it runs"
    );
    if signals.len() > 1 {
        // Physics stopped (SIGSTOP): the clean stop now waits for its grace period, and
        // only the second signal can end the bench at once.
        for &c in &children {
            if std::fs::read_to_string(format!("/proc/{c}/comm"))
                .is_ok_and(|comm| comm.trim() == "agp-physics")
            {
                let c = libc::pid_t::try_from(c).expect("pid fits");
                // SAFETY: plain kill(2) of a child of our own child, alive (listed just now).
                unsafe { libc::kill(c, libc::SIGSTOP) };
            }
        }
    }
    for (k, &sig) in signals.iter().enumerate() {
        if k > 0 {
            // The second signal once the bench said it is stopping on the first.
            bench.wait_for("a second signal stops at once");
        }
        bench.signal(sig, group);
    }
    let status = bench.wait();
    let first = signals[0];
    if signals.len() > 1 {
        assert!(
            bench.stderr().contains("again: stopping at once"),
            "the second signal forced the exit; stderr:\n{}",
            bench.stderr()
        );
    }
    assert_eq!(
        status.code(),
        Some(128 + first),
        "exit status {status:?} (signal {:?}); stderr:\n{}",
        status.signal(),
        bench.stderr()
    );
    for c in &children {
        assert!(process_is_gone(*c), "child {c} of the bench is still alive");
    }
    let left = bench_files(pid);
    assert!(left.is_empty(), "files left: {left:?}");
    let doc = read_json(&bench.json_path());
    assert_eq!(doc["partial"], true, "{doc}");
    let reason = doc["partial_reason"].as_str().unwrap_or_default();
    let name = match first {
        libc::SIGINT => "SIGINT",
        libc::SIGTERM => "SIGTERM",
        _ => "SIGHUP",
    };
    assert!(reason.contains(name), "partial_reason `{reason}`");
    let finished = doc["episodes_finished"].as_u64().unwrap_or(0);
    assert!(finished >= 1, "{doc}");
    assert_eq!(episodes_in(&doc), finished, "{doc}");
    assert_eq!(doc["episodes_planned"], 80, "{doc}");
    assert!(
        bench.stderr().contains("partial JSON"),
        "the bench says where its partial JSON is; stderr:\n{}",
        bench.stderr()
    );
    bench.json_path()
}

#[test]
fn sigint_to_the_bench_process_group_stops_it_cleanly_with_a_partial_json() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    stopped_bench_leaves_nothing_and_keeps_its_episodes(dir.path(), &[libc::SIGINT], true);
}

#[test]
fn sigint_to_the_bench_alone_stops_it_cleanly_with_a_partial_json() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    stopped_bench_leaves_nothing_and_keeps_its_episodes(dir.path(), &[libc::SIGINT], false);
}

#[test]
fn sigterm_stops_the_bench_cleanly_with_a_partial_json_that_a_merge_takes_only_when_told() {
    let tmp = tempfile::tempdir().expect("a temporary folder");
    let dir = tmp.path();
    stopped_bench_leaves_nothing_and_keeps_its_episodes(dir, &[libc::SIGTERM], false);
    let merge = |extra: &[&str]| {
        let mut args = vec!["bench", "merge", "place.json", "--json", "merged.json"];
        args.extend_from_slice(extra);
        run_agp(dir, &args, TIMEOUT)
    };
    let refused = merge(&[]);
    assert!(!refused.status.success(), "{}", refused.stdout);
    assert!(
        refused.stderr.contains("partial") && refused.stderr.contains("--allow-partial"),
        "{}",
        refused.stderr
    );
    assert!(!dir.join("merged.json").exists());
    let taken = merge(&["--allow-partial"]);
    assert!(taken.status.success(), "{}", taken.stderr);
    assert_eq!(read_json(&dir.join("merged.json"))["partial"], true);
}

#[test]
fn a_second_sigint_stops_the_bench_at_once_and_still_leaves_nothing() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    stopped_bench_leaves_nothing_and_keeps_its_episodes(
        dir.path(),
        &[libc::SIGINT, libc::SIGINT],
        true,
    );
}

#[test]
fn the_next_bench_removes_what_a_bench_killed_with_sigkill_left_and_says_so() {
    let _turn = one_at_a_time();
    let dirs = [tempfile::tempdir(), tempfile::tempdir()].map(|d| d.expect("a temporary folder"));
    let mut first = Bench::start(dirs[0].path());
    first.wait_for_an_episode();
    let pid = first.pid();
    let children = children_of(pid);
    first.signal(libc::SIGKILL, false);
    let status = first.wait();
    assert_eq!(status.signal(), Some(libc::SIGKILL));
    // Its children die with it (they are killed when their parent dies).
    let deadline = Instant::now() + TIMEOUT;
    while children.iter().any(|&c| !process_is_gone(c)) && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(10));
    }
    assert!(
        !bench_files(pid).is_empty(),
        "a bench killed with -9 cannot clean: its pipelines' files stay"
    );
    // What it finished is in its checkpoint.
    let doc = read_json(&first.json_path());
    assert_eq!(doc["partial"], true, "{doc}");
    assert!(episodes_in(&doc) >= 1, "{doc}");

    let mut second = Bench::start(dirs[1].path());
    second.wait_for("leftover instance(s) of benches that died");
    let said = second
        .seen
        .iter()
        .find(|l| l.contains("leftover instance(s)"))
        .cloned()
        .unwrap_or_default();
    assert!(
        said.contains(&format!("bench-{pid}-")),
        "the second bench names what it removed: {said}"
    );
    let left = bench_files(pid);
    assert!(left.is_empty(), "files of the killed bench left: {left:?}");
    second.signal(libc::SIGTERM, false);
    let status = second.wait();
    assert_eq!(
        status.code(),
        Some(128 + libc::SIGTERM),
        "{}",
        second.stderr()
    );
    assert!(bench_files(second.pid()).is_empty());
}

#[test]
fn agp_down_stale_removes_what_a_bench_killed_with_sigkill_left_and_names_it() {
    let _turn = one_at_a_time();
    let dir = tempfile::tempdir().expect("a temporary folder");
    let mut bench = Bench::start(dir.path());
    bench.wait_for_an_episode();
    let pid = bench.pid();
    let children = children_of(pid);
    bench.signal(libc::SIGKILL, false);
    bench.wait();
    let deadline = Instant::now() + TIMEOUT;
    while children.iter().any(|&c| !process_is_gone(c)) && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(10));
    }
    assert!(
        !bench_files(pid).is_empty(),
        "a bench killed with -9 cannot clean: its pipelines' files stay"
    );
    let down = run_agp(dir.path(), &["down", "--stale"], TIMEOUT);
    assert!(down.status.success(), "{}", down.stderr);
    assert!(
        down.stdout.contains(&format!("bench-{pid}-")),
        "`agp down --stale` names what it removed: {}",
        down.stdout
    );
    let left = bench_files(pid);
    assert!(left.is_empty(), "files of the killed bench left: {left:?}");
}
