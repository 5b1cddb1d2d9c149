//! The rule for an instance's name, which every process, the supervisor and the launch file share.

/// Longest instance name: root path plus prefix must stay under about 60 characters, since
/// iceoryx2 derives Unix socket paths from them.
pub const MAX_INSTANCE_NAME_LEN: usize = 20;

/// Environment variable that moves the folder holding every instance's iceoryx2 root.
pub const ROOT_ENV: &str = "AGP_IOX2_ROOT";

/// Why an instance name was refused.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum InstanceNameError {
    Empty,
    TooLong { len: usize },
    BadCharacter { c: char },
}

impl std::fmt::Display for InstanceNameError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Empty => write!(f, "instance name is empty"),
            Self::TooLong { len } => write!(
                f,
                "instance name is {len} characters long; at most {MAX_INSTANCE_NAME_LEN} fit in iceoryx2's socket paths"
            ),
            Self::BadCharacter { c } => write!(
                f,
                "instance name holds `{c}`; use lowercase letters, digits, `-` and `_`"
            ),
        }
    }
}

impl std::error::Error for InstanceNameError {}

/// Checks an instance name: 1 to [`MAX_INSTANCE_NAME_LEN`] lowercase letters, digits, `-`
/// and `_` (no `.`, which ends the name in every file name of an instance).
pub fn validate_instance_name(name: &str) -> Result<(), InstanceNameError> {
    if name.is_empty() {
        return Err(InstanceNameError::Empty);
    }
    if name.len() > MAX_INSTANCE_NAME_LEN {
        return Err(InstanceNameError::TooLong { len: name.len() });
    }
    if let Some(c) = name
        .chars()
        .find(|c| !(c.is_ascii_lowercase() || c.is_ascii_digit() || *c == '-' || *c == '_'))
    {
        return Err(InstanceNameError::BadCharacter { c });
    }
    Ok(())
}
