//! One live supervisor per instance: an exclusive `flock` on `<base>/<name>.lock`, next to
//! (not inside) the instance's iceoryx2 root folder.

use std::fs::{File, OpenOptions, TryLockError};
use std::io::{Read, Write};
use std::os::unix::fs::{MetadataExt, OpenOptionsExt};
use std::path::{Path, PathBuf};

use agp_shared_types::Instance;

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

    /// Locks `instance` for this process, or says which supervisor holds it.
    pub fn acquire(instance: &Instance) -> Result<Self, InstanceLockError> {
        let path = Self::path_of(instance);
        let io = |source| InstanceLockError::Io {
            path: path.clone(),
            source,
        };
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir).map_err(io)?;
        }
        // A releasing supervisor unlinks the file while it still holds the lock: whoever
        // locked the unlinked file retries on the path's new one.
        for _ in 0..16 {
            let mut file = OpenOptions::new()
                .read(true)
                .write(true)
                .create(true)
                .truncate(false)
                .mode(0o644)
                .open(&path)
                .map_err(io)?;
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
            file.set_len(0).map_err(io)?;
            writeln!(file, "{}", std::process::id()).map_err(io)?;
            return Ok(Self { path, file });
        }
        Err(io(std::io::Error::other(
            "the lock file kept changing under us",
        )))
    }
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
    fn a_second_lock_of_a_live_instance_is_refused_with_the_holders_pid() {
        let instance = Instance::new("t-sup-lock").expect("valid name");
        let first = InstanceLock::acquire(&instance).expect("first lock");
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
