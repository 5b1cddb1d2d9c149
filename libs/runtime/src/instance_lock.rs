//! One live supervisor per instance: an exclusive `flock` on `<base>/<name>.lock`, next to
//! (not inside) the instance's iceoryx2 root folder.
//!
//! The lock is opened without following a link, and only as a regular file of this user,
//! in a base folder of this user's mode 0700 ([`Instance::prepare_dirs`]): a link planted
//! there by someone else is refused, never truncated through.

use std::fs::{File, OpenOptions, TryLockError};
use std::io::{Read, Write};
use std::os::unix::fs::{MetadataExt, OpenOptionsExt};
use std::path::{Path, PathBuf};

use crate::instance::{Instance, InstanceDirError};

/// Held while a supervisor owns its instance; released (and the file removed) on drop. The
/// kernel releases the lock when the supervisor dies, however it dies.
#[derive(Debug)]
pub struct InstanceLock {
    path: PathBuf,
    file: File,
}

/// Why an instance could not be locked.
#[derive(Debug, thiserror::Error)]
pub enum InstanceLockError {
    /// A live supervisor owns the instance.
    #[error(
        "instance `{name}` is already up{by}; stop it first or pick another name with `--instance` (lock {})",
        path.display(),
        by = pid.map(|p| format!(" under supervisor pid {p}")).unwrap_or_default()
    )]
    Held {
        name: String,
        path: PathBuf,
        pid: Option<u32>,
    },
    /// The base folder the lock lives in is not safe to use.
    #[error(transparent)]
    Dir(#[from] InstanceDirError),
    /// The lock path is a link, not a regular file, or another user's.
    #[error("refusing the lock {}: {why}", path.display())]
    Unsafe { path: PathBuf, why: String },
    /// The lock file could not be created or locked.
    #[error("cannot lock {}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

impl InstanceLock {
    /// Where the lock of `instance` lives: beside its root folder.
    pub fn path_of(instance: &Instance) -> PathBuf {
        let root = instance.root_dir();
        root.parent()
            .unwrap_or_else(|| Path::new("/"))
            .join(format!("{}.lock", instance.name()))
    }

    /// Whether a supervisor holds the lock of `instance` (it is up, or starting, or
    /// stopping).
    ///
    /// The lock is opened as the supervisor opens it: not through a link, only a regular
    /// file of this user; anything else is no supervisor's.
    pub fn is_held(instance: &Instance) -> bool {
        let Ok(file) = open_lock(&Self::path_of(instance), false) else {
            return false;
        };
        match file.try_lock_shared() {
            Ok(()) => {
                let _ = file.unlock();
                false
            }
            Err(TryLockError::WouldBlock) => true,
            Err(TryLockError::Error(_)) => false,
        }
    }

    /// Writes this process's pid into the lock: from now on it answers on the instance's
    /// control service, and clients may ask it ([`InstanceLock::holder_pid`]).
    pub fn announce(&mut self) -> std::io::Result<()> {
        use std::io::Seek;
        self.file.set_len(0)?;
        self.file.rewind()?;
        writeln!(self.file, "{}", std::process::id())?;
        self.file.flush()
    }

    /// The pid the supervisor holding `instance` wrote into its lock once it answers; `None`
    /// when none holds it or the one that does is still starting.
    pub fn holder_pid(instance: &Instance) -> Option<u32> {
        if !Self::is_held(instance) {
            return None;
        }
        let mut file = open_lock(&Self::path_of(instance), false).ok()?;
        let mut text = String::new();
        file.read_to_string(&mut text).ok()?;
        text.trim().parse().ok()
    }

    /// Locks `instance` for this process, or says which supervisor holds it.
    pub fn acquire(instance: &Instance) -> Result<Self, InstanceLockError> {
        let path = Self::path_of(instance);
        let io = |source| InstanceLockError::Io {
            path: path.clone(),
            source,
        };
        instance.prepare_base()?;
        // A releasing supervisor unlinks the file while it still holds the lock: whoever
        // locked the unlinked file retries on the path's new one.
        for _ in 0..16 {
            let mut file = open_lock(&path, true)?;
            match file.try_lock() {
                Ok(()) => {}
                Err(TryLockError::WouldBlock) => {
                    let mut text = String::new();
                    let pid = file
                        .read_to_string(&mut text)
                        .ok()
                        .and_then(|_| text.trim().parse().ok());
                    return Err(InstanceLockError::Held {
                        name: instance.name().to_owned(),
                        path,
                        pid,
                    });
                }
                Err(TryLockError::Error(e)) => return Err(io(e)),
            }
            let ours = file.metadata().map_err(io)?;
            let same = std::fs::metadata(&path)
                .is_ok_and(|m| m.ino() == ours.ino() && m.dev() == ours.dev());
            if !same {
                continue;
            }
            // Empty until the supervisor answers (`announce`): a client that finds no pid
            // makes no node in the way of the leftovers being cleaned.
            file.set_len(0).map_err(io)?;
            return Ok(Self { path, file });
        }
        Err(io(std::io::Error::other(
            "the lock file kept changing under us",
        )))
    }
}

/// Opens the lock file at `path` (created mode 0600 if `create`) without following a link
/// and without blocking on a FIFO, and checks it is a regular file of this user.
fn open_lock(path: &Path, create: bool) -> Result<File, InstanceLockError> {
    let refuse = |why: &str| InstanceLockError::Unsafe {
        path: path.to_path_buf(),
        why: why.to_owned(),
    };
    let file = OpenOptions::new()
        .read(true)
        .write(create)
        .create(create)
        .truncate(false)
        .mode(0o600)
        .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC | libc::O_NONBLOCK)
        .open(path)
        .map_err(|e| match e.raw_os_error() {
            Some(libc::ELOOP) => refuse("it is a symbolic link"),
            _ => InstanceLockError::Io {
                path: path.to_path_buf(),
                source: e,
            },
        })?;
    let meta = file.metadata().map_err(|source| InstanceLockError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    if !meta.file_type().is_file() {
        return Err(refuse("it is not a regular file"));
    }
    // SAFETY: geteuid(2) has no preconditions and cannot fail.
    let uid = unsafe { libc::geteuid() };
    if meta.uid() != uid {
        return Err(refuse(&format!(
            "it belongs to uid {}, not to this user (uid {uid})",
            meta.uid()
        )));
    }
    Ok(file)
}

impl Drop for InstanceLock {
    fn drop(&mut self) {
        // Unlink while still locked, then the lock goes with the descriptor.
        let _ = std::fs::remove_file(&self.path);
        let _ = self.file.unlock();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_lock_of_a_live_instance_is_refused_with_the_holders_pid_once_it_answers() {
        let instance = Instance::new("t-sup-lock").expect("valid name");
        let mut first = InstanceLock::acquire(&instance).expect("first lock");
        // Still starting: held, but no pid for clients to ask yet.
        assert!(InstanceLock::is_held(&instance));
        assert_eq!(InstanceLock::holder_pid(&instance), None);
        match InstanceLock::acquire(&instance) {
            Err(InstanceLockError::Held { pid, .. }) => assert_eq!(pid, None),
            other => panic!("expected Held, got {other:?}"),
        }
        first.announce().expect("write the pid");
        assert_eq!(
            InstanceLock::holder_pid(&instance),
            Some(std::process::id())
        );
        match InstanceLock::acquire(&instance) {
            Err(InstanceLockError::Held { pid, .. }) => {
                assert_eq!(pid, Some(std::process::id()));
            }
            other => panic!("expected Held, got {other:?}"),
        }
        drop(first);
        assert!(!InstanceLock::path_of(&instance).exists());
        let again = InstanceLock::acquire(&instance).expect("lock after release");
        drop(again);
    }
}
