use std::io::Read;
use std::os::unix::fs::OpenOptionsExt;
use std::path::Path;

/// Largest scenario or launch file read, bytes: a real one is a few hundred.
pub const MAX_CONFIG_FILE_BYTES: u64 = 1 << 20;

/// Why a configuration file could not be read. The caller names the file.
#[derive(Debug, thiserror::Error)]
pub enum BoundedReadError {
    /// Opening or reading failed.
    #[error("{0}")]
    Io(#[from] std::io::Error),
    /// The path leads (after following links) to something that is not a regular file.
    #[error("not a regular file but {0}")]
    NotRegular(&'static str),
    /// The file is longer than the limit.
    #[error("larger than the limit of {limit} bytes")]
    TooLarge {
        /// The limit, bytes.
        limit: u64,
    },
    /// The contents are not UTF-8 text.
    #[error("not UTF-8 text")]
    NotUtf8,
}

/// Reads at most `limit` bytes of the regular file `path`, refusing anything else without
/// blocking: the file is opened with `O_NONBLOCK`, so a FIFO with no writer cannot hang the
/// open, and its type is checked on the open descriptor, after links were followed (a link
/// to `/dev/zero` is a character device and refused before a byte is read).
pub fn read_regular_file(path: &Path, limit: u64) -> Result<Vec<u8>, BoundedReadError> {
    let file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path)?;
    let kind = file.metadata()?.file_type();
    if !kind.is_file() {
        return Err(BoundedReadError::NotRegular(describe(kind)));
    }
    let mut bytes = Vec::new();
    file.take(limit + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > limit {
        return Err(BoundedReadError::TooLarge { limit });
    }
    Ok(bytes)
}

/// [`read_regular_file`] of UTF-8 text.
pub fn read_regular_text(path: &Path, limit: u64) -> Result<String, BoundedReadError> {
    String::from_utf8(read_regular_file(path, limit)?).map_err(|_| BoundedReadError::NotUtf8)
}

fn describe(kind: std::fs::FileType) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    if kind.is_dir() {
        "a directory"
    } else if kind.is_fifo() {
        "a FIFO"
    } else if kind.is_char_device() {
        "a character device"
    } else if kind.is_block_device() {
        "a block device"
    } else if kind.is_socket() {
        "a socket"
    } else {
        "a special file"
    }
}

/// `path` with `.` dropped and each `..` taken against the component before it, without
/// touching the file system: `examples/python-planner/../../results` is `results`, and
/// `../bad/../bad/typo.toml` is `../bad/typo.toml`. Leading `..` of a relative path stay,
/// and `..` at the root is the root. This is how a path a user wrote is shown and joined;
/// where a link makes the lexical and the real parent differ, the folders a launch file
/// names relative to itself are still what its author meant.
pub fn lexically_normal(path: &Path) -> std::path::PathBuf {
    use std::path::Component;
    let mut out = std::path::PathBuf::new();
    for part in path.components() {
        match part {
            Component::CurDir => {}
            Component::ParentDir => match out.components().next_back() {
                Some(Component::Normal(_)) => {
                    out.pop();
                }
                Some(Component::RootDir | Component::Prefix(_)) => {}
                _ => out.push(".."),
            },
            other => out.push(other),
        }
    }
    if out.as_os_str().is_empty() {
        out.push(".");
    }
    out
}

#[cfg(test)]
mod tests {
    use super::lexically_normal;
    use std::path::Path;

    #[test]
    fn a_path_is_shown_without_dots_that_lead_back_where_it_was() {
        let cases = [
            ("examples/python-planner/../../results", "results"),
            ("a/..", "."),
            (
                "examples/python-planner/../../results/x.json",
                "results/x.json",
            ),
            ("../bad/../bad/typo.toml", "../bad/typo.toml"),
            ("/a/./b/../c", "/a/c"),
            ("/../x", "/x"),
            ("../../x", "../../x"),
            ("./", "."),
            ("a/b/", "a/b"),
        ];
        for (given, shown) in cases {
            assert_eq!(
                lexically_normal(Path::new(given)),
                Path::new(shown),
                "{given}"
            );
        }
    }
}
