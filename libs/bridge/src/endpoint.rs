//! Where the Zenoh link runs: one end listens on an endpoint, the other connects to it;
//! nothing is scouted. `tls/HOST:PORT` is Zenoh's TLS transport with mutual authentication
//! (both ends show a certificate of the link's CA, [`crate::tls`]); `tcp/HOST:PORT` is plain
//! TCP, with no authentication and no encryption.

#[cfg(feature = "link")]
use crate::tls::TlsKeys;

/// One end of the link: `tls/HOST:PORT` or `tcp/HOST:PORT`, listened on or connected to.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Endpoint {
    Listen(String),
    Connect(String),
}

/// Why an endpoint was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum EndpointParseError {
    #[error(
        "`{0}` is not a TLS or TCP endpoint: expected `tls/HOST:PORT` (or `tcp/HOST:PORT`, insecure), e.g. `tls/127.0.0.1:7447`"
    )]
    NotTcp(String),
    #[error("`{0}` has no port from 1 to 65535: expected `tls/HOST:PORT` or `tcp/HOST:PORT`")]
    BadPort(String),
}

impl Endpoint {
    /// The endpoint as Zenoh names it.
    pub fn locator(&self) -> &str {
        match self {
            Self::Listen(l) | Self::Connect(l) => l,
        }
    }

    /// Whether the endpoint is Zenoh's TLS transport (`tls/`), not plain TCP.
    pub fn is_tls(&self) -> bool {
        self.locator().starts_with("tls/")
    }

    /// Checks `tls/HOST:PORT` or `tcp/HOST:PORT` (an IPv6 host in brackets:
    /// `tls/[::1]:7447`).
    pub fn check(locator: &str) -> Result<(), EndpointParseError> {
        let Some(rest) = locator
            .strip_prefix("tls/")
            .or_else(|| locator.strip_prefix("tcp/"))
        else {
            return Err(EndpointParseError::NotTcp(locator.to_owned()));
        };
        let Some((host, port)) = rest.rsplit_once(':') else {
            return Err(EndpointParseError::NotTcp(locator.to_owned()));
        };
        if host.is_empty() || host.contains('/') || host.contains('#') || host.contains('?') {
            return Err(EndpointParseError::NotTcp(locator.to_owned()));
        }
        match port.parse::<u16>() {
            Ok(p) if p > 0 => Ok(()),
            _ => Err(EndpointParseError::BadPort(locator.to_owned())),
        }
    }

    /// Why `locator` does not fit the link's security, if it does not: a `tls/` endpoint
    /// needs the link's keys, a `tcp/` endpoint (plain TCP) takes none.
    pub fn security_fault(locator: &str, keys: bool) -> Option<String> {
        match (locator.starts_with("tls/"), keys) {
            (true, false) => Some(format!(
                "`{locator}` is a TLS endpoint: give the link's keys (`tls = \"DIR\"`, `--tls DIR`; made by `agp bridge keygen DIR`)"
            )),
            (false, true) => Some(format!(
                "`{locator}` is plain TCP, but the link's keys were given: write `tls/{}`",
                locator.trim_start_matches("tcp/")
            )),
            _ => None,
        }
    }

    /// A listening end, checked.
    pub fn listen(locator: &str) -> Result<Self, EndpointParseError> {
        Self::check(locator)?;
        Ok(Self::Listen(locator.to_owned()))
    }

    /// A connecting end, checked.
    pub fn connect(locator: &str) -> Result<Self, EndpointParseError> {
        Self::check(locator)?;
        Ok(Self::Connect(locator.to_owned()))
    }

    #[cfg(feature = "link")]
    /// The Zenoh configuration of this end: a peer that listens on this endpoint only, or
    /// connects to it only (and listens nowhere), with multicast and gossip scouting off,
    /// so the bridge opens no socket but the one named. A `tls/` endpoint takes `tls`, the
    /// link's keys of this side, and requires mutual authentication; a `tcp/` one takes none.
    pub fn zenoh_config(&self, tls: Option<&TlsKeys>) -> Result<zenoh::Config, String> {
        let mut c = zenoh::Config::default();
        let json = |v: &str| serde_json_string(v);
        let (listen, connect) = match self {
            Self::Listen(l) => (format!("[{}]", json(l)), "[]".to_owned()),
            Self::Connect(l) => ("[]".to_owned(), format!("[{}]", json(l))),
        };
        for (key, value) in [
            ("mode", "\"peer\"".to_owned()),
            ("listen/endpoints", listen),
            ("connect/endpoints", connect),
            ("scouting/multicast/enabled", "false".to_owned()),
            ("scouting/gossip/enabled", "false".to_owned()),
            // A connecting end may start before the listening one: it retries for ever.
            ("connect/timeout_ms", "-1".to_owned()),
            ("connect/exit_on_failure", "false".to_owned()),
            // And after a lost link (a cut, the far end restarted) it tries again every
            // 100 ms at first, at most every second (Zenoh's default waits 1 s, then up to 4).
            (
                "connect/retry",
                "{ period_init_ms: 100, period_max_ms: 1000, period_increase_factor: 2.0 }"
                    .to_owned(),
            ),
        ] {
            c.insert_json5(key, &value)
                .map_err(|e| format!("zenoh config `{key}`: {e}"))?;
        }
        match (self.is_tls(), tls) {
            (true, Some(keys)) => {
                let path = |p: &std::path::Path| json(&p.display().to_string());
                for (key, value) in [
                    ("root_ca_certificate", path(&keys.ca)),
                    ("listen_certificate", path(&keys.cert)),
                    ("listen_private_key", path(&keys.key)),
                    ("connect_certificate", path(&keys.cert)),
                    ("connect_private_key", path(&keys.key)),
                    ("enable_mtls", "true".to_owned()),
                    ("verify_name_on_connect", "true".to_owned()),
                ] {
                    c.insert_json5(&format!("transport/link/tls/{key}"), &value)
                        .map_err(|e| format!("zenoh config `{key}`: {e}"))?;
                }
            }
            (_, keys) => {
                if let Some(fault) = Self::security_fault(self.locator(), keys.is_some()) {
                    return Err(fault);
                }
            }
        }
        Ok(c)
    }
}

#[cfg(feature = "link")]
/// `s` as a JSON string literal (the locators hold no quote or backslash once checked, but
/// the escaping costs nothing).
fn serde_json_string(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_tcp_endpoint_with_a_port_is_taken_and_anything_else_refused() {
        assert!(Endpoint::listen("tcp/127.0.0.1:7447").is_ok());
        assert!(Endpoint::connect("tcp/[::1]:7447").is_ok());
        assert!(Endpoint::connect("tls/[::1]:7447").is_ok_and(|e| e.is_tls()));
        assert!(Endpoint::listen("tcp/127.0.0.1:7447").is_ok_and(|e| !e.is_tls()));
        assert!(matches!(
            Endpoint::listen("udp/127.0.0.1:7447"),
            Err(EndpointParseError::NotTcp(_))
        ));
        assert!(matches!(
            Endpoint::listen("tcp/127.0.0.1"),
            Err(EndpointParseError::NotTcp(_))
        ));
        assert!(matches!(
            Endpoint::listen("tcp/127.0.0.1:0"),
            Err(EndpointParseError::BadPort(_))
        ));
        assert!(matches!(
            Endpoint::listen("tcp/127.0.0.1:70000"),
            Err(EndpointParseError::BadPort(_))
        ));
    }
}
