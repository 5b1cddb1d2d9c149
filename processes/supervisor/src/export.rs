//! `agp export IN.mcap OUT.mcap`: a recording copied with the scene in Foxglove's protobuf
//! schemas added, as `agp record` writes it now (agp-view's `FoxgloveTap` over the recorded
//! messages), so a recording made before opens in Foxglove, Lichtblick and Rerun.
//!
//! Every channel, message and metadata record of IN is copied as it is, except Foxglove
//! channels IN already has (message encoding `protobuf`), which are written anew. A raw
//! channel whose schema is not the payload type this build knows (another version of its
//! layout) is copied but not drawn, with a warning.

use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::PathBuf;

use agp_recording::{MESSAGE_ENCODING, Recording, Tap, mcap, recorded_topics};
use agp_view::FoxgloveTap;
use anyhow::{Context, Result, bail};

/// `agp export`.
#[derive(Debug, clap::Args)]
pub(crate) struct ExportArgs {
    /// The recording to read.
    input: PathBuf,
    /// The recording to write (not IN).
    output: PathBuf,
}

pub(crate) fn run(args: &ExportArgs) -> Result<u8> {
    let same = match (
        std::fs::canonicalize(&args.input),
        std::fs::canonicalize(&args.output),
    ) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    };
    if same {
        bail!("OUT must be another file than IN");
    }
    let input = Recording::open(&args.input)
        .with_context(|| format!("cannot read {}", args.input.display()))?;
    if input.truncated {
        eprintln!(
            "agp export: warning: {} ends early (a cut file): what it holds is exported",
            args.input.display()
        );
    }
    let file = std::fs::File::create(&args.output)
        .with_context(|| format!("cannot create {}", args.output.display()))?;
    let mut out = mcap::WriteOptions::new()
        .profile("agp")
        .library(format!("agp export {}", env!("CARGO_PKG_VERSION")))
        .compression(Some(mcap::Compression::Lz4))
        .create(BufWriter::with_capacity(1 << 20, file))
        .context("cannot start the MCAP file")?;
    let mcap_err =
        |e: mcap::McapError| anyhow::anyhow!("cannot write {}: {e}", args.output.display());
    for (name, metadata) in &input.metadata {
        if name == agp_view::FOXGLOVE_METADATA {
            continue;
        }
        out.write_metadata(&mcap::records::Metadata {
            name: name.clone(),
            metadata: metadata.clone(),
        })
        .map_err(mcap_err)?;
    }
    let mut tap = FoxgloveTap::default();
    tap.begin(&mut out).map_err(mcap_err)?;
    // Per input channel id: its id in OUT (None: not copied) and whether it is drawn.
    let mut channels: BTreeMap<u16, Option<(u16, bool)>> = BTreeMap::new();
    let mut schemas: BTreeMap<u16, u16> = BTreeMap::new();
    let mut copied = 0u64;
    // Every channel of the summary first, those without messages too (a recording lists
    // every topic); a file without a summary (cut short) gets its channels as they come.
    let summary = mcap::Summary::read(input.bytes()).ok().flatten();
    let mut listed: Vec<std::sync::Arc<mcap::Channel<'static>>> = summary
        .map(|s| s.channels.into_values().collect())
        .unwrap_or_default();
    listed.sort_by_key(|c| c.id);
    let first = listed.into_iter().map(Ok);
    let messages = input
        .messages()
        .context("cannot read the messages")?
        .map(Err::<std::sync::Arc<mcap::Channel<'static>>, _>);
    for item in first.chain(messages) {
        let (c, message) = match &item {
            Ok(c) => (c, None),
            Err(m) => (&m.channel, Some(m)),
        };
        let entry = match channels.get(&c.id) {
            Some(e) => *e,
            None => {
                let e = copy_channel(&mut out, c, &mut schemas).map_err(mcap_err)?;
                channels.insert(c.id, e);
                e
            }
        };
        let (Some((id, drawn)), Some(m)) = (entry, message) else {
            continue;
        };
        out.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: id,
                sequence: m.sequence,
                log_time: m.log_time,
                publish_time: m.publish_time,
            },
            &m.data,
        )
        .map_err(mcap_err)?;
        copied += 1;
        if drawn {
            tap.message(&mut out, &c.topic, &m.data, m.log_time)
                .map_err(mcap_err)?;
        }
    }
    tap.end(&mut out).map_err(mcap_err)?;
    out.finish().map_err(mcap_err)?;
    let file = out.into_inner();
    file.into_inner()
        .map_err(|e| e.into_error())
        .and_then(|f| f.sync_all())
        .with_context(|| format!("cannot complete {}", args.output.display()))?;
    print_counts(args, copied, &tap);
    Ok(0)
}

/// What `agp export` says at its end: the messages copied, the Foxglove channels' counts.
fn print_counts(args: &ExportArgs, copied: u64, tap: &FoxgloveTap) {
    println!(
        "agp export: {} -> {}: {copied} recorded messages copied; Foxglove channels:",
        args.input.display(),
        args.output.display()
    );
    for (topic, n) in tap.counts() {
        println!("  {topic:<18} {n:>8}");
    }
    if tap.refused() > 0 {
        println!(
            "agp export: {} recorded message(s) not drawn: their size is not their payload's",
            tap.refused()
        );
    }
}

/// Adds input channel `c` (and its schema, once) to `out`: its id there and whether the
/// tap draws it (a raw channel of a topic whose schema is the payload type this build
/// knows); `None` for a Foxglove channel, which is written anew.
fn copy_channel(
    out: &mut agp_recording::McapFile,
    c: &mcap::Channel<'static>,
    schemas: &mut BTreeMap<u16, u16>,
) -> Result<Option<(u16, bool)>, mcap::McapError> {
    if c.message_encoding == "protobuf" {
        return Ok(None);
    }
    let schema = match &c.schema {
        Some(s) => match schemas.get(&s.id) {
            Some(id) => *id,
            None => {
                let id = out.add_schema(&s.name, &s.encoding, &s.data)?;
                schemas.insert(s.id, id);
                id
            }
        },
        None => 0,
    };
    let id = out.add_channel(schema, &c.topic, &c.message_encoding, &c.metadata)?;
    let schema_name = c.schema.as_ref().map(|s| s.name.as_str());
    let expected = recorded_topics()
        .iter()
        .find(|t| t.service == c.topic)
        .map(|t| t.type_name);
    let drawn = match expected {
        Some(expected) if c.message_encoding == MESSAGE_ENCODING => {
            if schema_name != Some(expected) {
                eprintln!(
                    "agp export: warning: channel `{}` has schema `{}`, this build reads `{expected}`: copied, not drawn",
                    c.topic,
                    schema_name.unwrap_or("(none)")
                );
            }
            schema_name == Some(expected)
        }
        _ => false,
    };
    Ok(Some((id, drawn)))
}
