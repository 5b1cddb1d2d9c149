use std::path::Path;

use agp_affordance::{
    AG_FILE_VERSION, AffordanceGradient, AffordanceLearner, AgFileLoadError, LearnerConfig,
    PushOutcome,
};
use agp_shared_types::{GRID_SIDE, GridKind};
use glam::DVec2;

/// A small learned gradient: a few pushes and border points at each alpha.
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
                rotation_rad: 0.3 * (3.0 * phi).sin() + alpha.to_radians(),
                heading_obj: -c,
            };
            learner.add_push(alpha, &push).expect("learned alpha");
            learner.add_border_point(alpha, c).expect("learned alpha");
        }
    }
    learner.into_gradient()
}

fn saved(dir: &Path) -> (std::path::PathBuf, Vec<u8>) {
    let path = dir.join("triangle.ag");
    gradient().save(&path).expect("writable temp dir");
    let bytes = std::fs::read(&path).expect("just written");
    (path, bytes)
}

/// Writes `bytes` to a new file and loads it.
fn load_bytes(dir: &Path, name: &str, bytes: &[u8]) -> (std::path::PathBuf, AgFileLoadError) {
    let path = dir.join(name);
    std::fs::write(&path, bytes).expect("writable temp dir");
    let err = AffordanceGradient::load(&path).expect_err("a damaged file");
    (path, err)
}

/// FNV-1a 64, as the format specifies (recomputed here, not taken from the crate).
fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf29ce484222325;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x100000001b3);
    }
    h
}

/// Sets the trailing checksum to match the (edited) contents.
fn reseal(bytes: &mut [u8]) {
    let n = bytes.len() - 8;
    let sum = fnv1a64(&bytes[..n]);
    bytes[n..].copy_from_slice(&sum.to_le_bytes());
}

fn assert_names_path(err: &AgFileLoadError, path: &Path) {
    let message = err.to_string();
    assert!(
        message.contains(&path.display().to_string()),
        "`{message}` does not name the file"
    );
}

#[test]
fn a_saved_gradient_loads_back_identical() {
    let dir = tempfile::tempdir().expect("temp dir");
    let original = gradient();
    let path = dir.path().join("triangle.ag");
    original.save(&path).expect("writable temp dir");
    let loaded = AffordanceGradient::load(&path).expect("a file just written");
    assert_eq!(loaded, original);
    assert_eq!(loaded.object_name(), "triangle");
    assert_eq!(
        loaded.alphas_deg().collect::<Vec<_>>(),
        vec![-15.0, 0.0, 15.0]
    );
    for alpha in [-15.0, 0.0, 15.0] {
        assert_eq!(
            loaded.max_rotation_deg(alpha),
            original.max_rotation_deg(alpha)
        );
        for kind in GridKind::ALL {
            assert_eq!(
                loaded.component(alpha, kind),
                original.component(alpha, kind)
            );
        }
        let c = DVec2::new(0.0, 0.03);
        assert_eq!(loaded.predict(c, alpha), original.predict(c, alpha));
    }
    // No temporary file is left beside it.
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .expect("readable")
        .map(|e| e.expect("entry").file_name())
        .collect();
    assert_eq!(names, vec![std::ffi::OsString::from("triangle.ag")]);
}

#[test]
fn the_file_starts_with_the_documented_header() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (_, bytes) = saved(dir.path());
    assert_eq!(&bytes[..6], b"AGPAG\0");
    assert_eq!(u32::from_le_bytes(bytes[6..10].try_into().unwrap()), 2);
    assert_eq!(
        u32::from_le_bytes(bytes[10..14].try_into().unwrap()),
        GRID_SIDE as u32
    );
    assert_eq!(f64::from_le_bytes(bytes[14..22].try_into().unwrap()), 0.002);
    assert_eq!(u32::from_le_bytes(bytes[22..26].try_into().unwrap()), 3);
    let n = bytes.len() - 8;
    assert_eq!(
        u64::from_le_bytes(bytes[n..].try_into().unwrap()),
        fnv1a64(&bytes[..n])
    );
}

#[test]
fn a_truncated_file_is_refused() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (_, bytes) = saved(dir.path());
    for (k, cut) in [bytes.len() - 1, bytes.len() / 2, 30, 8, 3]
        .into_iter()
        .enumerate()
    {
        let (path, err) = load_bytes(dir.path(), &format!("cut{k}.ag"), &bytes[..cut]);
        assert!(
            matches!(err, AgFileLoadError::Truncated { len, .. } if len == cut),
            "cut at {cut}: {err}"
        );
        assert_names_path(&err, &path);
    }
}

#[test]
fn another_format_version_is_refused() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (_, mut bytes) = saved(dir.path());
    bytes[6..10].copy_from_slice(&(AG_FILE_VERSION + 1).to_le_bytes());
    reseal(&mut bytes);
    let (path, err) = load_bytes(dir.path(), "v3.ag", &bytes);
    assert!(
        matches!(err, AgFileLoadError::UnsupportedVersion { found: 3, .. }),
        "{err}"
    );
    assert_names_path(&err, &path);
}

