//! `agp view` seen by a stock client of the Foxglove WebSocket protocol: the protocol's
//! published npm package (`@foxglove/ws-protocol`'s `FoxgloveClient`, over `ws`, decoding
//! with the schemas the server advertises), run from tools/foxglove-client/client.cjs.
//!
//! Live: a lockstep pipeline of its own instance with `view = 0` in its launch file (the
//! supervisor runs `agp view` with the run, on a free port); the client receives the
//! scene topics, the robot where the scenario starts it, the IR rays and the AG layer;
//! after a goal, the goal and the object as the estimator believes it. `/dev/shm` is clean
//! after `agp down`.
//!
//! Replay: an MCAP recording written here in the recording's format is served by `agp view
//! FILE.mcap` over the same topics, its last scene held after its end.
//!
//! Needs node and the client's packages: `tools/foxglove-client/install.sh`.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use agp_shared_types::{
    GRID_CELLS, GRID_SIDE, GradientGrid, GridHeader, GridKind, IrFrame, ObjectEstimate, Pose2,
    ServiceNames, Task, TaskKind,
};
use agp_tests::{
    AgpUp, DownOnPanic, LaunchDir, count_instance_files, learned_ag, run_agp, triangle_ring_launch,
};
use agp_world::Scenario;
use serde_json::Value;

/// Safety net of every wait; the checks never depend on it.
const TIMEOUT: Duration = Duration::from_secs(240);

fn client_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ sits in the workspace")
        .join("tools/foxglove-client")
}

/// The client script, after checking node and its packages are there (one line says how
/// to get them if not).
#[track_caller]
fn client() -> PathBuf {
    let dir = client_dir();
    let node = Command::new("node").arg("--version").output();
    assert!(
        node.is_ok_and(|o| o.status.success()),
        "node is not installed: the Foxglove client needs node 20 or later (apt-get install nodejs npm)"
    );
    assert!(
        dir.join("node_modules/@foxglove/ws-protocol/package.json")
            .is_file(),
        "the Foxglove client's packages are not installed: run tools/foxglove-client/install.sh (npm ci)"
    );
    dir.join("client.cjs")
}

/// Runs the client against `url` until `requirements` are met, offering the stock
/// client's own subprotocol (`foxglove.websocket.v1`); its JSON dump.
#[track_caller]
fn receive(url: &str, requirements: &[&str], min_s: f64) -> Value {
    receive_offering(url, requirements, min_s, None)
}

/// [`receive`], offering `subprotocol` instead of the client's default when given.
#[track_caller]
fn receive_offering(
    url: &str,
    requirements: &[&str],
    min_s: f64,
    subprotocol: Option<&str>,
) -> Value {
    let mut cmd = Command::new("node");
    cmd.arg(client())
        .args(["--url", url, "--timeout-s", &TIMEOUT.as_secs().to_string()])
        .args(["--min-s", &min_s.to_string()]);
    if let Some(name) = subprotocol {
        cmd.args(["--subprotocol", name]);
    }
    for r in requirements {
        let flag = if r.contains(':') {
            "--require-entity"
        } else {
            "--require"
        };
        cmd.args([flag, r]);
    }
    let out = cmd.output().expect("run the Foxglove client");
    let text = String::from_utf8_lossy(&out.stdout);
    let dump: Value = serde_json::from_str(&text).unwrap_or_else(|e| {
        panic!(
            "the client printed no JSON ({e}): {}\nstderr: {}",
            text,
            String::from_utf8_lossy(&out.stderr)
        )
    });
    assert!(
        out.status.success(),
        "the client missed {}: {dump:#}",
        dump["missing"]
    );
    assert_eq!(dump["errors"], Value::Array(Vec::new()), "{dump:#}");
    dump
}

/// The `ws://` address in `agp view`'s "serving" line.
fn url_in(line: &str) -> String {
    let at = line.find("ws://").expect("a ws:// address");
    line[at..]
        .split_whitespace()
        .next()
        .expect("an address")
        .to_owned()
}

/// `x y theta` of an entity's `pose_mm_deg`.
fn pose_of(entity: &Value) -> (f64, f64, f64) {
    let text = entity["metadata"]["pose_mm_deg"]
        .as_str()
        .unwrap_or_else(|| panic!("no pose in {entity:#}"));
    let v: Vec<f64> = text
        .split_whitespace()
        .map(|s| s.parse().expect("a number"))
        .collect();
    (v[0], v[1], v[2])
}

/// The triangle's ring serving goals, with the view on any free port (`view = 0`).
fn launch(instance: &str, ag: &Path) -> String {
    triangle_ring_launch(
        instance,
        ag,
        "view = 0\n",
        r#""--mode", "serve", "--planner", "affordance""#,
        false,
    )
}

