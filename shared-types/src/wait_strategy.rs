//! How a process waits for its next input, as `AGP_WAIT` names it.

use std::time::Duration;

/// How a process waits for its next input.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WaitStrategy {
    /// Poll without pause: the lowest latency, one core per waiting process.
    Spin,
    /// Poll, yielding the core between polls: near-spin latency while others can run.
    Yield,
    /// Block on the event service at once.
    Block,
    /// Poll with yields for `spin`, then block.
    SpinThenBlock { spin: Duration },
}

impl WaitStrategy {
    /// The strategy named in `AGP_WAIT` (`spin`, `yield`, `block`, `spin-then-block` with an
    /// optional `:<microseconds>`), or the default.
    /// A value that names none is said on stderr and the default is used: `agp up` refuses
    /// such a value before anything starts ([`WaitStrategy::from_env_checked`]).
    pub fn from_env() -> Self {
        match Self::from_env_checked() {
            Ok(strategy) => strategy.unwrap_or_default(),
            Err(why) => {
                let default = Self::default();
                eprintln!("{why}: waiting `{}`", default.name());
                default
            }
        }
    }

    /// The environment variable that names the strategy.
    pub const ENV: &'static str = "AGP_WAIT";

    /// Why a value of [`WaitStrategy::ENV`] is refused, and what it may hold.
    pub const NOT_A_STRATEGY: &'static str =
        "not a waiting strategy: `spin`, `yield`, `block` or `spin-then-block[:<microseconds>]`";

    /// The strategy `AGP_WAIT` names; `Ok(None)` when it is unset, an error that names the
    /// value when it names no strategy.
    pub fn from_env_checked() -> Result<Option<Self>, String> {
        match std::env::var(Self::ENV) {
            Err(std::env::VarError::NotPresent) => Ok(None),
            Err(std::env::VarError::NotUnicode(v)) => {
                Err(format!("{}={v:?} is {}", Self::ENV, Self::NOT_A_STRATEGY))
            }
            Ok(v) => Self::parse(&v)
                .map(Some)
                .ok_or_else(|| format!("{}=`{v}` is {}", Self::ENV, Self::NOT_A_STRATEGY)),
        }
    }

    /// Parses a strategy name.
    pub fn parse(s: &str) -> Option<Self> {
        let (name, arg) = s.split_once(':').unwrap_or((s, ""));
        match name {
            "spin" => Some(Self::Spin),
            "yield" => Some(Self::Yield),
            "block" => Some(Self::Block),
            "spin-then-block" => {
                let us = if arg.is_empty() {
                    200
                } else {
                    arg.parse().ok()?
                };
                Some(Self::SpinThenBlock {
                    spin: Duration::from_micros(us),
                })
            }
            _ => None,
        }
    }

    pub fn name(&self) -> String {
        match self {
            Self::Spin => "spin".into(),
            Self::Yield => "yield".into(),
            Self::Block => "block".into(),
            Self::SpinThenBlock { spin } => format!("spin-then-block:{}", spin.as_micros()),
        }
    }
}

impl Default for WaitStrategy {
    fn default() -> Self {
        Self::SpinThenBlock {
            spin: Duration::from_micros(200),
        }
    }
}
