//! What the supervisor prints: one line at a time to stdout or stderr, never a panic on a
//! closed stream, and the run's event log stamped with the time since `up` started.

use std::io::Write;
use std::time::Instant;

/// Writes one line to stdout. A stdout nobody reads any more (`agp up | head -1`) is no
/// reason to stop supervising: the write's error is dropped (the SIGPIPE it raised stops
/// the run cleanly, see [`crate::signals::STOP_SIGNALS`]), never a panic.
pub(crate) fn say(line: std::fmt::Arguments<'_>) {
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "{line}");
    let _ = out.flush();
}

/// Writes one line to stderr; a closed stderr is ignored as [`say`] ignores a closed
/// stdout.
pub(crate) fn warn(line: std::fmt::Arguments<'_>) {
    let _ = writeln!(std::io::stderr().lock(), "{line}");
}

/// Prints one status line per event, stamped with the time since `up` started.
pub(crate) struct Log {
    pub(crate) start: Instant,
}

impl Log {
    pub(crate) fn event(&self, process: &str, what: std::fmt::Arguments<'_>) {
        say(format_args!(
            "[{:8.3} s] {process}: {what}",
            self.start.elapsed().as_secs_f64()
        ));
    }

    pub(crate) fn note(&self, what: std::fmt::Arguments<'_>) {
        say(format_args!(
            "[{:8.3} s] {what}",
            self.start.elapsed().as_secs_f64()
        ));
    }
}
