//! The soak: a long-running session of the release pipeline on the realtime clock, its
//! resident memory and its files watched from outside.
//!
//! `agp up` runs physics on the realtime clock (640 steps per second of wall time) and the
//! estimator reading and acknowledging every frame, until `agp down`; the supervisor's judge
//! records ground truth the whole time. No planner runs in it: the soak measures the
//! steady state of physics, the estimator and the supervisor on the realtime clock (a live
//! session with a planner serving goals, `agp-planner --mode serve`, is what `bench-faults`
//! runs in its live phase; the soak has not been run with one). Every few
//! seconds the soak reads the resident memory (`VmRSS` of `/proc/PID/status`) of the
//! supervisor and of every child, and counts the instance's files in `/dev/shm`. It reports
//! each process's mean resident memory over the first minute and over the last, their
//! ratio (the target: flat within 5 %), and the file count's range; then it brings the
//! session down and counts what the instance left.
//!
//! ```text
//! cargo build --release --workspace --bins
//! target/release/bench-soak --minutes 10 --json soak.json
//! ```

use std::collections::BTreeMap;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use agp_harness::pipeline::{
    Bins, LaunchSpec, Phase, Session, instance_files, is_interrupt, last_line_with, rss_kb,
    shm_file_count, sleep_checked,
};
use agp_runtime::install_shutdown_handler;
use anyhow::{Context, Result, bail};
use clap::Parser;
use serde_json::{Value, json};

/// Runs a realtime session for a while and reports its memory and files.
#[derive(Debug, Parser)]
#[command(version)]
struct Args {
    /// Folder of the release binaries (`agp`, `agp-physics`, `agp-estimator`,
    /// `agp-planner`) [default: the folder of this executable].
    #[arg(long, value_name = "DIR")]
    bin_dir: Option<PathBuf>,
    /// How long the session runs, minutes.
    #[arg(long, default_value_t = 10.0)]
    minutes: f64,
    /// Seconds between samples.
    #[arg(long, default_value_t = 5.0)]
    interval_s: f64,
    /// Also write the figures and every sample as JSON to this file.
    #[arg(long, value_name = "FILE")]
    json: Option<PathBuf>,
}

/// The window compared at each end of the soak, seconds.
const WINDOW_S: f64 = 60.0;

/// Largest drift of resident memory from the first minute to the last that counts as flat.
const FLAT_WITHIN: f64 = 0.05;

/// One process at one sample.
#[derive(Debug, Clone, Copy)]
struct ProcSample {
    pid: u32,
    rss_kb: u64,
    restarts: u32,
}

#[derive(Debug, Clone)]
struct Sample {
    t_s: f64,
    /// By process name (`supervisor`, then the children).
    procs: BTreeMap<String, ProcSample>,
    shm_files: usize,
}

fn main() {
    let args = Args::parse();
    install_shutdown_handler();
    match soak(&args) {
        Ok(None) => {}
        Ok(Some(missed)) => {
            eprintln!("bench-soak: targets missed: {missed}");
            std::process::exit(2);
        }
        Err(e) if is_interrupt(&e) => {
            eprintln!("bench-soak: interrupted; every process stopped, no file left");
            std::process::exit(130);
        }
        Err(e) => {
            eprintln!("bench-soak: error: {e:#}");
            std::process::exit(1);
        }
    }
}

/// Runs the soak and prints its figures; `Some(what)` when a target was missed (memory not
/// flat within 5 %, the file count not constant, a file left, `agp down` failed).
fn soak(args: &Args) -> Result<Option<String>> {
    check_args(args)?;
    let bins = Bins::new(args.bin_dir.clone())?;
    let work = tempfile::Builder::new()
        .prefix("bench-soak-")
        .tempdir()
        .context("cannot create a temporary folder")?;
    let instance = format!("soak{}", std::process::id() % 1_000_000);
    if !instance_files(&instance)?.is_empty() {
        bail!("instance `{instance}` already has files; remove them or run again");
    }
    let spec = LaunchSpec {
        phase: Phase::Live,
        instance: &instance,
        trials_per_alpha: 0,
        ag_file: None,
        max_restarts: 3,
    };
    let launch = spec.write(&bins, work.path())?;
    let mut session = Session::start(&bins, &instance, launch)?;
    wait_until_running(&mut session, Phase::Live.children())?;

    // The files of the last `agp status` (its node and its connection to the control
    // service) go within moments of its exit; the count starts once they have.
    sleep_checked(Duration::from_secs(2))?;
    let samples = sample_until_done(args, &mut session, &instance)?;

    // Down as a user brings it down; then what the instance left.
    let down_ok = session.down()?;
    let exit = session.sup().wait_exit(Duration::from_secs(30));
    let files_left = session.shut();
    let end = SoakEnd {
        instance: &instance,
        down_ok,
        exit: exit.and_then(|e| e.code()),
        files_left,
    };
    let report = Report::new(&samples);
    report.print(args, &end);
    if let Some(path) = &args.json {
        write_json(args, path, &report, &samples, &end)?;
    }
    Ok(report.missed(&end))
}