/// Every topic of `agp view` (agp_view::topics::ALL).
const VIEW_TOPICS: [&str; 7] = [
    "/robot",
    "/ir",
    "/estimate",
    "/goal",
    "/tf",
    "/ag/grid",
    "/ag/image",
];

/// The scene topics the live view publishes from its first frame on.
const SCENE: [&str; 7] = [
    "/robot",
    "/ir",
    "/tf",
    "/ag/grid",
    "/ag/image",
    "/robot:robot",
    "/ir:ir_rays",
];

#[test]
fn a_stock_foxglove_client_receives_the_live_scene_of_a_pipeline_and_its_goal() {
    let name = format!("fxv-{}", std::process::id());
    let ag = learned_ag("triangle");
    let dir = LaunchDir::new(&launch(&name, &ag));
    assert_eq!(count_instance_files(&name), 0);
    let _guard = DownOnPanic::new(dir.path(), &name);
    let mut up = AgpUp::start(&dir.launch(), &[]);
    let serving = up.wait_for_lines("agp view: serving", 1, TIMEOUT);
    let url = url_in(&serving[0]);
    up.wait_for_lines("serving the goals", 1, TIMEOUT);

    // Idle, wheels stopped: the robot where the scenario starts it. The client offers its
    // default subprotocol, the protocol's original name, as Lichtblick does.
    let dump = receive(&url, &SCENE, 0.0);
    assert_eq!(dump["offered"], "foxglove.websocket.v1", "{dump:#}");
    assert_eq!(dump["subprotocol"], "foxglove.websocket.v1", "{dump:#}");
    let scenario = Scenario::builtin("triangle").expect("the triangle");
    let start = scenario.robot.start;
    let robot = &dump["entities"]["/robot"]["robot"];
    let (x, y, theta) = pose_of(robot);
    assert!(
        (x - start.x * 1e3).abs() < 5.0 && (y - start.y * 1e3).abs() < 5.0,
        "the robot drawn at ({x}, {y}) mm, started at ({}, {}) mm",
        start.x * 1e3,
        start.y * 1e3
    );
    assert!(
        (theta - start.theta.to_degrees()).abs() < 3.0,
        "{theta} deg"
    );
    assert_eq!(robot["cylinders"].as_array().map(Vec::len), Some(1));
    assert_eq!(robot["frame_id"], "world");
    // Eight rays, two points each.
    let rays = &dump["entities"]["/ir"]["ir_rays"]["lines"][0];
    assert_eq!(rays["points"], 16, "{rays}");
    // The AG layer: 128 x 128 cells of five f32 fields in the object frame; an rgb8 image.
    let grid = &dump["topics"]["/ag/grid"];
    assert_eq!(grid["schemaName"], "foxglove.Grid");
    assert_eq!(grid["last"]["column_count"], 128, "{grid:#}");
    assert_eq!(grid["last"]["frame_id"], "object");
    assert_eq!(grid["last"]["data"]["bytes"], 128 * 128 * 20);
    let image = &dump["topics"]["/ag/image"]["last"];
    assert_eq!(
        (&image["width"], &image["height"], &image["encoding"]),
        (&Value::from(128), &Value::from(128), &Value::from("rgb8"))
    );
    let schemas: Vec<(String, String)> = dump["channels"]
        .as_array()
        .expect("channels")
        .iter()
        .map(|c| {
            (
                c["topic"].as_str().unwrap_or("").to_owned(),
                c["schemaName"].as_str().unwrap_or("").to_owned(),
            )
        })
        .collect();
    for (topic, schema) in [
        ("/robot", "foxglove.SceneUpdate"),
        ("/estimate", "foxglove.SceneUpdate"),
        ("/goal", "foxglove.SceneUpdate"),
        ("/tf", "foxglove.FrameTransforms"),
        ("/ag/image", "foxglove.RawImage"),
    ] {
        assert!(
            schemas.contains(&(topic.to_owned(), schema.to_owned())),
            "{topic} {schema} in {schemas:?}"
        );
    }
    println!("live view, idle:\n{dump:#}");

    // A goal: drawn at once, and the object once the first circling matched it.
    let goal = run_agp(
        dir.path(),
        &["goal", "--instance", &name, "--place", "300", "150", "90"],
        TIMEOUT,
    );
    assert!(goal.status.success(), "{}", goal.stderr);
    let dump = receive(
        &url,
        &[&SCENE[..], &["/goal:goal", "/estimate:object_estimate"]].concat(),
        0.0,
    );
    let texts = &dump["entities"]["/goal"]["goal"]["texts"];
    assert_eq!(
        texts[0], "goal 1: place at (300, 150) mm, 90 deg",
        "{texts}"
    );
    let object = &dump["entities"]["/estimate"]["object_estimate"];
    // The learned border at the estimated pose: a closed line and its fill.
    let outline = &object["lines"][0];
    assert_eq!(outline["type"], "LINE_LOOP", "{object:#}");
    assert!(outline["points"].as_u64().unwrap_or(0) >= 30, "{object:#}");
    assert!(
        !object["triangles"]
            .as_array()
            .expect("triangles")
            .is_empty()
    );
    // Where the estimator believes the object is: on its way from the start to the goal.
    let (ox, oy, _) = pose_of(object);
    let from = scenario.object.start.position() * 1e3;
    let to = glam::DVec2::new(300.0, 150.0);
    let p = glam::DVec2::new(ox, oy);
    let along = ((p - from).dot(to - from) / (to - from).length_squared()).clamp(0.0, 1.0);
    let off = (p - (from + along * (to - from))).length();
    assert!(
        off < 100.0,
        "the object estimated at ({ox}, {oy}) mm, {off} mm off its way from {from} to {to}"
    );
    println!("live view, with a goal:\n{dump:#}");
    // Every channel the view advertises had messages, on the stock client's default
    // subprotocol.
    let advertised: Vec<&str> = dump["channels"]
        .as_array()
        .expect("channels")
        .iter()
        .filter_map(|c| c["topic"].as_str())
        .collect();
    assert_eq!(advertised.len(), VIEW_TOPICS.len(), "{advertised:?}");
    for topic in VIEW_TOPICS {
        let count = dump["topics"][topic]["count"].as_u64().unwrap_or(0);
        assert!(count > 0, "no message on {topic}: {dump:#}");
        println!(
            "stock client ({}): {topic}: {count} messages",
            dump["subprotocol"]
        );
    }

    let down = run_agp(dir.path(), &["down", "--instance", &name], TIMEOUT);
    assert!(down.status.success(), "{}", down.stderr);
    let done = up.wait(TIMEOUT);
    assert!(done.status.success(), "{}\n{}", done.stdout, done.stderr);
    assert_eq!(count_instance_files(&name), 0, "files of `{name}` left");
}

