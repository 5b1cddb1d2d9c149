//! Reading a recording back: its metadata, its channels and their messages.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::{RECORDING_METADATA, RUN_METADATA};

/// Largest recording [`Recording::open`] reads (it reads the whole file into memory).
pub const MAX_RECORDING_BYTES: u64 = 4 << 30;

/// Why a recording could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    #[error("cannot read {}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{} is not a regular file", path.display())]
    NotAFile { path: PathBuf },
    #[error("{} is {bytes} bytes, more than the {MAX_RECORDING_BYTES} a recording may be", path.display())]
    TooLarge { path: PathBuf, bytes: u64 },
    #[error("{} is not a valid MCAP file: {source}", path.display())]
    Mcap {
        path: PathBuf,
        #[source]
        source: mcap::McapError,
    },
}

/// One channel of a recording.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChannelInfo {
    pub id: u16,
    /// The iceoryx2 service name (`agp/ir_frames`).
    pub topic: String,
    /// The schema's name: the payload's iceoryx2 type name (`agp::IrFrame.v2`).
    pub schema_name: String,
    pub schema_encoding: String,
    pub message_encoding: String,
    pub messages: u64,
}

/// A recording read into memory.
pub struct Recording {
    path: PathBuf,
    data: Vec<u8>,
    /// Every metadata record, by name ([`RUN_METADATA`], [`RECORDING_METADATA`]).
    pub metadata: BTreeMap<String, BTreeMap<String, String>>,
    pub channels: Vec<ChannelInfo>,
    /// The file ended before its footer (a recorder killed before it finished): every
    /// record up to the cut was read.
    pub truncated: bool,
}

impl Recording {
    /// Reads the MCAP file at `path` (a regular file of at most [`MAX_RECORDING_BYTES`])
    /// and indexes its channels and metadata.
    pub fn open(path: &Path) -> Result<Self, ReadError> {
        let io = |source| ReadError::Io {
            path: path.to_path_buf(),
            source,
        };
        let meta = std::fs::metadata(path).map_err(io)?;
        if !meta.is_file() {
            return Err(ReadError::NotAFile {
                path: path.to_path_buf(),
            });
        }
        if meta.len() > MAX_RECORDING_BYTES {
            return Err(ReadError::TooLarge {
                path: path.to_path_buf(),
                bytes: meta.len(),
            });
        }
        let data = std::fs::read(path).map_err(io)?;
        Self::from_bytes(path, data)
    }

    /// As [`Recording::open`], from bytes already read; `path` only names it in errors.
    pub fn from_bytes(path: &Path, data: Vec<u8>) -> Result<Self, ReadError> {
        let mut metadata = BTreeMap::new();
        let mut schemas: BTreeMap<u16, (String, String)> = BTreeMap::new();
        let mut channels: BTreeMap<u16, ChannelInfo> = BTreeMap::new();
        let mut truncated = false;
        let reader = mcap::read::ChunkFlattener::new(&data).map_err(|source| ReadError::Mcap {
            path: path.to_path_buf(),
            source,
        })?;
        for record in reader {
            let record = match record {
                Ok(r) => r,
                Err(_) => {
                    truncated = true;
                    break;
                }
            };
            use mcap::records::Record;
            match record {
                Record::Schema { header, .. } => {
                    schemas.insert(header.id, (header.name, header.encoding));
                }
                Record::Channel(c) => {
                    let (schema_name, schema_encoding) =
                        schemas.get(&c.schema_id).cloned().unwrap_or_default();
                    channels.entry(c.id).or_insert(ChannelInfo {
                        id: c.id,
                        topic: c.topic,
                        schema_name,
                        schema_encoding,
                        message_encoding: c.message_encoding,
                        messages: 0,
                    });
                }
                Record::Message { header, .. } => {
                    if let Some(c) = channels.get_mut(&header.channel_id) {
                        c.messages += 1;
                    }
                }
                Record::Metadata(m) => {
                    metadata.insert(m.name, m.metadata);
                }
                _ => {}
            }
        }
        Ok(Self {
            path: path.to_path_buf(),
            data,
            metadata,
            channels: channels.into_values().collect(),
            truncated,
        })
    }

    /// The run's metadata ([`RUN_METADATA`]); empty if absent.
    pub fn run(&self) -> BTreeMap<String, String> {
        self.metadata.get(RUN_METADATA).cloned().unwrap_or_default()
    }

    /// The recorder's own account ([`RECORDING_METADATA`]: per topic `received`,
    /// `written`, `dropped`, `lost`); empty if the recorder did not finish.
    pub fn recorder_stats(&self) -> BTreeMap<String, String> {
        self.metadata
            .get(RECORDING_METADATA)
            .cloned()
            .unwrap_or_default()
    }

    /// The channel of `topic`, if the recording has one.
    pub fn channel(&self, topic: &str) -> Option<&ChannelInfo> {
        self.channels.iter().find(|c| c.topic == topic)
    }

    /// Every message in file order (the order the recorder took them, batch by batch: in
    /// order within a topic, not strictly across topics). Stops quietly at the cut of a
    /// truncated file.
    pub fn messages(&self) -> Result<impl Iterator<Item = mcap::Message<'static>> + '_, ReadError> {
        let stream = mcap::MessageStream::new(&self.data).map_err(|source| ReadError::Mcap {
            path: self.path.clone(),
            source,
        })?;
        Ok(stream.map_while(Result::ok))
    }

    /// The data of every message of `topic`, in order.
    pub fn topic_messages<'a>(
        &'a self,
        topic: &'a str,
    ) -> Result<impl Iterator<Item = mcap::Message<'static>> + 'a, ReadError> {
        let stream = mcap::MessageStream::new(&self.data).map_err(|source| ReadError::Mcap {
            path: self.path.clone(),
            source,
        })?;
        Ok(stream
            .map_while(Result::ok)
            .filter(move |m| m.channel.topic == topic))
    }

    /// The file's bytes, as read.
    pub fn bytes(&self) -> &[u8] {
        &self.data
    }

    pub fn path(&self) -> &Path {
        &self.path
    }
}