/// Refuses a soak length or interval out of range.
fn check_args(args: &Args) -> Result<()> {
    if !(args.minutes.is_finite() && args.minutes > 0.0 && args.minutes <= 24.0 * 60.0) {
        bail!(
            "--minutes {}: give a number of minutes above 0, at most a day",
            args.minutes
        );
    }
    if !(args.interval_s.is_finite() && (0.2..=600.0).contains(&args.interval_s)) {
        bail!("--interval-s {}: give 0.2 to 600 seconds", args.interval_s);
    }
    Ok(())
}

/// Waits (60 s at most) until every child of `children` runs and physics publishes.
fn wait_until_running(session: &mut Session<'_>, children: &[&str]) -> Result<()> {
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        if let Some(code) = session.ended() {
            bail!(
                "the session ended before it ran (status {code:?}){}",
                last_line_with(&session.dir, "up.err", "error")
                    .map(|l| format!(": {l}"))
                    .unwrap_or_default()
            );
        }
        if let Some(s) = session.status()?
            && s.all_running(children)
            && s.child("physics")
                .and_then(|p| p.rate_per_s)
                .is_some_and(|r| r > 0.0)
        {
            return Ok(());
        }
        if Instant::now() >= deadline {
            bail!("the session's children were not all running within 60 s");
        }
        sleep_checked(Duration::from_millis(100))?;
    }
}

/// Samples the session every `--interval-s` for `--minutes`, printing a line now and
/// then; fails if the session ends by itself.
fn sample_until_done(
    args: &Args,
    session: &mut Session<'_>,
    instance: &str,
) -> Result<Vec<Sample>> {
    let total = Duration::from_secs_f64(args.minutes * 60.0);
    let interval = Duration::from_secs_f64(args.interval_s);
    let started = Instant::now();
    let mut samples: Vec<Sample> = Vec::new();
    let mut next = started;
    loop {
        if let Some(code) = session.ended() {
            bail!(
                "the session ended by itself after {:.0} s (status {code:?}){}",
                started.elapsed().as_secs_f64(),
                last_line_with(&session.dir, "up.err", "error")
                    .map(|l| format!(": {l}"))
                    .unwrap_or_default()
            );
        }
        let sample = take_sample(session, instance, started.elapsed().as_secs_f64())?;
        show_progress(&sample, total, samples.len());
        samples.push(sample);
        if started.elapsed() >= total {
            break;
        }
        next += interval;
        let now = Instant::now();
        let until = next.min(started + total);
        if until > now {
            sleep_checked(until - now)?;
        }
    }
    if std::io::stderr().is_terminal() {
        eprintln!();
    }
    Ok(samples)
}

/// The instance's file count and the resident memory of the supervisor and of every
/// child `agp status` lists, at `t_s` into the soak.
fn take_sample(session: &mut Session<'_>, instance: &str, t_s: f64) -> Result<Sample> {
    // Counted before this sample's `agp status`, whose own node and connection are
    // files of the instance while it runs.
    let shm_files = shm_file_count(instance)?;
    let mut procs = BTreeMap::new();
    let sup_pid = session.sup().pid();
    if let Some(rss) = rss_kb(sup_pid) {
        procs.insert(
            "supervisor".to_owned(),
            ProcSample {
                pid: sup_pid,
                rss_kb: rss,
                restarts: 0,
            },
        );
    }
    if let Some(s) = session.status()? {
        for c in &s.processes {
            if let Some(pid) = c.pid
                && let Some(rss) = rss_kb(pid)
            {
                procs.insert(
                    c.name.clone(),
                    ProcSample {
                        pid,
                        rss_kb: rss,
                        restarts: c.restarts,
                    },
                );
            }
        }
    }
    Ok(Sample {
        t_s,
        procs,
        shm_files,
    })
}

