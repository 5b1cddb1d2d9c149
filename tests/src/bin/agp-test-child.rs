//! A stand-in process for `agp up` tests: joins the instance named in `AGP_INSTANCE` (a node
//! and a publisher, so it owns real files in /dev/shm), records its context, says `ready`,
//! then behaves as its arguments say:
//!
//! - `--exit-after-ms N --status S`: exits with status S after N ms; a non-zero status
//!   exits without dropping anything, as a crash would;
//! - `--until-signal`: waits for SIGTERM or SIGINT through iceoryx2's `Node::wait` (50 ms
//!   cycle), then drops its ports and exits 0;
//! - `--ignore-sigterm`: ignores SIGTERM and runs until killed.
//!
//! The record is one line appended to `$AGP_RESULTS/$AGP_PROCESS.log`:
//! `pid=.. AGP_INSTANCE=.. AGP_SCENARIO=.. ... args=..`.

use std::io::Write;
use std::process::ExitCode;
use std::time::Duration;

use agp_runtime::Instance;

enum Mode {
    ExitAfter { ms: u64, status: i32 },
    UntilSignal,
    IgnoreSigterm,
}

fn parse_args(args: &[String]) -> Result<Mode, String> {
    let mut mode = None;
    let mut exit_ms = None;
    let mut status = 0;
    let mut it = args.iter();
    while let Some(arg) = it.next() {
        let mut value = |flag: &str| {
            it.next()
                .ok_or_else(|| format!("`{flag}` needs a value"))
                .cloned()
        };
        match arg.as_str() {
            "--exit-after-ms" => {
                let v = value(arg)?;
                exit_ms = Some(v.parse().map_err(|_| format!("bad milliseconds `{v}`"))?);
            }
            "--status" => {
                let v = value(arg)?;
                status = v.parse().map_err(|_| format!("bad status `{v}`"))?;
            }
            "--until-signal" => mode = Some(Mode::UntilSignal),
            "--ignore-sigterm" => mode = Some(Mode::IgnoreSigterm),
            other => return Err(format!("unknown argument `{other}`")),
        }
    }
    match (mode, exit_ms) {
        (Some(m), None) => Ok(m),
        (None, Some(ms)) => Ok(Mode::ExitAfter { ms, status }),
        _ => Err(
            "give one of `--exit-after-ms N [--status S]`, `--until-signal`, `--ignore-sigterm`"
                .into(),
        ),
    }
}

/// Appends this process's context to `$AGP_RESULTS/$AGP_PROCESS.log`.
fn record(process: &str, args: &[String]) -> std::io::Result<()> {
    let Some(results) = std::env::var_os("AGP_RESULTS") else {
        return Ok(());
    };
    let mut line = format!("pid={}", std::process::id());
    for key in [
        "AGP_INSTANCE",
        "AGP_SCENARIO",
        "AGP_CLOCK",
        "AGP_RATE_HZ",
        "AGP_RESULTS",
        "AGP_PROCESS",
        "AGP_TEST_MARK",
    ] {
        let value = std::env::var(key).unwrap_or_default();
        line.push_str(&format!(" {key}={value}"));
    }
    line.push_str(&format!(" args={}", args.join(",")));
    let mut file = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(std::path::Path::new(&results).join(format!("{process}.log")))?;
    writeln!(file, "{line}")
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mode = match parse_args(&args) {
        Ok(m) => m,
        Err(e) => {
            eprintln!("agp-test-child: {e}");
            return ExitCode::from(2);
        }
    };
    if matches!(mode, Mode::IgnoreSigterm) {
        // SAFETY: setting a disposition to SIG_IGN installs no code.
        unsafe { libc::signal(libc::SIGTERM, libc::SIG_IGN) };
    }
    let process = std::env::var("AGP_PROCESS").unwrap_or_else(|_| "child".into());
    let Ok(name) = std::env::var("AGP_INSTANCE") else {
        eprintln!("agp-test-child: AGP_INSTANCE is not set");
        return ExitCode::from(2);
    };
    if let Err(e) = record(&process, &args) {
        eprintln!("agp-test-child {process}: cannot record the context: {e}");
        return ExitCode::from(2);
    }
    let instance = match Instance::new(&name) {
        Ok(i) => i,
        Err(e) => {
            eprintln!("agp-test-child {process}: {e}");
            return ExitCode::from(2);
        }
    };
    let node = match instance.node(&process, matches!(mode, Mode::UntilSignal)) {
        Ok(n) => n,
        Err(e) => {
            eprintln!("agp-test-child {process}: cannot create a node: {e:?}");
            return ExitCode::from(2);
        }
    };
    let frames = match instance.ir_frames(&node) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("agp-test-child {process}: {e}");
            return ExitCode::from(2);
        }
    };
    let publisher = match frames.data.publisher_builder().create() {
        Ok(p) => p,
        Err(e) => {
            eprintln!("agp-test-child {process}: cannot create a publisher: {e:?}");
            return ExitCode::from(2);
        }
    };
    println!(
        "agp-test-child {process}: ready, pid {}",
        std::process::id()
    );

    match mode {
        Mode::ExitAfter { ms, status } => {
            std::thread::sleep(Duration::from_millis(ms));
            if status != 0 {
                // A crash: nothing dropped, the supervisor cleans up.
                std::process::exit(status);
            }
        }
        Mode::UntilSignal => while node.wait(Duration::from_millis(50)).is_ok() {},
        Mode::IgnoreSigterm => loop {
            std::thread::sleep(Duration::from_millis(50));
        },
    }
    drop(publisher);
    drop(frames);
    drop(node);
    ExitCode::SUCCESS
}