/// Writes an MCAP recording in the recording's format (one channel per topic, named by
/// its service, schema named by the payload's type name, raw `#[repr(C)]` bytes): the task,
/// one AG layer whose S is a ring of radius `RING_M`, and 1 s of frames and estimates at
/// 100 Hz in which the robot drives 100 mm along x and the object is estimated at
/// (300, 150) mm, 30 deg, within 4 mm and 2 deg.
const RING_M: f64 = 0.04;

fn bytes_of<T>(v: &T) -> &[u8] {
    // SAFETY: the payloads are #[repr(C)] without implicit padding: every byte is set.
    unsafe { std::slice::from_raw_parts((v as *const T).cast::<u8>(), size_of::<T>()) }
}

fn write_recording(path: &Path) {
    use std::collections::BTreeMap;
    let file = std::io::BufWriter::new(std::fs::File::create(path).expect("create the recording"));
    let mut out = mcap::Writer::new(file).expect("an MCAP writer");
    let mut channel = |topic: &str, type_name: &str| {
        let schema = out
            .add_schema(type_name, "agp-repr-c-layout", b"")
            .expect("a schema");
        out.add_channel(schema, topic, "agp-repr-c", &BTreeMap::new())
            .expect("a channel")
    };
    let task_ch = channel(ServiceNames::TASK, "agp::Task.v2");
    let grid_ch = channel(ServiceNames::GRIDS, "agp::GradientGrid.v2");
    let frame_ch = channel(ServiceNames::IR_FRAMES, "agp::IrFrame.v2");
    let est_ch = channel(ServiceNames::ESTIMATES, "agp::ObjectEstimate.v4");
    let t0: u64 = 1_800_000_000_000_000_000;
    let mut seq = 0u32;
    let mut write = |out: &mut mcap::Writer<_>, ch: u16, t: u64, data: &[u8]| {
        seq += 1;
        out.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: ch,
                sequence: seq,
                log_time: t,
                publish_time: t,
            },
            data,
        )
        .expect("write a message");
    };
    let task = Task {
        kind: TaskKind::Place as u32,
        path_len: 0,
        goal: Pose2::new(0.3, 0.15, 90f64.to_radians()),
        tolerance_m: 0.01,
        tolerance_rad: 10f64.to_radians(),
        path: [[0.0; 2]; 32],
        max_pushes: 40,
        _pad: 0,
        seed: 7,
        heading_tolerance_rad: 0.0,
    };
    write(&mut out, task_ch, t0, bytes_of(&task));
    let cell = 0.002;
    let origin = -(GRID_SIDE as f64) * cell / 2.0;
    for kind in GridKind::ALL {
        let mut grid = Box::new(GradientGrid {
            header: GridHeader {
                seq: 1,
                kind: kind as u32,
                alpha_count: 1,
                width: GRID_SIDE as u32,
                height: GRID_SIDE as u32,
                alpha_deg: 0.0,
                cell_size_m: cell,
                origin_x_m: origin,
                origin_y_m: origin,
                shape_scale: 1.0,
                ..GridHeader::default()
            },
            cells: [0.0; GRID_CELLS],
        });
        if kind == GridKind::Shape {
            for j in 0..GRID_SIDE {
                for i in 0..GRID_SIDE {
                    let x = origin + (i as f64 + 0.5) * cell;
                    let y = origin + (j as f64 + 0.5) * cell;
                    let d = ((x * x + y * y).sqrt() - RING_M) / cell;
                    grid.cells[j * GRID_SIDE + i] = (-d * d).exp() as f32;
                }
            }
        }
        write(&mut out, grid_ch, t0, bytes_of(&*grid));
    }
    for k in 0..=100u64 {
        let t = t0 + k * 10_000_000;
        let robot = Pose2::new(k as f64 * 0.001, 0.0, 0.0);
        let frame = IrFrame {
            step: k,
            ir_raw: [100.0; 8],
            ..IrFrame::default()
        };
        write(&mut out, frame_ch, t, bytes_of(&frame));
        let e = ObjectEstimate {
            step: k,
            robot,
            pose: Pose2::new(0.3, 0.15, 30f64.to_radians()),
            sigma_xy: 0.004,
            sigma_theta: 2f64.to_radians(),
            valid: 1,
            ..ObjectEstimate::default()
        };
        write(&mut out, est_ch, t, bytes_of(&e));
    }
    out.finish().expect("finish the recording");
}