/// The sample as a line on standard error: rewritten in place on a terminal, else every
/// twelfth (`taken` samples came before it).
fn show_progress(sample: &Sample, total: Duration, taken: usize) {
    let line = format!(
        "{:.0}/{:.0} s: {}; {} files in /dev/shm",
        sample.t_s,
        total.as_secs_f64(),
        sample
            .procs
            .iter()
            .map(|(n, p)| format!("{n} {:.1} MB", p.rss_kb as f64 / 1024.0))
            .collect::<Vec<_>>()
            .join(", "),
        sample.shm_files
    );
    if std::io::stderr().is_terminal() {
        eprint!("\r\x1b[2K{line}");
    } else if taken.is_multiple_of(12) {
        eprintln!("{line}");
    }
}

/// How the session ended: `agp down`, the supervisor's exit and what the instance left.
struct SoakEnd<'a> {
    instance: &'a str,
    down_ok: bool,
    /// The supervisor's exit status (`None`: killed by the tool).
    exit: Option<i32>,
    files_left: usize,
}

/// Writes the figures, every sample and how the session ended as JSON to `path`.
fn write_json(
    args: &Args,
    path: &Path,
    report: &Report,
    samples: &[Sample],
    end: &SoakEnd<'_>,
) -> Result<()> {
    let mut v = report.json(samples);
    v["instance"] = json!(end.instance);
    v["minutes"] = json!(args.minutes);
    v["interval_s"] = json!(args.interval_s);
    v["down_ok"] = json!(end.down_ok);
    v["exit"] = json!(end.exit);
    v["files_left"] = json!(end.files_left);
    let text = serde_json::to_string_pretty(&v).context("cannot format the JSON")?;
    std::fs::write(path, text + "\n").with_context(|| format!("cannot write {}", path.display()))
}

/// One process over the soak.
struct ProcFigures {
    first_kb: f64,
    last_kb: f64,
    min_kb: u64,
    max_kb: u64,
    /// Distinct pids it ran as.
    pids: usize,
    restarts: u32,
}

impl ProcFigures {
    fn ratio(&self) -> f64 {
        self.last_kb / self.first_kb
    }

    fn flat(&self) -> bool {
        (self.ratio() - 1.0).abs() <= FLAT_WITHIN
    }
}

struct Report {
    duration_s: f64,
    procs: BTreeMap<String, ProcFigures>,
    shm_min: usize,
    shm_max: usize,
    overlap: bool,
}

fn mean(v: &[u64]) -> f64 {
    v.iter().map(|&x| x as f64).sum::<f64>() / v.len().max(1) as f64
}

impl Report {
    fn new(samples: &[Sample]) -> Self {
        let duration_s = samples.last().map_or(0.0, |s| s.t_s);
        let mut names: Vec<&String> = samples.iter().flat_map(|s| s.procs.keys()).collect();
        names.sort();
        names.dedup();
        let mut procs = BTreeMap::new();
        for name in names {
            let series: Vec<(f64, ProcSample)> = samples
                .iter()
                .filter_map(|s| s.procs.get(name).map(|p| (s.t_s, *p)))
                .collect();
            let first: Vec<u64> = series
                .iter()
                .filter(|(t, _)| *t <= WINDOW_S)
                .map(|(_, p)| p.rss_kb)
                .collect();
            let last: Vec<u64> = series
                .iter()
                .filter(|(t, _)| *t >= duration_s - WINDOW_S)
                .map(|(_, p)| p.rss_kb)
                .collect();
            let mut pids: Vec<u32> = series.iter().map(|(_, p)| p.pid).collect();
            pids.sort_unstable();
            pids.dedup();
            procs.insert(
                name.clone(),
                ProcFigures {
                    first_kb: mean(&first),
                    last_kb: mean(&last),
                    min_kb: series.iter().map(|(_, p)| p.rss_kb).min().unwrap_or(0),
                    max_kb: series.iter().map(|(_, p)| p.rss_kb).max().unwrap_or(0),
                    pids: pids.len(),
                    restarts: series.iter().map(|(_, p)| p.restarts).max().unwrap_or(0),
                },
            );
        }
        Self {
            duration_s,
            procs,
            shm_min: samples.iter().map(|s| s.shm_files).min().unwrap_or(0),
            shm_max: samples.iter().map(|s| s.shm_files).max().unwrap_or(0),
            overlap: duration_s < 2.0 * WINDOW_S,
        }
    }

