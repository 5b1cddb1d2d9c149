//! Channels derived from the recorded messages, written into the same file: the recorder
//! hands a [`Tap`] every message it writes, on its writing thread (never on the thread
//! that drains the ring), and the tap adds what it makes of them. `agp record` gives it the
//! view's tap (agp-view's `FoxgloveTap`: the scene in Foxglove's protobuf schemas), and
//! `agp export` runs the same tap over an older recording's messages.

use std::io::BufWriter;

/// The MCAP writer of a recording's file.
pub type McapFile = mcap::Writer<BufWriter<std::fs::File>>;

/// Adds channels to a recording from its recorded messages.
pub trait Tap: Send {
    /// Adds its schemas and channels to `out`; called once, after the recording's own
    /// channels and before any message.
    fn begin(&mut self, out: &mut McapFile) -> Result<(), mcap::McapError>;

    /// One recorded message: its topic's service name (`agp/estimates`, ...), the
    /// payload's raw bytes and its log time (Unix ns); called in the order the messages
    /// are written.
    fn message(
        &mut self,
        out: &mut McapFile,
        service: &str,
        data: &[u8],
        log_time: u64,
    ) -> Result<(), mcap::McapError>;

    /// Called once after the last message, before the file is completed.
    fn end(&mut self, out: &mut McapFile) -> Result<(), mcap::McapError>;
}
