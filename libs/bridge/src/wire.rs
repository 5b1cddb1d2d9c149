//! What crosses the link besides the payloads' bytes: a short text header in each Zenoh
//! sample's attachment, checked at the far end.
//!
//! - `data SERVICE TYPE_NAME`: the payload is that topic's `#[repr(C)]` bytes; the far end
//!   takes it only if the type name and the size are its own for that service.
//! - `hello NONCE` (on the hello key): a receiving end that just started asks the sending
//!   end for the latched state ([`crate::Latch`]), once per nonce.
//! - `welcome NONCE`: the sending end has sent the latched state for that hello; live
//!   messages follow.
//! - `bye`: the sending end is stopping (its run is over).

use crate::route::{BridgedTopic, Side};

/// One header, decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Header<'a> {
    Data {
        service: &'a str,
        type_name: &'a str,
    },
    Hello {
        nonce: u64,
    },
    Welcome {
        nonce: u64,
    },
    Bye,
}

impl Header<'_> {
    /// The header's text.
    pub fn encode(&self) -> String {
        match self {
            Self::Data { service, type_name } => format!("data {service} {type_name}"),
            Self::Hello { nonce } => format!("hello {nonce}"),
            Self::Welcome { nonce } => format!("welcome {nonce}"),
            Self::Bye => "bye".to_owned(),
        }
    }
}

/// Why a message from the far end was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum WireDecodeError {
    #[error("a message without a readable header (`{0}`): is the far end an agp bridge?")]
    Malformed(String),
    #[error(
        "the far end sends `{service}`, which this end does not carry: give both ends the same `--topics`"
    )]
    NotCarried { service: String },
    #[error(
        "the far end sends `{service}`, which this end sends too: one bridge must be `--side robot`, the other `--side planner`"
    )]
    SameSide { service: String },
    #[error(
        "the far end sends `{service}` as `{far}`, this end knows it as `{near}`: build both ends from the same agp"
    )]
    TypeMismatch {
        service: String,
        far: String,
        near: &'static str,
    },
    #[error(
        "the far end sends `{service}` (`{type_name}`) in {far} bytes, this end's is {near} bytes: build both ends from the same agp"
    )]
    SizeMismatch {
        service: String,
        type_name: &'static str,
        far: usize,
        near: usize,
    },
}

/// Decodes a header's text.
pub fn decode(text: &[u8]) -> Result<Header<'_>, WireDecodeError> {
    let malformed = || WireDecodeError::Malformed(String::from_utf8_lossy(text).into_owned());
    let s = std::str::from_utf8(text).map_err(|_| malformed())?;
    let mut words = s.split(' ');
    let header = match (words.next(), words.next(), words.next()) {
        (Some("data"), Some(service), Some(type_name)) => Header::Data { service, type_name },
        (Some("hello"), Some(n), None) => Header::Hello {
            nonce: n.parse().map_err(|_| malformed())?,
        },
        (Some("welcome"), Some(n), None) => Header::Welcome {
            nonce: n.parse().map_err(|_| malformed())?,
        },
        (Some("bye"), None, None) => Header::Bye,
        _ => return Err(malformed()),
    };
    if words.next().is_some() {
        return Err(malformed());
    }
    Ok(header)
}

/// The index in `topics` of the topic a data message from the far end belongs to, once its
/// service, type name and size are checked against this end's (`side`).
pub fn check_data(
    topics: &[BridgedTopic],
    side: Side,
    service: &str,
    type_name: &str,
    len: usize,
) -> Result<usize, WireDecodeError> {
    let Some(i) = topics.iter().position(|t| t.service == service) else {
        return Err(WireDecodeError::NotCarried {
            service: service.to_owned(),
        });
    };
    let t = &topics[i];
    if t.from == side {
        return Err(WireDecodeError::SameSide {
            service: service.to_owned(),
        });
    }
    if t.type_name != type_name {
        return Err(WireDecodeError::TypeMismatch {
            service: service.to_owned(),
            far: type_name.to_owned(),
            near: t.type_name,
        });
    }
    if t.size != len {
        return Err(WireDecodeError::SizeMismatch {
            service: service.to_owned(),
            type_name: t.type_name,
            far: len,
            near: t.size,
        });
    }
    Ok(i)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::route::{all_topics, bridged_topic};

    #[test]
    fn every_header_survives_its_text() {
        let frames = bridged_topic("ir_frames").expect("carried");
        let headers = [
            Header::Data {
                service: frames.service,
                type_name: frames.type_name,
            },
            Header::Hello { nonce: 7 },
            Header::Welcome { nonce: u64::MAX },
            Header::Bye,
        ];
        for h in headers {
            let text = h.encode();
            assert_eq!(decode(text.as_bytes()), Ok(h));
        }
    }

    #[test]
    fn a_header_of_unknown_words_is_malformed() {
        for bad in [
            "",
            "data agp/ir_frames",
            "hello x",
            "bye now",
            "welcome 1 2",
        ] {
            assert!(matches!(
                decode(bad.as_bytes()),
                Err(WireDecodeError::Malformed(_))
            ));
        }
    }

    #[test]
    fn a_frame_from_the_robot_is_taken_by_the_planner_side_only_with_its_own_type_and_size() {
        let topics = all_topics();
        let f = bridged_topic("ir_frames").expect("carried");
        let at = check_data(&topics, Side::Planner, f.service, f.type_name, f.size);
        assert_eq!(at.map(|i| topics[i].name), Ok("ir_frames"));
        assert!(matches!(
            check_data(&topics, Side::Robot, f.service, f.type_name, f.size),
            Err(WireDecodeError::SameSide { .. })
        ));
        assert!(matches!(
            check_data(&topics, Side::Planner, f.service, "agp::IrFrame.v1", f.size),
            Err(WireDecodeError::TypeMismatch { .. })
        ));
        assert!(matches!(
            check_data(&topics, Side::Planner, f.service, f.type_name, f.size - 8),
            Err(WireDecodeError::SizeMismatch { .. })
        ));
        let only_commands = [bridged_topic("motor_commands").expect("carried")];
        assert!(matches!(
            check_data(
                &only_commands,
                Side::Planner,
                f.service,
                f.type_name,
                f.size
            ),
            Err(WireDecodeError::NotCarried { .. })
        ));
    }
}