    fn print(&self, args: &Args, end: &SoakEnd<'_>) {
        let SoakEnd {
            instance,
            down_ok,
            exit,
            files_left,
        } = *end;
        println!(
            "soak of instance `{instance}`: {:.0} s of a realtime session (physics at 640 Hz wall clock, the estimator reading every frame, the judge recording; no planner), a sample every {:.1} s",
            self.duration_s, args.interval_s
        );
        if self.overlap {
            println!(
                "note: a soak shorter than two minutes compares overlapping windows: run `--minutes 10` for the figures"
            );
        }
        println!();
        println!(
            "{:<11} {:>15} {:>15} {:>8} {:>10} {:>10} {:>5} {:>8}  verdict",
            "process",
            "first min MB",
            "last min MB",
            "ratio",
            "min MB",
            "max MB",
            "pids",
            "restarts"
        );
        for (name, p) in &self.procs {
            println!(
                "{:<11} {:>15.2} {:>15.2} {:>8.4} {:>10.2} {:>10.2} {:>5} {:>8}  {}",
                name,
                p.first_kb / 1024.0,
                p.last_kb / 1024.0,
                p.ratio(),
                p.min_kb as f64 / 1024.0,
                p.max_kb as f64 / 1024.0,
                p.pids,
                p.restarts,
                if p.flat() {
                    "flat within 5 %"
                } else if p.ratio() > 1.0 {
                    "GROWS"
                } else {
                    "shrinks"
                }
            );
        }
        println!();
        println!(
            "files of the instance in /dev/shm: min {}, max {}{}",
            self.shm_min,
            self.shm_max,
            if self.shm_min == self.shm_max {
                " (constant)"
            } else {
                " (NOT constant)"
            }
        );
        println!(
            "`agp down`: {}; the supervisor exited with {}; files of the instance left after it: {files_left}",
            if down_ok { "ok" } else { "FAILED" },
            exit.map_or("no status (killed by the tool)".to_owned(), |c| format!(
                "status {c}"
            ))
        );
    }

    /// What missed its target, if anything: a process's memory not flat within 5 %, the
    /// file count not constant, a file left, `agp down` failed.
    fn missed(&self, end: &SoakEnd<'_>) -> Option<String> {
        let mut missed: Vec<String> = self
            .procs
            .iter()
            .filter(|(_, p)| !p.flat())
            .map(|(n, p)| format!("{n} {:+.1} %", (p.ratio() - 1.0) * 100.0))
            .collect();
        if self.shm_min != self.shm_max {
            missed.push(format!(
                "/dev/shm files {} to {}",
                self.shm_min, self.shm_max
            ));
        }
        if end.files_left > 0 {
            missed.push(format!("{} file(s) left", end.files_left));
        }
        if !end.down_ok {
            missed.push("`agp down` failed".to_owned());
        }
        (!missed.is_empty()).then(|| missed.join(", "))
    }

    fn json(&self, samples: &[Sample]) -> Value {
        let procs: BTreeMap<&String, Value> = self
            .procs
            .iter()
            .map(|(n, p)| {
                (
                    n,
                    json!({
                        "first_minute_rss_kb": p.first_kb,
                        "last_minute_rss_kb": p.last_kb,
                        "ratio": p.ratio(),
                        "flat_within_5_percent": p.flat(),
                        "min_rss_kb": p.min_kb,
                        "max_rss_kb": p.max_kb,
                        "pids": p.pids,
                        "restarts": p.restarts,
                    }),
                )
            })
            .collect();
        let samples: Vec<Value> = samples
            .iter()
            .map(|s| {
                json!({
                    "t_s": s.t_s,
                    "shm_files": s.shm_files,
                    "rss_kb": s.procs.iter().map(|(n, p)| (n.clone(), json!(p.rss_kb))).collect::<serde_json::Map<_, _>>(),
                })
            })
            .collect();
        json!({
            "duration_s": self.duration_s,
            "session": "physics on the realtime clock and the estimator reading every frame until `agp down`, no planner",
            "processes": procs,
            "shm_files_min": self.shm_min,
            "shm_files_max": self.shm_max,
            "samples": samples,
        })
    }
}
