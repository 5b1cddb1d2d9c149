//! A recording opened with the field's own tools, without agp: `agp record` writes the
//! scene in Foxglove's protobuf schemas beside the raw channels, and
//!
//! - the stock decoders (`mcap` + `mcap-protobuf-support` from PyPI) decode every Foxglove
//!   channel of it;
//! - `agp export` adds the same channels to a recording made without them;
//! - Rerun (`rerun-sdk` from PyPI) loads it, the robot, the object and the IR as entities;
//! - Rerun's web viewer, served offline from the same package, shows the object in headless
//!   Chromium where the recording puts it (a screenshot, checked by its colours).
//!
//! One recording serves them all: a placement by the affordance planner on the triangle in
//! lockstep, recorded by `agp record --instance NAME` started apart from `agp up` (so the
//! run's description must come from the supervisor: issue 34).
//!
//! Needs `tools/setup.sh` (the venv .venv-ci with the pinned packages, npm packages,
//! chromium).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;
use std::time::Duration;

use agp_recording::{MESSAGE_ENCODING, Recording, TOPIC_COUNT};
use agp_tests::{AgpUp, LaunchDir, count_instance_files, learned_ag, run_agp};
use serde_json::Value;

/// Safety net of every wait; the checks never depend on it.
const TIMEOUT: Duration = Duration::from_secs(300);

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ sits in the workspace")
        .to_path_buf()
}

/// The venv's Python, or a failure naming the set-up line.
#[track_caller]
fn python() -> PathBuf {
    let py = repo().join(".venv-ci/bin/python");
    assert!(
        py.is_file(),
        "no .venv-ci: run tools/setup.sh (it makes the venv from tools/requirements-ci.txt)"
    );
    py
}

/// Runs a script of tools/ with the venv's Python; its stdout, or a failure with both
/// streams.
#[track_caller]
fn tool(script: &str, args: &[&str]) -> String {
    let out = Command::new(python())
        .arg(repo().join("tools").join(script))
        .args(args)
        .output()
        .expect("run the venv's Python");
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "tools/{script} failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    println!("tools/{script}:\n{stdout}");
    stdout
}

/// The placement's launch: physics, the estimator serving the learned triangle, and the
/// affordance planner, which starts once the recorder listens (`record.ready`).
fn launch(instance: &str, ag: &Path) -> String {
    agp_tests::gated_triangle_launch(
        instance,
        ag,
        "",
        "record.ready",
        "agp-planner",
        "--mode place --planner affordance",
    )
}

/// The recorded placement, made once for every test of this file.
struct Recorded {
    /// Its folder (under the target folder: it stays for a look after a failure).
    dir: PathBuf,
    mcap: PathBuf,
    /// What `agp record` printed.
    stdout: String,
}

fn recorded() -> &'static Recorded {
    static RECORDED: OnceLock<Recorded> = OnceLock::new();
    RECORDED.get_or_init(|| {
        let ag = learned_ag("triangle");
        let name = format!("fxr{}", std::process::id() % 100_000);
        let launch_dir = LaunchDir::new(&launch(&name, &ag));
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("foxglove_recording-{name}"));
        std::fs::create_dir_all(&dir).expect("the recording's folder");
        let mcap = dir.join("run.mcap");
        let mut up = AgpUp::start(&launch_dir.launch(), &[]);
        up.wait_for_lines("started", 3, TIMEOUT);
        // The recorder, started apart: no scenario, clock or seed on its command line.
        let mut record = AgpUp::spawn(
            launch_dir.path(),
            &[
                "record",
                "--instance",
                &name,
                mcap.to_str().expect("a UTF-8 path"),
            ],
        );
        record.wait_for_lines("agp: recording instance", 1, TIMEOUT);
        std::fs::write(launch_dir.path().join("record.ready"), b"").expect("the ready marker");
        let run = up.wait(TIMEOUT);
        run.assert_success("`agp up`");
        // The recorder ends when the instance went down.
        let record = record.wait(TIMEOUT);
        record.assert_success("`agp record`");
        assert_eq!(count_instance_files(&name), 0, "files of `{name}` remain");
        Recorded {
            dir,
            mcap,
            stdout: record.stdout,
        }
    })
}

