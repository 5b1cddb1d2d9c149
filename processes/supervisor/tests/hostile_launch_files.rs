//! Launch files written to do harm: absurd rates, restart counts and delays, a FIFO or
//! `/dev/zero` in place of the file or of its scenario. Each is refused with the file, the
//! line and the limit; random mutations of a good file never panic.

use std::path::Path;
use std::sync::mpsc;
use std::time::Duration;

use agp_launch::{
    LaunchConfig, LaunchConfigParseError, LaunchFaultKind, LaunchOptions, RemoteChecks,
};
use proptest::prelude::*;

const GOOD: &str = r#"instance = "t-hostile"
scenario = "arena.toml"

[clock]
mode = "lockstep"
rate_hz = 640

[[process]]
name = "physics"
exec = "agp-fake"
args = ["--seed", "7"]
env = { RUST_LOG = "info" }
restart = { policy = "on-failure", max_restarts = 5, backoff_ms = 50 }

[[process]]
name = "planner"
exec = "agp-fake"
ends_run = true
stop_grace_ms = 500
"#;

#[path = "../../../libs/launch/tests/fixture/mod.rs"]
mod fixture;
use fixture::Fixture;

/// A folder with an executable `bin/agp-fake` and a valid scenario `arena.toml`, its
/// launch files parsed with the bridge's checks.
fn new_fixture() -> Fixture {
    Fixture::new(&["bin/agp-fake"], Some(agp_supervisor::BRIDGE_CHECKS))
}

/// GOOD with `from` replaced by `to`, refused with one fault: its line and the shown
/// error, which starts with the file's path.
#[track_caller]
fn refused(fx: &Fixture, from: &str, to: &str) -> (Option<usize>, String) {
    assert!(GOOD.contains(from), "test setup: `{from}` not in the file");
    let (line, shown, _) = fx.fault(&GOOD.replacen(from, to, 1));
    assert!(
        shown.starts_with(&fx.file().display().to_string()),
        "{shown}"
    );
    (line, shown)
}

fn without_hanging<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(f());
    });
    rx.recv_timeout(Duration::from_secs(20))
        .expect("the load blocked (or read without end)")
}

fn make_fifo(path: &Path) {
    let c = std::ffi::CString::new(path.as_os_str().as_encoded_bytes()).expect("no NUL");
    // SAFETY: mkfifo(3) on a NUL-terminated path this test owns.
    let rc = unsafe { libc::mkfifo(c.as_ptr(), 0o600) };
    assert_eq!(rc, 0, "mkfifo: {}", std::io::Error::last_os_error());
}

#[test]
fn the_file_these_tests_mutate_is_valid() {
    let fx = new_fixture();
    fx.parse(GOOD).expect("valid");
}

#[test]
fn a_rate_of_1e12_or_0_001_hz_is_refused_naming_the_limit() {
    let fx = new_fixture();
    for bad in ["1e12", "0.001", "-640", "nan", "inf"] {
        let (line, shown) = refused(&fx, "rate_hz = 640", &format!("rate_hz = {bad}"));
        assert_eq!(line, Some(6), "{shown}");
        assert!(
            shown.contains("`rate_hz` must be a positive number")
                && shown.contains("from 1 to 100000"),
            "{shown}"
        );
    }
    for ok in ["1", "100000"] {
        fx.parse(&GOOD.replace("rate_hz = 640", &format!("rate_hz = {ok}")))
            .expect("a rate at the limit");
    }
}

#[test]
fn a_huge_restart_count_backoff_or_stop_grace_is_refused_naming_the_limit() {
    let fx = new_fixture();
    let cases = [
        (
            "max_restarts = 5",
            "max_restarts = 4000000000",
            13,
            "`max_restarts` must be at most 1000",
        ),
        (
            "backoff_ms = 50",
            "backoff_ms = 18446744073709551615",
            13,
            "`backoff_ms` must be at most 60000 ms",
        ),
        (
            "stop_grace_ms = 500",
            "stop_grace_ms = 99999999",
            19,
            "`stop_grace_ms` must be at most 60000 ms",
        ),
        (
            "args = [\"--seed\", \"7\"]",
            "args = [\"--seed\", \"7\\u0000\"]",
            11,
            "argument 2 with a NUL byte",
        ),
    ];
    for (from, to, want, words) in cases {
        let (line, shown) = refused(&fx, from, to);
        assert_eq!(line, Some(want), "{shown}");
        assert!(shown.contains(words), "`{shown}` does not say {words}");
    }
    let many: String = (0..40)
        .map(|k| format!("[[process]]\nname = \"p{k}\"\nexec = \"agp-fake\"\n"))
        .collect();
    let err = fx
        .parse(&format!("{GOOD}{many}"))
        .expect_err("42 processes");
    assert!(
        err.to_string()
            .contains("`process` must be at most 32 entries"),
        "{err}"
    );
}

#[test]
fn a_fifo_as_a_launch_file_is_refused_without_blocking() {
    let fx = new_fixture();
    let fifo = fx.path().join("fifo.toml");
    make_fifo(&fifo);
    let options = fx.options();
    let shown = {
        let fifo = fifo.clone();
        without_hanging(move || LaunchConfig::load(&fifo, &options).map(|_| ()))
    }
    .expect_err("a FIFO is no launch file")
    .to_string();
    assert!(
        shown.starts_with(&fifo.display().to_string())
            && shown.contains("not a regular file but a FIFO"),
        "{shown}"
    );
}

