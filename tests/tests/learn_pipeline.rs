//! The learning phase over the real pipeline: physics, `agp-estimator` and `agp-planner
//! --mode learn` under `agp up`, a few trials on the triangle. The run ends with status 0,
//! the estimator publishes the 51 grids of the affordance gradient (for each of alphas 0,
//! +15, -15 the paper's S, Px, Py, R+, R- and the twelve statistics a planner rebuilds the
//! gradient from, every header carrying its set and its alpha's counters) on the `grids`
//! topic and saves the AG file, which loads again (`agp-estimator --load` publishes the same
//! grids), and the instance leaves no file.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use agp_runtime::Instance;
use agp_shared_types::{GRID_CELLS, GRID_SIDE, GRIDS_PER_ALPHA, GridKind};
use agp_tests::{AgpUp, LaunchDir, bin_path, count_instance_files, triangle_learning_launch};
use agp_world::{ObjectShape, Scenario};

/// Safety net of every wait; the checks never depend on it.
const TIMEOUT: Duration = Duration::from_secs(120);

/// The learner's cell size, m (`agp_affordance::DEFAULT_CELL_SIZE_M`).
const CELL_SIZE_M: f64 = 0.002;

/// Trials per alpha: few, so the test stays short.
const TRIALS_PER_ALPHA: u32 = 6;

/// The learned alphas, whole degrees.
const ALPHAS_DEG: [i32; 3] = [-15, 0, 15];

/// Grids of one publication: every kind of every alpha.
const SET_GRIDS: usize = GRIDS_PER_ALPHA * ALPHAS_DEG.len();

/// What the test keeps of one received grid.
#[derive(Debug, Clone, PartialEq)]
struct GridSeen {
    seq: u64,
    alpha_count: u32,
    cell_size_m: f64,
    width: u32,
    height: u32,
    origin_m: (f64, f64),
    /// The alpha's layer as the header tells it: S's scale, largest rotation (rad), pushes
    /// and border points.
    layer: (f64, f64, u64, u64),
    /// Sum and number of non-zero cells: a fingerprint to compare two publications.
    sum: f64,
    nonzero: usize,
    /// The cells, to check the kinds of one alpha against each other.
    cells: Vec<f32>,
    /// Shape grids only: fraction of S's mass within `BORDER_BAND_M` of the true border,
    /// and its mass-weighted mean distance to the border, m.
    near_border: f64,
    mean_distance_m: f64,
}