#[test]
fn agp_record_started_apart_keeps_the_scenario_clock_and_seed_its_supervisor_gave_physics() {
    let rec = recorded();
    let file = Recording::open(&rec.mcap).expect("a readable recording");
    let run = file.run();
    println!("agp.run: {run:?}");
    assert_eq!(run.get("scenario").map(String::as_str), Some("triangle"));
    assert_eq!(run.get("clock").map(String::as_str), Some("lockstep"));
    let seed = agp_world::Scenario::builtin("triangle")
        .expect("the triangle")
        .task
        .seed;
    assert_eq!(run.get("seed"), Some(&seed.to_string()));
    assert!(run.contains_key("rate_hz"), "{run:?}");
}

#[test]
fn every_foxglove_channel_of_a_recorded_placement_decodes_with_the_stock_protobuf_decoder() {
    let rec = recorded();
    println!("agp record:\n{}", rec.stdout);
    let file = Recording::open(&rec.mcap).expect("a readable recording");
    // The raw channels stay, one per topic, for bit-exact replay.
    let raw = file
        .channels
        .iter()
        .filter(|c| c.message_encoding == MESSAGE_ENCODING)
        .count();
    assert_eq!(raw, TOPIC_COUNT);
    let json = rec.dir.join("decoded.json");
    tool(
        "foxglove_decode.py",
        &[
            rec.mcap.to_str().expect("a UTF-8 path"),
            "--json",
            json.to_str().expect("a UTF-8 path"),
        ],
    );
    let counts: Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("the counts")).expect("JSON");
    for (topic, schema) in [
        ("/tf", "foxglove.FrameTransforms"),
        ("/robot", "foxglove.SceneUpdate"),
        ("/ir", "foxglove.SceneUpdate"),
        ("/estimate", "foxglove.SceneUpdate"),
        ("/goal", "foxglove.SceneUpdate"),
        ("/robot/pose", "foxglove.PoseInFrame"),
        ("/estimate/pose", "foxglove.PoseInFrame"),
        ("/robot/points", "foxglove.PointCloud"),
        ("/ir/points", "foxglove.PointCloud"),
        ("/estimate/points", "foxglove.PointCloud"),
        ("/ag/grid", "foxglove.Grid"),
        ("/ag/image", "foxglove.RawImage"),
        ("/log", "foxglove.Log"),
    ] {
        let c = &counts[topic];
        assert_eq!(c["schema"], schema, "{topic}: {c}");
        assert_eq!(c["encoding"], "protobuf", "{topic}");
        assert_eq!(c["errors"], 0, "{topic}: {c}");
        let n = c["decoded"].as_u64().unwrap_or(0);
        assert!(n > 0, "{topic}: nothing decoded: {c}");
        assert_eq!(c["messages"], n, "{topic}");
    }
    // The AG layer once per set: the estimator published one set.
    assert_eq!(counts["/ag/grid"]["decoded"], 1);
    // The scene at 25 Hz of log time at most: not one per frame.
    let frames = counts["agp/ir_frames"]["messages"].as_u64().unwrap_or(0);
    let scenes = counts["/robot"]["decoded"].as_u64().unwrap_or(0);
    assert!(scenes < frames, "{scenes} scenes for {frames} frames");
}

/// `IN` without its Foxglove channels, as `agp record` wrote it before they existed.
fn strip_foxglove(input: &Path, output: &Path) {
    let file = Recording::open(input).expect("a readable recording");
    let out = std::fs::File::create(output).expect("create the stripped recording");
    let mut w = mcap::WriteOptions::new()
        .profile("agp")
        .create(std::io::BufWriter::new(out))
        .expect("an MCAP writer");
    for (name, metadata) in &file.metadata {
        if name.starts_with("agp.foxglove") {
            continue;
        }
        w.write_metadata(&mcap::records::Metadata {
            name: name.clone(),
            metadata: metadata.clone(),
        })
        .expect("metadata");
    }
    // Every raw channel, those without messages too, as the recorder lists them.
    let summary = mcap::Summary::read(file.bytes())
        .expect("a summary")
        .expect("a summary");
    let mut ids = std::collections::BTreeMap::new();
    let mut raw: Vec<_> = summary.channels.values().cloned().collect();
    raw.sort_by_key(|c| c.id);
    for c in raw
        .iter()
        .filter(|c| c.message_encoding == MESSAGE_ENCODING)
    {
        let s = c.schema.as_ref().expect("a schema");
        let schema = w
            .add_schema(&s.name, &s.encoding, &s.data)
            .expect("a schema");
        let id = w
            .add_channel(schema, &c.topic, &c.message_encoding, &c.metadata)
            .expect("a channel");
        ids.insert(c.id, id);
    }
    for m in file.messages().expect("messages") {
        if let Some(id) = ids.get(&m.channel.id) {
            let header = mcap::records::MessageHeader {
                channel_id: *id,
                sequence: m.sequence,
                log_time: m.log_time,
                publish_time: m.publish_time,
            };
            w.write_to_known_channel(&header, &m.data)
                .expect("a message");
        }
    }
    w.finish().expect("finish the stripped recording");
}

