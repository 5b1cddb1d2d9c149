//! AG files written to do harm: absurd alphas behind a good checksum, another object's
//! gradient, a FIFO or `/dev/zero` in place of a file, impossible statistics. Each is
//! refused naming the file, the field and the limit; random corruptions never panic.

use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Duration;

use agp_affordance::{
    AffordanceGradient, AffordanceLearner, AgFileLoadError, CELL_SIZE_M, LearnerConfig,
    MAX_AG_FILE_BYTES, MAX_ALPHA_DEG, MAX_ALPHAS, PushOutcome,
};
use agp_shared_types::GRID_CELLS;
use glam::DVec2;
use proptest::prelude::*;

/// A small learned gradient of `triangle` at the default three alphas.
fn gradient() -> AffordanceGradient {
    let config = LearnerConfig::default();
    let mut learner = AffordanceLearner::new("triangle", &config).expect("valid config");
    for &alpha in &config.alphas_deg {
        for k in 0..12 {
            let phi = std::f64::consts::TAU * k as f64 / 12.0;
            let c = DVec2::from_angle(phi) * 0.03;
            let push = PushOutcome {
                contact_point_obj: c,
                displacement_obj: -c * 0.5,
                rotation_rad: 0.3 * (3.0 * phi).sin(),
                heading_obj: -c,
            };
            learner.add_push(alpha, &push).expect("learned alpha");
            learner.add_border_point(alpha, c).expect("learned alpha");
        }
    }
    learner.into_gradient()
}

/// The bytes of [`gradient`]'s file, made once.
fn good_bytes() -> &'static [u8] {
    static BYTES: std::sync::OnceLock<Vec<u8>> = std::sync::OnceLock::new();
    BYTES.get_or_init(|| {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("triangle.ag");
        gradient().save(&path).expect("writable temp dir");
        std::fs::read(&path).expect("just written")
    })
}

/// Byte offsets of the header's fields (the format of `AffordanceGradient::save`).
const CELL_SIZE_AT: usize = 14;
const ALPHA_COUNT_AT: usize = 22;
const ALPHAS_AT: usize = 26;
const ALPHAS: usize = 3;
const NAME_LEN_AT: usize = ALPHAS_AT + 8 * ALPHAS;
const NAME_AT: usize = NAME_LEN_AT + 4;
const GRIDS_AT: usize = NAME_AT + "triangle".len();
const GRID_BYTES: usize = GRID_CELLS * 4;
const TAILS_AT: usize = GRIDS_AT + ALPHAS * 17 * GRID_BYTES;

fn fnv1a64(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325_u64, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// Sets the trailing checksum to match the (edited) contents.
fn reseal(bytes: &mut [u8]) {
    let n = bytes.len() - 8;
    let sum = fnv1a64(&bytes[..n]);
    bytes[n..].copy_from_slice(&sum.to_le_bytes());
}

/// An edit of a file's bytes.
type Edit = Box<dyn FnOnce(&mut Vec<u8>)>;

/// The good file with `edit` applied and the checksum fixed, loaded from `dir/name`.
fn load_edited(
    dir: &Path,
    name: &str,
    edit: impl FnOnce(&mut Vec<u8>),
) -> (PathBuf, Result<AffordanceGradient, AgFileLoadError>) {
    let mut bytes = good_bytes().to_vec();
    edit(&mut bytes);
    reseal(&mut bytes);
    let path = dir.join(name);
    std::fs::write(&path, &bytes).expect("write");
    let loaded = AffordanceGradient::load(&path);
    (path, loaded)
}

#[track_caller]
fn refusal(path: &Path, loaded: Result<AffordanceGradient, AgFileLoadError>) -> String {
    let shown = loaded
        .expect_err("an impossible file was accepted")
        .to_string();
    assert!(
        shown.contains(&path.display().to_string()),
        "`{shown}` does not name the file"
    );
    shown
}

fn without_hanging<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(f());
    });
    rx.recv_timeout(Duration::from_secs(20))
        .expect("the load blocked (or read without end)")
}

#[test]
fn the_good_file_loads() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (_, loaded) = load_edited(dir.path(), "good.ag", |_| {});
    assert_eq!(loaded.expect("valid").object_name(), "triangle");
}

#[test]
fn an_ag_file_with_an_alpha_of_1e300_or_1000_deg_is_refused_naming_the_limit() {
    let dir = tempfile::tempdir().expect("temp dir");
    for (k, alpha) in [1e300, 1000.0, -90.5, f64::MAX].into_iter().enumerate() {
        let (path, loaded) = load_edited(dir.path(), &format!("alpha{k}.ag"), |b| {
            b[ALPHAS_AT + 8..ALPHAS_AT + 16].copy_from_slice(&alpha.to_le_bytes());
        });
        let shown = refusal(&path, loaded);
        assert!(
            shown.contains("alpha 2") && shown.contains("|alpha| <= 90 deg"),
            "{shown}"
        );
    }
    // Two alphas closer than the gradient tells apart are one alpha repeated.
    let (path, loaded) = load_edited(dir.path(), "twice.ag", |b| {
        let first: [u8; 8] = b[ALPHAS_AT..ALPHAS_AT + 8].try_into().expect("8 bytes");
        b[ALPHAS_AT + 8..ALPHAS_AT + 16].copy_from_slice(&first);
    });
    assert!(refusal(&path, loaded).contains("repeated"));
    assert_eq!(MAX_ALPHA_DEG, 90.0);
}