/// Distance from `(x, y)` to segment `a`-`b`.
fn segment_distance(x: f64, y: f64, a: (f64, f64), b: (f64, f64)) -> f64 {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 {
        (((x - a.0) * dx + (y - a.1) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (x - a.0 - t * dx).hypot(y - a.1 - t * dy)
}

/// The triangle's vertices in its own frame (centroid at the origin), m.
fn triangle() -> Vec<(f64, f64)> {
    let scenario = Scenario::resolve("triangle").expect("the built-in triangle");
    let ObjectShape::Polygon(p) = &scenario.object.shape else {
        panic!("the triangle is a polygon");
    };
    p.vertices().iter().map(|v| (v.x, v.y)).collect()
}

/// S's mass counted as near the border within this distance: two of the learner's shape
/// Gaussians' sigma (2.5 mm), which hold 95 % of a Gaussian's mass across a straight face.
const BORDER_BAND_M: f64 = 0.005;

/// Reads the grids of `instance` until `count` arrived or `stop` is set; the node lives in
/// this thread only. Returns them by (kind, alpha in whole degrees).
fn collect_grids(
    instance: &str,
    count: usize,
    stop: Arc<AtomicBool>,
    subscribed: std::sync::mpsc::Sender<()>,
) -> BTreeMap<(u32, i32), GridSeen> {
    let instance = Instance::new(instance).expect("a valid name");
    let node = instance.node("test-grids", false).expect("a node");
    let topic = instance.grids(&node).expect("the grids topic");
    let subscriber = topic.subscriber().create().expect("a grid subscriber");
    subscribed.send(()).expect("the test waits");
    let border = triangle();
    let n = border.len();
    let mut seen = BTreeMap::new();
    let deadline = Instant::now() + TIMEOUT;
    while seen.len() < count && !stop.load(Ordering::SeqCst) && Instant::now() < deadline {
        let Ok(Some(g)) = subscriber.receive() else {
            std::thread::sleep(Duration::from_micros(500));
            continue;
        };
        let h = g.header;
        let (mut sum, mut nonzero, mut near, mut weighted) = (0.0, 0, 0.0, 0.0);
        for j in 0..GRID_SIDE {
            for i in 0..GRID_SIDE {
                let v = f64::from(g.cells[j * GRID_SIDE + i]);
                if v == 0.0 {
                    continue;
                }
                sum += v;
                nonzero += 1;
                if h.kind == GridKind::Shape as u32 {
                    let c = h.cell_size_m;
                    let x = h.origin_x_m + (i as f64 + 0.5) * c;
                    let y = h.origin_y_m + (j as f64 + 0.5) * c;
                    let d = (0..n)
                        .map(|k| segment_distance(x, y, border[k], border[(k + 1) % n]))
                        .fold(f64::INFINITY, f64::min);
                    weighted += v * d;
                    if d <= BORDER_BAND_M {
                        near += v;
                    }
                }
            }
        }
        let key = (h.kind, h.alpha_deg.round() as i32);
        seen.insert(
            key,
            GridSeen {
                seq: h.seq,
                alpha_count: h.alpha_count,
                cell_size_m: h.cell_size_m,
                width: h.width,
                height: h.height,
                origin_m: (h.origin_x_m, h.origin_y_m),
                layer: (h.shape_scale, h.max_rotation_rad, h.pushes, h.border_points),
                sum,
                nonzero,
                cells: g.cells.to_vec(),
                near_border: if sum > 0.0 { near / sum } else { 0.0 },
                mean_distance_m: if sum > 0.0 { weighted / sum } else { 0.0 },
            },
        );
    }
    seen
}

/// Checks the 51 grids of a learned triangle.
#[track_caller]
fn check_grids(grids: &BTreeMap<(u32, i32), GridSeen>) {
    assert_eq!(
        grids.len(),
        SET_GRIDS,
        "{GRIDS_PER_ALPHA} kinds x 3 alphas: {:?}",
        grids.keys()
    );
    let seq = grids.values().next().expect("a grid").seq;
    for kind in GridKind::ALL {
        for alpha in ALPHAS_DEG {
            let g = grids
                .get(&(kind as u32, alpha))
                .unwrap_or_else(|| panic!("no {kind:?} grid at alpha {alpha}"));
            assert_eq!(g.seq, seq, "one publication");
            assert_eq!(g.alpha_count, 3, "a set of three alphas");
            assert_eq!((g.width, g.height), (GRID_SIDE as u32, GRID_SIDE as u32));
            assert!((g.cell_size_m - CELL_SIZE_M).abs() < 1e-12);
            // Centred on the centroid: the origin is half the grid's side down and left.
            let half = -CELL_SIZE_M * GRID_SIDE as f64 / 2.0;
            assert!(
                (g.origin_m.0 - half).abs() < 1e-9 && (g.origin_m.1 - half).abs() < 1e-9,
                "origin {:?}",
                g.origin_m
            );
        }
    }
    for alpha in ALPHAS_DEG {
        let nonzero = |kind: GridKind| grids[&(kind as u32, alpha)].nonzero;
        for kind in [
            GridKind::Shape,
            GridKind::PositionX,
            GridKind::PositionY,
            GridKind::PushWeight,
            GridKind::DisplacementSqMean,
        ] {
            assert!(nonzero(kind) > 0, "{kind:?} at alpha {alpha} is empty");
        }
        check_layer(grids, alpha);
        // A few pushes may all turn the object one way: one of R+ and R- may be empty.
        assert!(
            nonzero(GridKind::RotationPos) + nonzero(GridKind::RotationNeg) > 0,
            "no rotation learned at alpha {alpha}"
        );
        let s = &grids[&(GridKind::Shape as u32, alpha)];
        println!(
            "S at alpha {alpha}: {:.1} % of the mass within {} mm of the true border, mean distance {:.2} mm",
            s.near_border * 100.0,
            BORDER_BAND_M * 1e3,
            s.mean_distance_m * 1e3
        );
        // S is Gaussians round border points seen by IR: most of its mass within two
        // sigma of the true border, and on average within about one sigma of it.
        assert!(
            s.near_border > 0.9,
            "S at alpha {alpha}: only {:.0} % of its mass within {} mm of the border",
            s.near_border * 100.0,
            BORDER_BAND_M * 1e3
        );
        assert!(
            s.mean_distance_m < 0.003,
            "S at alpha {alpha}: mean distance to the border {:.2} mm",
            s.mean_distance_m * 1e3
        );
    }
}

/// The grids of one alpha against each other and against their headers: one layer (the
/// same S scale and counters in every header, no more pushes than trials, S normalised by
/// its scale), and statistics a planner can predict from (every push weighs in R+'s or R-'s
/// weight, no mean rotation beyond the largest one, no negative variance).
#[track_caller]
fn check_layer(grids: &BTreeMap<(u32, i32), GridSeen>, alpha: i32) {
    let grid = |kind: GridKind| &grids[&(kind as u32, alpha)];
    let layer = grid(GridKind::Shape).layer;
    for kind in GridKind::ALL {
        assert_eq!(
            grid(kind).layer,
            layer,
            "{kind:?} at alpha {alpha}: another layer"
        );
    }
    let (shape_scale, max_rotation_rad, pushes, border_points) = layer;
    println!(
        "alpha {alpha}: {pushes} pushes, {border_points} border points, S scale {shape_scale:.1}, largest rotation {:.1} deg",
        max_rotation_rad.to_degrees()
    );
    assert!(
        (1..=u64::from(TRIALS_PER_ALPHA)).contains(&pushes),
        "alpha {alpha}: {pushes} pushes of {TRIALS_PER_ALPHA} trials"
    );
    assert!(border_points > 0 && shape_scale > 0.0);
    assert!(max_rotation_rad > 0.0 && max_rotation_rad < std::f64::consts::PI);
    let s_max = grid(GridKind::Shape)
        .cells
        .iter()
        .copied()
        .fold(0.0, f32::max);
    assert!(
        (s_max - 1.0).abs() < 1e-6,
        "S at alpha {alpha} peaks at {s_max}"
    );

    let cells = |kind: GridKind| &grid(kind).cells;
    let (w, wp, wn) = (
        cells(GridKind::PushWeight),
        cells(GridKind::RotationPosWeight),
        cells(GridKind::RotationNegWeight),
    );
    let (px, py, d2) = (
        cells(GridKind::PositionX),
        cells(GridKind::PositionY),
        cells(GridKind::DisplacementSqMean),
    );
    let (r, r2, rp, rn) = (
        cells(GridKind::Rotation),
        cells(GridKind::RotationSqMean),
        cells(GridKind::RotationPos),
        cells(GridKind::RotationNeg),
    );
    // f32 rounding of sums of a few unit-peak Gaussians and of their ratios.
    let tol = |x: f32| 1e-5 * x.abs() + 1e-7;
    let max_rot = max_rotation_rad as f32;
    for k in 0..GRID_CELLS {
        assert!(w[k] >= 0.0 && wp[k] >= 0.0 && wn[k] >= 0.0);
        assert!(
            (w[k] - wp[k] - wn[k]).abs() <= tol(w[k]),
            "alpha {alpha} cell {k}: push weight {} is not R+'s {} plus R-'s {}",
            w[k],
            wp[k],
            wn[k]
        );
        assert!(rp[k] >= 0.0 && rp[k] <= max_rot + tol(max_rot));
        assert!(rn[k] <= 0.0 && -rn[k] <= max_rot + tol(max_rot));
        assert!(r[k].abs() <= max_rot + tol(max_rot));
        if w[k] > 0.05 {
            let d2_mean = px[k] * px[k] + py[k] * py[k];
            assert!(
                d2[k] >= d2_mean - tol(d2[k]),
                "alpha {alpha} cell {k}: mean squared displacement {} below the squared mean {d2_mean}",
                d2[k]
            );
            assert!(
                r2[k] >= r[k] * r[k] - tol(r2[k]),
                "alpha {alpha} cell {k}: mean squared rotation {} below the squared mean {}",
                r2[k],
                r[k] * r[k]
            );
        }
    }
}

/// `agp-estimator --load FILE` on a fresh instance: the grids it publishes.
fn load_grids(instance: &str, file: &Path) -> BTreeMap<(u32, i32), GridSeen> {
    let stop = Arc::new(AtomicBool::new(false));
    let (tx, rx) = std::sync::mpsc::channel();
    let name = instance.to_owned();
    let reader = {
        let stop = stop.clone();
        std::thread::spawn(move || collect_grids(&name, SET_GRIDS, stop, tx))
    };
    rx.recv_timeout(TIMEOUT).expect("the reader subscribed");
    let mut estimator = Command::new(bin_path("agp-estimator"))
        .args(["--instance", instance, "--scenario", "triangle", "--load"])
        .arg(file)
        .spawn()
        .expect("start agp-estimator");
    let grids = reader.join().expect("the reader");
    let pid = libc::pid_t::try_from(estimator.id()).expect("a pid");
    // SAFETY: plain kill(2) of our own child, not reaped yet.
    assert_eq!(unsafe { libc::kill(pid, libc::SIGTERM) }, 0);
    let status = estimator.wait().expect("the estimator exits");
    assert!(status.success(), "agp-estimator --load: {status}");
    grids
}

#[test]
fn the_learning_phase_over_three_processes_publishes_and_saves_the_triangles_gradients() {
    let name = "t-learn-pipe";
    let dir = LaunchDir::new(&triangle_learning_launch(name, TRIALS_PER_ALPHA, ""));
    let mut up = AgpUp::start(&dir.launch(), &[]);
    up.wait_for_lines("started", 3, TIMEOUT);

    // The grids as the pipeline publishes them, read while the run goes on.
    let stop = Arc::new(AtomicBool::new(false));
    let (tx, rx) = std::sync::mpsc::channel();
    let reader = {
        let stop = stop.clone();
        std::thread::spawn(move || collect_grids(name, SET_GRIDS, stop, tx))
    };
    rx.recv_timeout(TIMEOUT).expect("the reader subscribed");
    let run = up.wait(TIMEOUT);
    stop.store(true, Ordering::SeqCst);
    let live = reader.join().expect("the reader");
    assert!(run.status.success(), "{}\n{}", run.stdout, run.stderr);
    let trials = 3 * TRIALS_PER_ALPHA as usize;
    assert!(
        run.stdout.contains(&format!(" of {trials}; grids seq 1")),
        "{}",
        run.stdout
    );
    check_grids(&live);
    assert_eq!(count_instance_files(name), 0, "the instance left files");

    // The AG file loads and gives the same grids.
    let file = dir.results().join("triangle.ag");
    assert!(file.is_file(), "no AG file at {}", file.display());
    let load_name = "t-learn-load";
    let loaded = load_grids(load_name, &file);
    check_grids(&loaded);
    for (key, g) in &live {
        let l = &loaded[key];
        assert_eq!((l.nonzero, l.sum), (g.nonzero, g.sum), "grid {key:?}");
        assert_eq!(l.layer, g.layer, "grid {key:?}");
    }
    let instance = Instance::new(load_name).expect("a valid name");
    instance
        .remove_files()
        .expect("remove the load instance's files");
}