#[test]
fn a_link_to_dev_zero_as_a_launch_file_is_refused_without_reading() {
    let fx = new_fixture();
    let link = fx.path().join("zero.toml");
    std::os::unix::fs::symlink("/dev/zero", &link).expect("symlink");
    let options = fx.options();
    let err = without_hanging(move || LaunchConfig::load(&link, &options).map(|_| ()))
        .expect_err("/dev/zero is no launch file");
    assert!(
        matches!(err.faults[0].kind, LaunchFaultKind::Read(_)),
        "{err}"
    );
    let shown = err.to_string();
    assert!(
        shown.contains("zero.toml") && shown.contains("a character device"),
        "{shown}"
    );
}

#[test]
fn a_fifo_as_the_scenario_of_a_launch_file_is_refused_without_blocking() {
    let fx = new_fixture();
    make_fifo(&fx.path().join("pipe.toml"));
    let file = fx.file();
    let options = fx.options();
    let text = GOOD.replace("arena.toml", "pipe.toml");
    let err = without_hanging(move || LaunchConfig::parse(&text, &file, &options).map(|_| ()))
        .expect_err("a FIFO is no scenario");
    let shown = err.to_string();
    assert_eq!(err.faults[0].line, Some(2), "{shown}");
    assert!(
        shown.contains("pipe.toml") && shown.contains("not a regular file but a FIFO"),
        "{shown}"
    );
}

/// One edit of a launch file's text.
#[derive(Debug, Clone)]
enum Edit {
    DeleteLine(usize),
    ReplaceValue(usize, String),
    InsertLine(usize, String),
    Truncate(usize),
}

fn hostile_value() -> impl Strategy<Value = String> {
    prop_oneof![
        Just("1e300".to_owned()),
        Just("-1".to_owned()),
        Just("nan".to_owned()),
        Just("0".to_owned()),
        Just("18446744073709551615".to_owned()),
        Just("-9223372036854775808".to_owned()),
        Just("\"../../etc/passwd\"".to_owned()),
        Just("\"/dev/zero\"".to_owned()),
        Just("\"\"".to_owned()),
        Just("[]".to_owned()),
        Just("{}".to_owned()),
        Just("{ policy = \"always\", max_restarts = 4294967295, backoff_ms = 1 }".to_owned()),
        Just("\"a\\u0000b\"".to_owned()),
        any::<f64>().prop_map(|x| format!("{x:?}")),
        any::<i64>().prop_map(|x| x.to_string()),
        "[ -~]{0,12}",
        "\\PC{0,6}",
    ]
}

fn edit() -> impl Strategy<Value = Edit> {
    prop_oneof![
        (0..25usize).prop_map(Edit::DeleteLine),
        (0..25usize, hostile_value()).prop_map(|(k, v)| Edit::ReplaceValue(k, v)),
        (0..25usize, "[ -~]{0,20}").prop_map(|(k, v)| Edit::InsertLine(k, v)),
        (0..GOOD.len()).prop_map(Edit::Truncate),
    ]
}

fn apply(text: &str, edits: &[Edit]) -> String {
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    let mut cut = None;
    for e in edits {
        let n = lines.len().max(1);
        match e {
            Edit::DeleteLine(k) if !lines.is_empty() => {
                lines.remove(k % n);
            }
            Edit::ReplaceValue(k, v) if !lines.is_empty() => {
                let line = &mut lines[k % n];
                if let Some(eq) = line.find('=') {
                    line.truncate(eq + 1);
                    line.push(' ');
                    line.push_str(v);
                }
            }
            Edit::InsertLine(k, v) => lines.insert(k % (lines.len() + 1), v.clone()),
            Edit::Truncate(at) => cut = Some(*at),
            _ => {}
        }
    }
    let mut out = lines.join("\n");
    if let Some(at) = cut {
        let mut at = at.min(out.len());
        while !out.is_char_boundary(at) {
            at -= 1;
        }
        out.truncate(at);
    }
    out
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn a_mutated_launch_file_never_panics_and_every_fault_names_the_file_and_its_line(
        edits in proptest::collection::vec(edit(), 1..4)
    ) {
        let fx = new_fixture();
        let text = apply(GOOD, &edits);
        if let Err(err) = fx.parse(&text) {
            let file = fx.file().display().to_string();
            let shown = err.to_string();
            prop_assert_eq!(shown.lines().count(), err.faults.len(), "{}", shown);
            for (fault, line) in err.faults.iter().zip(shown.lines()) {
                prop_assert!(line.starts_with(&file), "{}", line);
                let placeless = matches!(
                    fault.kind,
                    LaunchFaultKind::NoInstance | LaunchFaultKind::NoProcess
                );
                match fault.line {
                    Some(l) => prop_assert!(l >= 1 && l <= text.lines().count() + 1, "line {} of {}", l, text),
                    None => prop_assert!(placeless || matches!(fault.kind, LaunchFaultKind::Toml(_)), "no line: {}", line),
                }
            }
        }
    }
}
