//! `agp bridge keygen DIR`: a key folder for a TLS link (its files: [`crate::tls`]), made
//! with rcgen. Only with the `link` feature: the `agp` supervisor reads key folders
//! ([`TlsKeys::load`]) but makes none.

use std::fs::{self, OpenOptions};
use std::io::Write;
use std::os::unix::fs::{OpenOptionsExt, PermissionsExt};
use std::path::{Path, PathBuf};

use rcgen::{
    BasicConstraints, CertificateParams, DnType, ExtendedKeyUsagePurpose, IsCa, Issuer, KeyPair,
    KeyUsagePurpose,
};

use crate::route::Side;
use crate::tls::{CA_FILE, DEFAULT_HOSTS, TlsError, VALID_YEARS, cert_file, io_err, key_file};

/// Makes a key folder at `dir` (0700; created if missing, refused if it already holds keys):
/// a CA, and a certificate and private key for each side, valid for the loopback
/// ([`DEFAULT_HOSTS`]) and each of `hosts` (names or addresses the far end connects by).
/// Returns the files written.
pub fn keygen(dir: &Path, hosts: &[String]) -> Result<Vec<PathBuf>, TlsError> {
    let mut names: Vec<String> = DEFAULT_HOSTS.iter().map(|h| (*h).to_owned()).collect();
    for h in hosts {
        if h.is_empty() || h.chars().any(|c| c.is_whitespace() || c == '/') {
            return Err(TlsError::Host {
                host: h.clone(),
                detail: "a DNS name or an IP address".to_owned(),
            });
        }
        if !names.contains(h) {
            names.push(h.clone());
        }
    }
    let files = [
        CA_FILE.to_owned(),
        cert_file(Side::Robot),
        key_file(Side::Robot),
        cert_file(Side::Planner),
        key_file(Side::Planner),
    ];
    if files.iter().any(|f| dir.join(f).exists()) {
        return Err(TlsError::Exists(dir.to_owned()));
    }
    fs::create_dir_all(dir).map_err(io_err(dir))?;
    fs::set_permissions(dir, fs::Permissions::from_mode(0o700)).map_err(io_err(dir))?;

    let rc = |e: rcgen::Error| TlsError::Rcgen(e.to_string());
    let year = this_year();
    let validity = |p: &mut CertificateParams| {
        p.not_before = rcgen::date_time_ymd(year - 1, 1, 1);
        p.not_after = rcgen::date_time_ymd(year + VALID_YEARS, 1, 1);
    };
    let ca_key = KeyPair::generate().map_err(rc)?;
    let mut ca = CertificateParams::new(Vec::<String>::new()).map_err(rc)?;
    ca.distinguished_name
        .push(DnType::CommonName, "agp bridge link CA");
    ca.is_ca = IsCa::Ca(BasicConstraints::Constrained(0));
    ca.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign];
    validity(&mut ca);
    let ca_cert = ca.self_signed(&ca_key).map_err(rc)?;
    let issuer = Issuer::from_params(&ca, &ca_key);

    let mut written = Vec::new();
    write_file(&dir.join(CA_FILE), ca_cert.pem().as_bytes(), 0o644)?;
    written.push(dir.join(CA_FILE));
    for side in [Side::Robot, Side::Planner] {
        let key = KeyPair::generate().map_err(rc)?;
        let mut p = CertificateParams::new(names.clone()).map_err(|e| TlsError::Host {
            host: names.join(", "),
            detail: e.to_string(),
        })?;
        p.distinguished_name
            .push(DnType::CommonName, format!("agp bridge {}", side.name()));
        p.is_ca = IsCa::NoCa;
        p.key_usages = vec![KeyUsagePurpose::DigitalSignature];
        // Each side listens or connects, as its launch file says: a server and a client.
        p.extended_key_usages = vec![
            ExtendedKeyUsagePurpose::ServerAuth,
            ExtendedKeyUsagePurpose::ClientAuth,
        ];
        validity(&mut p);
        let cert = p.signed_by(&key, &issuer).map_err(rc)?;
        let (cert_path, key_path) = (dir.join(cert_file(side)), dir.join(key_file(side)));
        write_file(&key_path, key.serialize_pem().as_bytes(), 0o600)?;
        write_file(&cert_path, cert.pem().as_bytes(), 0o644)?;
        written.push(cert_path);
        written.push(key_path);
    }
    Ok(written)
}

/// Writes a new file with `mode` from its creation (a key is never readable by others, not
/// even for a moment).
fn write_file(path: &Path, bytes: &[u8], mode: u32) -> Result<(), TlsError> {
    let mut f = OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(mode)
        .open(path)
        .map_err(io_err(path))?;
    // The umask may have taken bits away, never added any; make the mode exact.
    f.set_permissions(fs::Permissions::from_mode(mode))
        .map_err(io_err(path))?;
    f.write_all(bytes).map_err(io_err(path))?;
    f.sync_all().map_err(io_err(path))
}

/// The current year (UTC), from the system clock.
fn this_year() -> i32 {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    year_of(secs)
}

/// The UTC year of `secs` seconds after 1970-01-01 (Howard Hinnant's days-to-civil
/// algorithm, the year only).
fn year_of(secs: u64) -> i32 {
    let days = (secs / 86_400) as i64 + 719_468;
    let era = days.div_euclid(146_097);
    let doe = days.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let year = yoe + era * 400 + i64::from(mp >= 10);
    i32::try_from(year).unwrap_or(i32::MAX)
}

#[cfg(test)]
mod tests {
    use std::os::unix::fs::MetadataExt;

    use super::*;
    use crate::tls::TlsKeys;

    #[test]
    fn keygen_writes_a_ca_and_a_pair_per_side_with_private_keys_closed_to_others() {
        let tmp = tempfile::tempdir().expect("temp dir");
        let dir = tmp.path().join("keys");
        let written = keygen(&dir, &["robot.lab".to_owned()]).expect("keygen");
        assert_eq!(written.len(), 5);
        let mode = |p: &Path| fs::metadata(p).expect("meta").mode() & 0o777;
        assert_eq!(mode(&dir), 0o700);
        for side in [Side::Robot, Side::Planner] {
            let keys = TlsKeys::load(&dir, side).expect("loads");
            assert_eq!(mode(&keys.key), 0o600);
            assert_eq!(mode(&keys.cert), 0o644);
        }
        // A second keygen into the same folder overwrites nothing.
        assert!(matches!(keygen(&dir, &[]), Err(TlsError::Exists(_))));
    }

    #[test]
    fn a_private_key_readable_by_others_is_refused_naming_the_file() {
        let tmp = tempfile::tempdir().expect("temp dir");
        keygen(tmp.path(), &[]).expect("keygen");
        let key = tmp.path().join(key_file(Side::Planner));
        fs::set_permissions(&key, fs::Permissions::from_mode(0o644)).expect("chmod");
        let e = TlsKeys::load(tmp.path(), Side::Planner).expect_err("refused");
        let shown = e.to_string();
        assert!(shown.contains(&key.display().to_string()), "{shown}");
        assert!(shown.contains("chmod 600"), "{shown}");
        // The other side's key is still fine.
        assert!(TlsKeys::load(tmp.path(), Side::Robot).is_ok());
    }

    #[test]
    fn the_year_of_known_instants_is_their_calendar_year() {
        assert_eq!(year_of(0), 1970);
        assert_eq!(year_of(951_782_400), 2000); // 2000-02-29 00:00
        assert_eq!(year_of(1_735_689_599), 2024); // 2024-12-31 23:59:59
        assert_eq!(year_of(1_735_689_600), 2025); // 2025-01-01 00:00
    }
}
