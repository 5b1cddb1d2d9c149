use std::io::Write;
use std::path::{Path, PathBuf};

use agp_shared_types::{GRID_CELLS, GRID_SIDE, MAX_GRID_ALPHAS};

use crate::affordance_gradient::{ALPHA_EPS_DEG, AlphaLayer, LAYER_GRIDS, LayerGrid};
use crate::{AffordanceGradient, Grid};

/// First bytes of every AG file.
pub const AG_FILE_MAGIC: [u8; 6] = *b"AGPAG\0";
/// The format version this code writes. It reads this one and version 1 (11 grids per
/// alpha, before the pushes past the centroid were kept apart: its pushes all land in the
/// first branch's grids, as they were learned).
pub const AG_FILE_VERSION: u32 = 2;
/// Grids per alpha in a version-1 file.
const V1_LAYER_GRIDS: usize = 11;
/// Largest number of alphas a file may hold: no more than one set of published grids holds
/// ([`MAX_GRID_ALPHAS`]), so a loaded gradient can always be published whole.
pub const MAX_ALPHAS: u32 = 8;
/// Longest object name a file may hold, bytes.
pub const MAX_NAME_LEN: u32 = 256;
/// Largest |alpha| a file may hold, degrees: a push deviated by more than a right angle from
/// the centroid moves away from the object.
pub const MAX_ALPHA_DEG: f64 = 90.0;
/// Smallest and largest grid cell a file may hold, metres (0.1 mm to 10 mm: a 128-cell grid
/// then spans 12.8 mm to 1.28 m).
pub const CELL_SIZE_M: (f64, f64) = (1e-4, 1e-2);
/// Largest |value| of a grid cell (sums of unit-peak Gaussians and of their weighted SI
/// values): far above what any learning writes, far below what overflows an `f32` sum.
pub const MAX_CELL_MAGNITUDE: f32 = 1e12;
/// Largest rotation of a single push a file may hold, radians (a full turn).
pub const MAX_PUSH_ROTATION_RAD: f64 = std::f64::consts::TAU;
/// Most pushes and border points one alpha's layer may count.
pub const MAX_LAYER_COUNT: u64 = 1_000_000_000_000;
/// Largest AG file: one of [`MAX_ALPHAS`] alphas and a name of [`MAX_NAME_LEN`] bytes.
/// Nothing longer is read.
pub const MAX_AG_FILE_BYTES: u64 = (6
    + 4
    + 4
    + 8
    + 4
    + 8 * MAX_ALPHAS as usize
    + 4
    + MAX_NAME_LEN as usize
    + MAX_ALPHAS as usize * (LAYER_GRIDS * GRID_BYTES + LAYER_TAIL_BYTES)
    + 8) as u64;

const _: () = assert!(
    MAX_ALPHAS as usize <= MAX_GRID_ALPHAS,
    "the grids topic must hold a whole set of the gradient of any AG file"
);

const GRID_BYTES: usize = GRID_CELLS * 4;
const LAYER_TAIL_BYTES: usize = 8 * 3;

/// Why an AG file could not be written.
#[derive(Debug, thiserror::Error)]
pub enum AgFileSaveError {
    /// Writing or renaming the file failed.
    #[error("cannot write AG file `{}`", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
}

/// Why an AG file was refused.
#[derive(Debug, thiserror::Error)]
pub enum AgFileLoadError {
    /// The file could not be read.
    #[error("cannot read AG file `{}`", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The path leads (after following links) to something that is not a regular file: a
    /// FIFO, a device, a directory. Refused without reading from it.
    #[error("AG file `{}` is not a regular file but {kind}", path.display())]
    NotRegularFile {
        /// The file.
        path: PathBuf,
        /// What it is.
        kind: &'static str,
    },
    /// The file is longer than any AG file can be.
    #[error("AG file `{}` is larger than the limit of {limit} bytes (MAX_AG_FILE_BYTES)", path.display())]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// [`MAX_AG_FILE_BYTES`].
        limit: u64,
    },
    /// The gradient was learned on another object than the one asked for.
    #[error("AG file `{}` holds the gradient of object `{found}`, not of `{expected}`", path.display())]
    WrongObject {
        /// The file.
        path: PathBuf,
        /// The object asked for (the scenario's name).
        expected: String,
        /// The object named in the file.
        found: String,
    },
    /// The file does not start with [`AG_FILE_MAGIC`].
    #[error("`{}` is not an AG file (bad magic bytes)", path.display())]
    BadMagic {
        /// The file.
        path: PathBuf,
    },
    /// The file ends before its header says it should.
    #[error("AG file `{}` is truncated: {len} bytes, {needed} expected", path.display())]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Its length, bytes.
        len: usize,
        /// The length its contents call for (so far), bytes.
        needed: usize,
    },
    /// Another format version.
    #[error("AG file `{}` has format version {found}, this build reads {AG_FILE_VERSION}", path.display())]
    UnsupportedVersion {
        /// The file.
        path: PathBuf,
        /// The version found.
        found: u32,
    },
    /// Another grid side.
    #[error("AG file `{}` holds {found} x {found} grids, this build uses {GRID_SIDE} x {GRID_SIDE}", path.display())]
    GridSizeMismatch {
        /// The file.
        path: PathBuf,
        /// The side found.
        found: u32,
    },
    /// The checksum does not match the contents.
    #[error("AG file `{}` is corrupt: checksum {stored:#018x}, contents give {computed:#018x}", path.display())]
    ChecksumMismatch {
        /// The file.
        path: PathBuf,
        /// The checksum stored in the file.
        stored: u64,
        /// The checksum of the contents.
        computed: u64,
    },
    /// A field holds an impossible value.
    #[error("AG file `{}` is invalid: {reason}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
}