#[test]
fn agp_export_adds_the_same_foxglove_channels_to_a_recording_made_without_them() {
    let rec = recorded();
    let old = rec.dir.join("old.mcap");
    let new = rec.dir.join("exported.mcap");
    strip_foxglove(&rec.mcap, &old);
    let stripped = Recording::open(&old).expect("the stripped recording");
    assert_eq!(stripped.channels.len(), TOPIC_COUNT);
    let export = run_agp(
        &rec.dir,
        &[
            "export",
            old.to_str().expect("a UTF-8 path"),
            new.to_str().expect("a UTF-8 path"),
        ],
        TIMEOUT,
    );
    export.assert_success("`agp export`");
    println!("{}", export.stdout);
    // The same messages as the recorder wrote live: the tap is the same over the same
    // messages in the same order.
    let counts = |p: &Path| -> Vec<(String, String, u64)> {
        let r = Recording::open(p).expect("a readable recording");
        let mut v: Vec<_> = r
            .channels
            .iter()
            .map(|c| (c.topic.clone(), c.schema_name.clone(), c.messages))
            .collect();
        v.sort();
        v
    };
    let live = counts(&rec.mcap);
    let exported = counts(&new);
    assert_eq!(exported, live);
    assert_eq!(exported.len(), TOPIC_COUNT + agp_view_channel_count());
    // And the stock decoder reads them.
    tool("foxglove_decode.py", &[new.to_str().expect("a UTF-8 path")]);
    // Exporting an exported file writes its Foxglove channels anew, not twice.
    let again = rec.dir.join("exported-again.mcap");
    let export = run_agp(
        &rec.dir,
        &[
            "export",
            new.to_str().expect("a UTF-8 path"),
            again.to_str().expect("a UTF-8 path"),
        ],
        TIMEOUT,
    );
    export.assert_success("`agp export` of an exported file");
    assert_eq!(counts(&again), live);
}

/// The Foxglove channels `agp record` adds (agp_view::channels::ALL).
fn agp_view_channel_count() -> usize {
    13
}

#[test]
fn rerun_loads_the_recording_with_the_robot_the_object_and_the_ir_as_entities() {
    let rec = recorded();
    let rrd = rec.dir.join("run.rrd");
    let json = rec.dir.join("rerun.json");
    tool(
        "rerun_check.py",
        &[
            "entities",
            rec.mcap.to_str().expect("a UTF-8 path"),
            "--rrd",
            rrd.to_str().expect("a UTF-8 path"),
            "--json",
            json.to_str().expect("a UTF-8 path"),
        ],
    );
    let found: Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("the entities")).expect("JSON");
    let entities = found["entities"].as_object().expect("entities");
    for path in ["/robot/points", "/estimate/points", "/ir/points"] {
        let components = entities
            .get(path)
            .unwrap_or_else(|| panic!("no entity {path} in {found:#}"));
        let text = components.to_string();
        assert!(
            text.contains("Points3D:positions") && text.contains("Points3D:colors"),
            "{path}: {text}"
        );
    }
    for path in ["/robot/pose", "/estimate/pose", "/tf"] {
        assert!(entities.contains_key(path), "no entity {path} in {found:#}");
    }
}

#[test]
fn rerun_s_web_viewer_in_headless_chromium_shows_the_object_where_the_recording_puts_it() {
    let rec = recorded();
    let png = rec.dir.join("rerun-view.png");
    let node_modules = repo().join("tools/foxglove-client/node_modules/puppeteer-core");
    assert!(
        node_modules.is_dir(),
        "puppeteer-core is not installed: run tools/setup.sh (npm ci in tools/foxglove-client)"
    );
    assert!(
        Path::new("/usr/bin/chromium").is_file(),
        "no /usr/bin/chromium: run tools/setup.sh (apt-get install chromium)"
    );
    tool(
        "rerun_check.py",
        &[
            "browser",
            rec.mcap.to_str().expect("a UTF-8 path"),
            "--png",
            png.to_str().expect("a UTF-8 path"),
        ],
    );
    assert!(png.is_file());
}