#[test]
fn an_ag_file_of_another_object_is_refused_naming_both_objects_and_the_file() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("square.ag");
    std::fs::write(&path, good_bytes()).expect("write");
    let err = AffordanceGradient::load_for(&path, "square").expect_err("the triangle's AG");
    assert!(matches!(err, AgFileLoadError::WrongObject { .. }), "{err}");
    let shown = err.to_string();
    assert!(
        shown.contains("square.ag") && shown.contains("`triangle`") && shown.contains("`square`"),
        "{shown}"
    );
    let ag = AffordanceGradient::load_for(&path, "triangle").expect("its own object");
    assert_eq!(ag.object_name(), "triangle");
}

#[test]
fn an_ag_file_with_an_absurd_cell_size_count_or_statistic_is_refused_naming_the_field() {
    let dir = tempfile::tempdir().expect("temp dir");
    let f64_at =
        |at: usize, x: f64| move |b: &mut Vec<u8>| b[at..at + 8].copy_from_slice(&x.to_le_bytes());
    let f32_at =
        |at: usize, x: f32| move |b: &mut Vec<u8>| b[at..at + 4].copy_from_slice(&x.to_le_bytes());
    let (lo, hi) = CELL_SIZE_M;
    let cases: Vec<(&str, Edit, &[&str])> = vec![
        (
            "cell-huge",
            Box::new(f64_at(CELL_SIZE_AT, 1e300)),
            &["cell size", "0.01 m"],
        ),
        (
            "cell-tiny",
            Box::new(f64_at(CELL_SIZE_AT, lo / 10.0)),
            &["cell size", "0.0001"],
        ),
        (
            "cell-big",
            Box::new(f64_at(CELL_SIZE_AT, hi * 2.0)),
            &["CELL_SIZE_M"],
        ),
        (
            "alphas-9",
            Box::new(|b: &mut Vec<u8>| {
                b[ALPHA_COUNT_AT..ALPHA_COUNT_AT + 4]
                    .copy_from_slice(&(MAX_ALPHAS + 1).to_le_bytes())
            }),
            &["9 alphas", "1 to 8"],
        ),
        (
            "name-control",
            Box::new(|b: &mut Vec<u8>| b[NAME_AT] = 0x1b),
            &["control character"],
        ),
        // The first cell of the first grid (S evidence) of alpha -15.
        (
            "s-negative",
            Box::new(f32_at(GRIDS_AT, -1.0)),
            &["S evidence", "non-negative"],
        ),
        (
            "s-huge",
            Box::new(f32_at(GRIDS_AT, 1e30)),
            &["S evidence", "MAX_CELL_MAGNITUDE"],
        ),
        // The second grid, push weight.
        (
            "weight-negative",
            Box::new(f32_at(GRIDS_AT + GRID_BYTES, -3.0)),
            &["push weight", "non-negative"],
        ),
        // R- sum, grid 10.
        (
            "r-minus-positive",
            Box::new(f32_at(GRIDS_AT + 9 * GRID_BYTES, 0.5)),
            &["R- sum", "non-positive"],
        ),
        // The past-centroid push weight, grid 12.
        (
            "past-weight-negative",
            Box::new(f32_at(GRIDS_AT + 11 * GRID_BYTES, -3.0)),
            &["past push weight", "non-negative"],
        ),
        (
            "rotation-1e300",
            Box::new(f64_at(TAILS_AT, 1e300)),
            &["max rotation", "MAX_PUSH_ROTATION_RAD"],
        ),
        (
            "pushes",
            Box::new(|b: &mut Vec<u8>| {
                b[TAILS_AT + 8..TAILS_AT + 16].copy_from_slice(&u64::MAX.to_le_bytes())
            }),
            &["pushes", "MAX_LAYER_COUNT"],
        ),
    ];
    for (name, edit, words) in cases {
        let (path, loaded) = load_edited(dir.path(), &format!("{name}.ag"), edit);
        let shown = refusal(&path, loaded);
        for w in words {
            assert!(shown.contains(w), "{name}: `{shown}` does not say {w}");
        }
    }
}

#[test]
fn a_fifo_or_a_link_to_dev_zero_as_an_ag_file_is_refused_without_blocking() {
    let dir = tempfile::tempdir().expect("temp dir");
    let fifo = dir.path().join("fifo.ag");
    let c = std::ffi::CString::new(fifo.as_os_str().as_encoded_bytes()).expect("no NUL");
    // SAFETY: mkfifo(3) on a NUL-terminated path this test owns.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    let shown = {
        let fifo = fifo.clone();
        without_hanging(move || AffordanceGradient::load(&fifo))
    }
    .expect_err("a FIFO")
    .to_string();
    assert!(
        shown.contains("fifo.ag") && shown.contains("not a regular file but a FIFO"),
        "{shown}"
    );

    let zero = dir.path().join("zero.ag");
    std::os::unix::fs::symlink("/dev/zero", &zero).expect("symlink");
    let shown = without_hanging(move || AffordanceGradient::load(&zero))
        .expect_err("/dev/zero")
        .to_string();
    assert!(
        shown.contains("zero.ag") && shown.contains("a character device"),
        "{shown}"
    );
}