/// FNV-1a, 64 bits.
pub(crate) fn fnv1a64(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325_u64, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

impl AffordanceGradient {
    /// Writes the gradient to `path`, through a temporary file renamed into place so a
    /// reader never sees half a file.
    ///
    /// # Format
    ///
    /// Little-endian throughout:
    ///
    /// | field                 | type                      | notes                               |
    /// |-----------------------|---------------------------|-------------------------------------|
    /// | magic                 | 6 bytes                   | `AGPAG\0`                           |
    /// | version               | u32                       | [`AG_FILE_VERSION`]                 |
    /// | grid side             | u32                       | [`GRID_SIDE`]                       |
    /// | cell_size_m           | f64                       | metres                              |
    /// | alpha count `A`       | u32                       | 1 ..= [`MAX_ALPHAS`]                |
    /// | alphas_deg            | `A` x f64                 | degrees, ascending                  |
    /// | name length `L`       | u32                       | 0 ..= [`MAX_NAME_LEN`]              |
    /// | object name           | `L` bytes                 | UTF-8                               |
    /// | grids                 | `A` x 17 x side^2 x f32   | per alpha, row-major, see below     |
    /// | per alpha             | `A` x (f64, u64, u64)     | max_rotation_rad, pushes, border points |
    /// | checksum              | u64                       | FNV-1a 64 of every byte before it   |
    ///
    /// The 17 grids of an alpha, in order: S evidence (sum of Gaussians), push weight, then
    /// weighted sums of displacement x (m), displacement y (m), squared displacement (m^2),
    /// signed rotation (rad), squared rotation (rad^2), R+ (rad), then R+ weight, R- sum
    /// (rad, negative), R- weight; then the same six push statistics (weight, displacement
    /// x and y, squared displacement, rotation, squared rotation) of the pushes that meet
    /// the border past the centroid ([`crate::meets_past_centroid`]), the push weight and
    /// the five before R+ holding the others. Values are as in memory (SI), so a round
    /// trip is exact. Version 1 had the first 11 alone.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), AgFileSaveError> {
        let path = path.as_ref();
        let bytes = self.to_bytes();
        let io = |source| AgFileSaveError::Io {
            path: path.to_owned(),
            source,
        };
        let Some(name) = path.file_name() else {
            return Err(io(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "the path names no file",
            )));
        };
        let mut tmp_name = name.to_owned();
        tmp_name.push(".tmp");
        let tmp = path.with_file_name(tmp_name);
        let write = || -> std::io::Result<()> {
            let mut f = std::fs::File::create(&tmp)?;
            f.write_all(&bytes)?;
            f.sync_all()?;
            std::fs::rename(&tmp, path)
        };
        write().map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            io(e)
        })
    }

    /// Reads a gradient written by [`AffordanceGradient::save`], refusing a file with bad
    /// magic, another version or grid size, a truncated or corrupt (checksum) file, or
    /// impossible values.
    ///
    /// Reads nothing but a regular file (a FIFO or a link to a device is refused without
    /// blocking) of at most [`MAX_AG_FILE_BYTES`], and holds every number to a limit:
    /// |alpha| <= [`MAX_ALPHA_DEG`], distinct; a cell size within [`CELL_SIZE_M`]; cells
    /// finite, within [`MAX_CELL_MAGNITUDE`] and of their statistic's sign; a push's
    /// rotation at most [`MAX_PUSH_ROTATION_RAD`]; counts at most [`MAX_LAYER_COUNT`]; a
    /// name of at most [`MAX_NAME_LEN`] bytes of UTF-8 without control characters. Each
    /// refusal names the file, the field and the limit.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, AgFileLoadError> {
        let path = path.as_ref();
        let bytes = read_bounded(path)?;
        Self::from_bytes(&bytes, path)
    }

    /// The format version of the AG file at `path`, read from its header. A file of an
    /// older version still loads, but an older learner wrote it: a benchmark that reuses
    /// the files it learned before learns again one of another version than
    /// [`AG_FILE_VERSION`].
    pub fn file_version(path: impl AsRef<Path>) -> Result<u32, AgFileLoadError> {
        let path = path.as_ref();
        let bytes = read_bounded(path)?;
        if !bytes.starts_with(&AG_FILE_MAGIC) {
            return Err(AgFileLoadError::BadMagic {
                path: path.to_owned(),
            });
        }
        Reader {
            bytes: &bytes,
            pos: AG_FILE_MAGIC.len(),
            path,
        }
        .u32()
    }

    /// [`AffordanceGradient::load`], refusing a gradient learned on another object than
    /// `expected_object` (the scenario's name) with [`AgFileLoadError::WrongObject`].
    pub fn load_for(
        path: impl AsRef<Path>,
        expected_object: &str,
    ) -> Result<Self, AgFileLoadError> {
        let path = path.as_ref();
        let ag = Self::load(path)?;
        if ag.object_name != expected_object {
            return Err(AgFileLoadError::WrongObject {
                path: path.to_owned(),
                expected: expected_object.to_owned(),
                found: ag.object_name,
            });
        }
        Ok(ag)
    }

    fn to_bytes(&self) -> Vec<u8> {
        let name = self.object_name.as_bytes();
        let a = self.layers.len();
        let mut out = Vec::with_capacity(
            6 + 4
                + 4
                + 8
                + 4
                + 8 * a
                + 4
                + name.len()
                + a * (LAYER_GRIDS * GRID_BYTES + LAYER_TAIL_BYTES)
                + 8,
        );
        out.extend_from_slice(&AG_FILE_MAGIC);
        out.extend_from_slice(&AG_FILE_VERSION.to_le_bytes());
        out.extend_from_slice(&(GRID_SIDE as u32).to_le_bytes());
        out.extend_from_slice(&self.cell_size_m.to_le_bytes());
        out.extend_from_slice(&(a as u32).to_le_bytes());
        for l in &self.layers {
            out.extend_from_slice(&l.alpha_deg.to_le_bytes());
        }
        out.extend_from_slice(&(name.len() as u32).to_le_bytes());
        out.extend_from_slice(name);
        for l in &self.layers {
            for g in &l.grids {
                for c in g.cells() {
                    out.extend_from_slice(&c.to_le_bytes());
                }
            }
        }
        for l in &self.layers {
            out.extend_from_slice(&l.max_rotation_rad.to_le_bytes());
            out.extend_from_slice(&l.pushes.to_le_bytes());
            out.extend_from_slice(&l.border_points.to_le_bytes());
        }
        let sum = fnv1a64(&out);
        out.extend_from_slice(&sum.to_le_bytes());
        out
    }

    fn from_bytes(bytes: &[u8], path: &Path) -> Result<Self, AgFileLoadError> {
        let p = || path.to_owned();
        let invalid = |reason: String| AgFileLoadError::Invalid { path: p(), reason };
        let head = &bytes[..bytes.len().min(AG_FILE_MAGIC.len())];
        if head != &AG_FILE_MAGIC[..head.len()] {
            return Err(AgFileLoadError::BadMagic { path: p() });
        }
        let mut r = Reader {
            bytes,
            pos: AG_FILE_MAGIC.len(),
            path,
        };
        if bytes.len() < AG_FILE_MAGIC.len() {
            return Err(r.truncated(AG_FILE_MAGIC.len()));
        }
        let version = r.u32()?;
        let layer_grids = match version {
            AG_FILE_VERSION => LAYER_GRIDS,
            1 => V1_LAYER_GRIDS,
            found => return Err(AgFileLoadError::UnsupportedVersion { path: p(), found }),
        };
        let side = r.u32()?;
        if side as usize != GRID_SIDE {
            return Err(AgFileLoadError::GridSizeMismatch {
                path: p(),
                found: side,
            });
        }
        let cell_size_m = r.f64()?;
        let alpha_count = r.u32()?;
        if !(1..=MAX_ALPHAS).contains(&alpha_count) {
            return Err(invalid(format!(
                "{alpha_count} alphas, expected 1 to {MAX_ALPHAS}"
            )));
        }
        let a = alpha_count as usize;
        let mut alphas = Vec::with_capacity(a);
        for _ in 0..a {
            alphas.push(r.f64()?);
        }
        let name_len = r.u32()?;
        if name_len > MAX_NAME_LEN {
            return Err(invalid(format!(
                "object name: {name_len} bytes, at most {MAX_NAME_LEN} (MAX_NAME_LEN) allowed"
            )));
        }
        let name_bytes = r.take(name_len as usize)?;
        let needed = r.pos + a * (layer_grids * GRID_BYTES + LAYER_TAIL_BYTES) + 8;
        if bytes.len() < needed {
            return Err(r.truncated(needed));
        }
        if bytes.len() > needed {
            return Err(invalid(format!(
                "{} bytes after the checksum",
                bytes.len() - needed
            )));
        }
        let (body, tail) = bytes.split_at(needed - 8);
        let mut stored = [0u8; 8];
        stored.copy_from_slice(tail);
        let stored = u64::from_le_bytes(stored);
        let computed = fnv1a64(body);
        if stored != computed {
            return Err(AgFileLoadError::ChecksumMismatch {
                path: p(),
                stored,
                computed,
            });
        }
        // The checksum holds: what follows checks meaning, not integrity.
        let object_name = std::str::from_utf8(name_bytes)
            .map_err(|_| invalid("object name is not UTF-8".into()))?
            .to_owned();
        if object_name.chars().any(char::is_control) {
            return Err(invalid("object name holds a control character".into()));
        }
        let (lo, hi) = CELL_SIZE_M;
        if !(cell_size_m.is_finite() && (lo..=hi).contains(&cell_size_m)) {
            return Err(invalid(format!(
                "cell size {cell_size_m} m, expected {lo} to {hi} m (CELL_SIZE_M)"
            )));
        }
        for (k, &alpha) in alphas.iter().enumerate() {
            if !(alpha.is_finite() && alpha.abs() <= MAX_ALPHA_DEG) {
                return Err(invalid(format!(
                    "alpha {} is {alpha} deg, beyond the limit |alpha| <= {MAX_ALPHA_DEG} deg (MAX_ALPHA_DEG)",
                    k + 1
                )));
            }
            if alphas[..k]
                .iter()
                .any(|&b| (alpha - b).abs() < ALPHA_EPS_DEG)
            {
                return Err(invalid(format!(
                    "alpha {} is {alpha} deg, repeated: alphas must be distinct",
                    k + 1
                )));
            }
        }
        let mut layers: Vec<AlphaLayer> = alphas
            .iter()
            .map(|&alpha| AlphaLayer::new(alpha, cell_size_m))
            .collect();
        for layer in &mut layers {
            for (g, grid) in layer.grids.iter_mut().enumerate().take(layer_grids) {
                read_grid(&mut r, grid)?;
                if let Some(why) = check_cells(g, grid.cells()) {
                    return Err(invalid(format!(
                        "grid {} ({}) of alpha {} deg: {why}",
                        g + 1,
                        GRID_NAMES[g],
                        layer.alpha_deg
                    )));
                }
            }
        }
        for layer in &mut layers {
            layer.max_rotation_rad = r.f64()?;
            layer.pushes = r.u64()?;
            layer.border_points = r.u64()?;
            if !(layer.max_rotation_rad.is_finite()
                && (0.0..=MAX_PUSH_ROTATION_RAD).contains(&layer.max_rotation_rad))
            {
                return Err(invalid(format!(
                    "max rotation {} rad of alpha {} deg, expected 0 to {MAX_PUSH_ROTATION_RAD} rad (MAX_PUSH_ROTATION_RAD)",
                    layer.max_rotation_rad, layer.alpha_deg
                )));
            }
            for (field, count) in [
                ("pushes", layer.pushes),
                ("border points", layer.border_points),
            ] {
                if count > MAX_LAYER_COUNT {
                    return Err(invalid(format!(
                        "{count} {field} at alpha {} deg, at most {MAX_LAYER_COUNT} (MAX_LAYER_COUNT)",
                        layer.alpha_deg
                    )));
                }
            }
        }
        layers.sort_by(|a, b| a.alpha_deg.total_cmp(&b.alpha_deg));
        Ok(Self {
            object_name,
            cell_size_m,
            layers,
        })
    }
}