#[test]
fn a_stock_foxglove_client_receives_a_recording_served_by_agp_view_paced_by_its_log_times() {
    let client = client();
    let dir = tempfile::tempdir().expect("a temporary folder");
    let path = dir.path().join("run.mcap");
    write_recording(&path);
    let mut view = AgpUp::spawn(
        dir.path(),
        &["view", path.to_str().expect("a UTF-8 path"), "--port", "0"],
    );
    let serving = view.wait_for_lines("agp view: serving", 1, TIMEOUT);
    let url = url_in(&serving[0]);
    assert!(client.is_file());
    // 1 s of log time: the client stays until past its end, and sees the last scene. It
    // offers the SDK's name for the protocol, which the view still takes.
    let dump = receive_offering(
        &url,
        &[
            "/robot:robot",
            "/estimate:object_estimate",
            "/goal:goal",
            "/ag/grid",
        ],
        1.5,
        Some("foxglove.sdk.v1"),
    );
    assert_eq!(dump["subprotocol"], "foxglove.sdk.v1", "{dump:#}");
    let (x, y, _) = pose_of(&dump["entities"]["/robot"]["robot"]);
    assert!((x - 100.0).abs() < 1e-6 && y.abs() < 1e-6, "({x}, {y}) mm");
    let object = &dump["entities"]["/estimate"]["object_estimate"];
    let (ox, oy, otheta) = pose_of(object);
    assert!(
        (ox - 300.0).abs() < 1e-3 && (oy - 150.0).abs() < 1e-3 && (otheta - 30.0).abs() < 1e-3,
        "({ox}, {oy}) mm, {otheta} deg"
    );
    assert_eq!(object["metadata"]["sigma_xy_mm"], "4.000");
    // The learned border: the ring, one point every 4 degrees.
    assert_eq!(object["lines"][0]["points"], 90);
    // The server's clock follows the recording: it ends at the last log time.
    assert_eq!(
        dump["server"]["capabilities"],
        serde_json::json!(["time"]),
        "{dump:#}"
    );
    let last = dump["time"].as_f64().expect("a time");
    assert!((last - 1_800_000_001_000_000_000f64).abs() < 1e6, "{last}");
    println!("replay:\n{dump:#}");
    view.signal(libc::SIGTERM);
    let done = view.wait(TIMEOUT);
    assert!(done.status.success(), "{}\n{}", done.stdout, done.stderr);
    assert!(
        done.stdout.contains(&format!(
            "read 101 estimates, 101 IR frames, {} grids",
            GridKind::ALL.len()
        )),
        "{}",
        done.stdout
    );
}