/// The bytes of a version-1 file of the same gradient: 11 grids per alpha (the last six,
/// the pushes past the centroid, are left out; this gradient has none).
fn as_version_1(bytes: &[u8]) -> Vec<u8> {
    const GRID_BYTES: usize = GRID_SIDE * GRID_SIDE * 4;
    let alphas = u32::from_le_bytes(bytes[22..26].try_into().unwrap()) as usize;
    let name_at = 26 + 8 * alphas;
    let name_len = u32::from_le_bytes(bytes[name_at..name_at + 4].try_into().unwrap()) as usize;
    let grids_at = name_at + 4 + name_len;
    let mut out = bytes[..grids_at].to_vec();
    out[6..10].copy_from_slice(&1u32.to_le_bytes());
    for a in 0..alphas {
        let layer = grids_at + a * 17 * GRID_BYTES;
        out.extend_from_slice(&bytes[layer..layer + 11 * GRID_BYTES]);
    }
    out.extend_from_slice(&bytes[grids_at + alphas * 17 * GRID_BYTES..]);
    reseal(&mut out);
    out
}

#[test]
fn a_version_1_file_still_loads_and_predicts_as_before() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (_, bytes) = saved(dir.path());
    let v1 = as_version_1(&bytes);
    assert_eq!(v1.len(), bytes.len() - 3 * 6 * GRID_SIDE * GRID_SIDE * 4);
    let path = dir.path().join("v1.ag");
    std::fs::write(&path, &v1).expect("writable temp dir");
    let loaded = AffordanceGradient::load(&path).expect("a version-1 file loads");
    let original = gradient();
    for alpha in [0.0, 15.0, -15.0] {
        let c = DVec2::new(0.0, 0.03);
        let p = loaded.predict(c, alpha).expect("learned there");
        assert_eq!(Some(p), original.predict(c, alpha));
    }
    // Saved again, it is a version-2 file of the same gradient.
    loaded.save(dir.path().join("v2.ag")).expect("writable");
    let again = std::fs::read(dir.path().join("v2.ag")).expect("written");
    assert_eq!(again, bytes);
    // The header tells the two apart (a benchmark reusing its files relearns the old one).
    let version = |name: &str| AffordanceGradient::file_version(dir.path().join(name));
    assert_eq!(version("v1.ag").expect("a header"), 1);
    assert_eq!(version("v2.ag").expect("a header"), AG_FILE_VERSION);
    std::fs::write(dir.path().join("not.ag"), b"GIF89a").expect("writable");
    let err = version("not.ag").expect_err("no AG file");
    assert!(matches!(err, AgFileLoadError::BadMagic { .. }), "{err}");
    std::fs::write(dir.path().join("short.ag"), b"AGPAG\0\x02").expect("writable");
    let err = version("short.ag").expect_err("no whole version");
    assert!(matches!(err, AgFileLoadError::Truncated { .. }), "{err}");
}

#[test]
fn another_grid_size_is_refused() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (_, mut bytes) = saved(dir.path());
    bytes[10..14].copy_from_slice(&64u32.to_le_bytes());
    reseal(&mut bytes);
    let (path, err) = load_bytes(dir.path(), "side64.ag", &bytes);
    assert!(
        matches!(err, AgFileLoadError::GridSizeMismatch { found: 64, .. }),
        "{err}"
    );
    assert_names_path(&err, &path);
}

#[test]
fn bad_magic_is_refused() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (_, mut bytes) = saved(dir.path());
    bytes[0] = b'X';
    let (path, err) = load_bytes(dir.path(), "magic.ag", &bytes);
    assert!(matches!(err, AgFileLoadError::BadMagic { .. }), "{err}");
    assert_names_path(&err, &path);
    let (_, err) = load_bytes(dir.path(), "text.ag", b"hello, world");
    assert!(matches!(err, AgFileLoadError::BadMagic { .. }), "{err}");
}

#[test]
fn a_bad_checksum_is_refused() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (_, mut bytes) = saved(dir.path());
    // One bit of one grid cell.
    let k = bytes.len() / 2;
    bytes[k] ^= 0x10;
    let (path, err) = load_bytes(dir.path(), "flipped.ag", &bytes);
    assert!(
        matches!(err, AgFileLoadError::ChecksumMismatch { .. }),
        "{err}"
    );
    assert_names_path(&err, &path);
}

#[test]
fn a_missing_file_is_an_io_error_naming_it() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("absent.ag");
    let err = AffordanceGradient::load(&path).expect_err("no such file");
    assert!(matches!(err, AgFileLoadError::Io { .. }), "{err}");
    assert_names_path(&err, &path);
}

#[test]
fn impossible_values_behind_a_good_checksum_are_refused() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (_, mut bytes) = saved(dir.path());
    // A negative cell size.
    bytes[14..22].copy_from_slice(&(-0.002f64).to_le_bytes());
    reseal(&mut bytes);
    let (path, err) = load_bytes(dir.path(), "cell.ag", &bytes);
    assert!(matches!(err, AgFileLoadError::Invalid { .. }), "{err}");
    assert_names_path(&err, &path);
}