/// The grids of a layer, in file order, as the errors name them.
const GRID_NAMES: [&str; LAYER_GRIDS] = [
    "S evidence",
    "push weight",
    "displacement x sum",
    "displacement y sum",
    "squared displacement sum",
    "rotation sum",
    "squared rotation sum",
    "R+ sum",
    "R+ weight",
    "R- sum",
    "R- weight",
    "past push weight",
    "past displacement x sum",
    "past displacement y sum",
    "past squared displacement sum",
    "past rotation sum",
    "past squared rotation sum",
];

/// Why the cells of layer grid `g` are impossible, if they are: not finite, beyond
/// [`MAX_CELL_MAGNITUDE`], or of the wrong sign for a sum of Gaussians (weights, S, squares
/// and R+ are never negative, R- never positive).
fn check_cells(g: usize, cells: &[f32]) -> Option<String> {
    let sign = match g {
        x if x == LayerGrid::DisplacementX as usize
            || x == LayerGrid::DisplacementY as usize
            || x == LayerGrid::Rotation as usize
            || x == LayerGrid::PastDisplacementX as usize
            || x == LayerGrid::PastDisplacementY as usize
            || x == LayerGrid::PastRotation as usize =>
        {
            0
        }
        x if x == LayerGrid::RotationNeg as usize => -1,
        _ => 1,
    };
    let (k, &c) = cells.iter().enumerate().find(|&(_, &c)| {
        !(c.is_finite() && c.abs() <= MAX_CELL_MAGNITUDE)
            || (sign > 0 && c < 0.0)
            || (sign < 0 && c > 0.0)
    })?;
    Some(if !c.is_finite() {
        format!("cell {k} holds a non-finite value")
    } else if c.abs() > MAX_CELL_MAGNITUDE {
        format!("cell {k} is {c}, beyond the limit of {MAX_CELL_MAGNITUDE} (MAX_CELL_MAGNITUDE)")
    } else if sign > 0 {
        format!("cell {k} is {c}, expected a non-negative value")
    } else {
        format!("cell {k} is {c}, expected a non-positive value")
    })
}