#[test]
fn an_ag_file_larger_than_any_gradient_is_refused_naming_the_limit() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("huge.ag");
    let mut bytes = good_bytes().to_vec();
    bytes.resize(MAX_AG_FILE_BYTES as usize + 1, 0);
    std::fs::write(&path, &bytes).expect("write");
    let shown = AffordanceGradient::load(&path)
        .expect_err("too large")
        .to_string();
    assert!(
        shown.contains("huge.ag") && shown.contains(&format!("limit of {MAX_AG_FILE_BYTES} bytes")),
        "{shown}"
    );
}

/// One corruption of a good file.
#[derive(Debug, Clone)]
enum Damage {
    /// XOR a byte, checksum left as it is.
    Flip(usize, u8),
    /// Cut the file.
    Truncate(usize),
    /// Write a value into the header (cell size, an alpha, a tail) and fix the checksum.
    HeaderF64(usize, f64),
    /// Write a count (alpha count, name length) and fix the checksum.
    HeaderU32(usize, u32),
    /// Write a cell of some grid and fix the checksum.
    Cell(usize, f32),
}

fn hostile_f64() -> impl Strategy<Value = f64> {
    prop_oneof![
        any::<f64>(),
        Just(1e300),
        Just(-1e300),
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(0.0),
        Just(-0.0),
        Just(1000.0),
        Just(90.0),
        Just(f64::MIN_POSITIVE),
    ]
}

fn damage() -> impl Strategy<Value = Damage> {
    let len = good_bytes().len();
    prop_oneof![
        (0..len, 1..=255u8).prop_map(|(at, x)| Damage::Flip(at, x)),
        (0..len).prop_map(Damage::Truncate),
        (
            prop_oneof![
                Just(CELL_SIZE_AT),
                Just(ALPHAS_AT),
                Just(ALPHAS_AT + 8),
                Just(ALPHAS_AT + 16),
                Just(TAILS_AT),
                Just(TAILS_AT + 24)
            ],
            hostile_f64()
        )
            .prop_map(|(at, x)| Damage::HeaderF64(at, x)),
        (
            prop_oneof![Just(ALPHA_COUNT_AT), Just(NAME_LEN_AT)],
            prop_oneof![any::<u32>(), 0..16u32]
        )
            .prop_map(|(at, x)| Damage::HeaderU32(at, x)),
        (0..ALPHAS * 11 * GRID_CELLS, any::<f32>()).prop_map(|(k, x)| Damage::Cell(k, x)),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn a_corrupted_ag_file_never_panics_and_every_refusal_names_the_file(
        damages in proptest::collection::vec(damage(), 1..4)
    ) {
        let mut bytes = good_bytes().to_vec();
        let mut seal = false;
        for d in &damages {
            let n = bytes.len();
            match *d {
                Damage::Flip(at, x) if n > 0 => bytes[at % n] ^= x,
                Damage::Truncate(at) => bytes.truncate(at.min(n)),
                Damage::HeaderF64(at, x) if at + 8 <= n => {
                    bytes[at..at + 8].copy_from_slice(&x.to_le_bytes());
                    seal = true;
                }
                Damage::HeaderU32(at, x) if at + 4 <= n => {
                    bytes[at..at + 4].copy_from_slice(&x.to_le_bytes());
                    seal = true;
                }
                Damage::Cell(k, x) if GRIDS_AT + 4 * k + 4 <= n => {
                    bytes[GRIDS_AT + 4 * k..GRIDS_AT + 4 * k + 4].copy_from_slice(&x.to_le_bytes());
                    seal = true;
                }
                _ => {}
            }
        }
        if seal && bytes.len() >= 8 {
            reseal(&mut bytes);
        }
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("damaged.ag");
        std::fs::write(&path, &bytes).expect("write");
        match AffordanceGradient::load(&path) {
            Ok(ag) => {
                // Whatever is accepted is within every limit.
                let alphas: Vec<f64> = ag.alphas_deg().collect();
                prop_assert!(!alphas.is_empty() && alphas.len() <= MAX_ALPHAS as usize);
                prop_assert!(alphas.iter().all(|a| a.abs() <= MAX_ALPHA_DEG));
                let (lo, hi) = CELL_SIZE_M;
                prop_assert!((lo..=hi).contains(&ag.cell_size_m()));
                for a in alphas {
                    prop_assert!(ag.max_rotation_deg(a).is_none_or(|r| r.is_finite() && r <= 360.0));
                }
            }
            Err(e) => {
                let shown = e.to_string();
                prop_assert!(shown.contains(&path.display().to_string()), "{}", shown);
                prop_assert!(!shown.contains('\n'), "{}", shown);
            }
        }
    }
}
