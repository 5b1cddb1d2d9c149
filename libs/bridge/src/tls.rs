//! The link's keys: a CA made for this link alone, and one certificate and private key per
//! side, signed by it. Zenoh's TLS transport (rustls, TLS 1.3) runs with mutual
//! authentication: the listening end takes only a far end whose certificate this CA signed,
//! and the connecting end checks that the listening end's certificate is signed by it and
//! names the host it connects to.
//!
//! `keygen` (with the `link` feature) writes a key folder (`agp bridge keygen DIR`):
//!
//! | file | what | mode |
//! | --- | --- | --- |
//! | `ca.pem` | the CA's certificate (its key is not kept: run keygen again for new hosts) | 0644 |
//! | `robot.pem`, `robot-key.pem` | the robot side's certificate and private key | 0644, 0600 |
//! | `planner.pem`, `planner-key.pem` | the planner side's | 0644, 0600 |
//!
//! The folder is made 0700. [`TlsKeys::load`] refuses a private key that another user owns or
//! that group or others may read or write, naming it.

use std::fs;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};

use crate::route::Side;

/// The CA's certificate in a key folder.
pub const CA_FILE: &str = "ca.pem";

/// The names every certificate `keygen` makes carries, besides the `--host` ones: the
/// loopback, by name and by address.
pub const DEFAULT_HOSTS: [&str; 3] = ["localhost", "127.0.0.1", "::1"];

/// How long the certificates `keygen` makes are valid, years from the start of this one.
pub const VALID_YEARS: i32 = 10;

/// A side's certificate in a key folder.
pub fn cert_file(side: Side) -> String {
    format!("{}.pem", side.name())
}

/// A side's private key in a key folder.
pub fn key_file(side: Side) -> String {
    format!("{}-key.pem", side.name())
}

/// Why keys could not be made or used.
#[derive(Debug, thiserror::Error)]
pub enum TlsError {
    #[error("{path}: {detail}")]
    Io { path: PathBuf, detail: String },
    #[error("{0}: no such file: make the key folder with `agp bridge keygen DIR`")]
    Missing(PathBuf),
    #[error(
        "{path}: a private key readable or writable by group or others (mode {mode:04o}): run `chmod 600 {path}`"
    )]
    KeyOpen { path: PathBuf, mode: u32 },
    #[error(
        "{path}: a private key owned by user {owner}, not by this user ({me}): make the key folder as this user"
    )]
    KeyOwner { path: PathBuf, owner: u32, me: u32 },
    #[error(
        "{0}: the folder already holds keys: remove it first, or name another (keygen overwrites nothing)"
    )]
    Exists(PathBuf),
    #[error("bad host name `{host}`: {detail}")]
    Host { host: String, detail: String },
    #[error("cannot make the certificates: {0}")]
    Rcgen(String),
}

pub(crate) fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> TlsError + '_ {
    move |e| TlsError::Io {
        path: path.to_owned(),
        detail: e.to_string(),
    }
}

/// The files one side of a TLS link uses, checked.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TlsKeys {
    /// The link's CA certificate: the far end's certificate must be signed by it.
    pub ca: PathBuf,
    /// This side's certificate, shown to the far end.
    pub cert: PathBuf,
    /// This side's private key (0600, owned by this user).
    pub key: PathBuf,
}

impl TlsKeys {
    /// The files of `side` in the key folder `dir`: each present, the private key owned by
    /// this user and closed to group and others.
    pub fn load(dir: &Path, side: Side) -> Result<Self, TlsError> {
        let keys = Self {
            ca: dir.join(CA_FILE),
            cert: dir.join(cert_file(side)),
            key: dir.join(key_file(side)),
        };
        for file in [&keys.ca, &keys.cert, &keys.key] {
            if !file.is_file() {
                return Err(TlsError::Missing(file.clone()));
            }
        }
        check_private(&keys.key)?;
        Ok(keys)
    }
}

/// Refuses a private key file that another user owns, or that group or others may touch.
pub fn check_private(path: &Path) -> Result<(), TlsError> {
    let meta = fs::metadata(path).map_err(io_err(path))?;
    // SAFETY: geteuid has no preconditions and cannot fail.
    let me = unsafe { libc::geteuid() };
    if meta.uid() != me {
        return Err(TlsError::KeyOwner {
            path: path.to_owned(),
            owner: meta.uid(),
            me,
        });
    }
    let mode = meta.mode() & 0o7777;
    if mode & 0o077 != 0 {
        return Err(TlsError::KeyOpen {
            path: path.to_owned(),
            mode,
        });
    }
    Ok(())
}