/// Reads at most [`MAX_AG_FILE_BYTES`] of the regular file `path`, without blocking on a
/// FIFO (`agp_world::read_regular_file`: opened with `O_NONBLOCK`, its type checked on the
/// open descriptor).
fn read_bounded(path: &Path) -> Result<Vec<u8>, AgFileLoadError> {
    use agp_world::BoundedReadError;
    agp_world::read_regular_file(path, MAX_AG_FILE_BYTES).map_err(|e| match e {
        BoundedReadError::NotRegular(kind) => AgFileLoadError::NotRegularFile {
            path: path.to_owned(),
            kind,
        },
        BoundedReadError::TooLarge { limit } => AgFileLoadError::TooLarge {
            path: path.to_owned(),
            limit,
        },
        BoundedReadError::Io(source) => AgFileLoadError::Io {
            path: path.to_owned(),
            source,
        },
        // Only `read_regular_text` checks UTF-8; bytes are bytes.
        BoundedReadError::NotUtf8 => AgFileLoadError::Io {
            path: path.to_owned(),
            source: std::io::Error::from(std::io::ErrorKind::InvalidData),
        },
    })
}

fn read_grid(r: &mut Reader<'_>, grid: &mut Grid) -> Result<(), AgFileLoadError> {
    let raw = r.take(GRID_BYTES)?;
    for (c, b) in grid.cells_mut().iter_mut().zip(raw.chunks_exact(4)) {
        *c = f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
    }
    Ok(())
}

/// A cursor over the file's bytes whose reads fail with [`AgFileLoadError::Truncated`].
struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
    path: &'a Path,
}

impl<'a> Reader<'a> {
    fn truncated(&self, needed: usize) -> AgFileLoadError {
        AgFileLoadError::Truncated {
            path: self.path.to_owned(),
            len: self.bytes.len(),
            needed,
        }
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8], AgFileLoadError> {
        let end = self.pos + n;
        let bytes: &'a [u8] = self.bytes;
        let out = bytes
            .get(self.pos..end)
            .ok_or_else(|| self.truncated(end))?;
        self.pos = end;
        Ok(out)
    }

    fn array<const N: usize>(&mut self) -> Result<[u8; N], AgFileLoadError> {
        let mut out = [0u8; N];
        out.copy_from_slice(self.take(N)?);
        Ok(out)
    }

    fn u32(&mut self) -> Result<u32, AgFileLoadError> {
        self.array().map(u32::from_le_bytes)
    }

    fn u64(&mut self) -> Result<u64, AgFileLoadError> {
        self.array().map(u64::from_le_bytes)
    }

    fn f64(&mut self) -> Result<f64, AgFileLoadError> {
        self.array().map(f64::from_le_bytes)
    }
}
