//! What the supervisor adds to a launch file's plan once `agp_launch` has read it: the bridge's checks of a `remote` entry, and each planner's own `--check`, which runs a process.

use agp_launch::{
    LaunchConfig, LaunchConfigParseError, LaunchFault, LaunchFaultKind, RemoteChecks,
};

/// The bridge's checks of a `remote` entry (endpoint, topics, the side's keys), handed to
/// [`agp_launch::LaunchOptions::remote_checks`] by every command that loads a launch file.
pub const BRIDGE_CHECKS: RemoteChecks = RemoteChecks {
    endpoint: |endpoint| agp_bridge::Endpoint::check(endpoint).map_err(|e| e.to_string()),
    topics: |topics| {
        agp_bridge::parse_topics(topics)
            .map(drop)
            .map_err(|e| e.to_string())
    },
    keys: |dir, side| {
        let side =
            agp_bridge::Side::parse(side).ok_or_else(|| format!("unknown bridge side `{side}`"))?;
        agp_bridge::TlsKeys::load(dir, side)
            .map(drop)
            .map_err(|e| e.to_string())
    },
    security_fault: agp_bridge::Endpoint::security_fault,
};

/// The bridge's binary, `agp-bridge`, beside the `agp` at `agp`: `agp bridge` runs it (a
/// binary of its own, so that `agp` links no Zenoh).
pub fn bridge_binary(agp: &std::path::Path) -> std::path::PathBuf {
    agp.with_file_name("agp-bridge")
}

/// How to build `agp-bridge` when it is not beside the `agp` at `agp`.
pub fn build_the_bridge_hint(agp: &std::path::Path) -> String {
    let release = agp
        .parent()
        .and_then(|d| d.file_name())
        .is_some_and(|d| d == "release");
    format!(
        "the bridge binary {} is not built: build it with `cargo build{} --workspace --bins` (the first command of the README builds no bridge)",
        bridge_binary(agp).display(),
        if release { " --release" } else { "" }
    )
}

/// Why process `p` of a plan cannot start, if it is an `agp bridge` and `agp-bridge` is
/// not built beside its `agp` (an `agp-bridge` written out is its own executable, which
/// the launch file's checks found).
fn missing_bridge(p: &agp_launch::ProcessConfig) -> Option<String> {
    (p.is_bridge() && !bridge_binary(&p.exec).is_file()).then(|| build_the_bridge_hint(&p.exec))
}

/// The checks of a launch file's plan that start processes.
pub trait CheckProcesses {
    /// Asks every agp planner of the file whether its arguments run on the file's clock
    /// (`agp-planner --check` with the context the run would give it): a task in realtime
    /// runs, the learning phase does not. Run before anything starts; every refusal names
    /// the process's line.
    fn check_processes(&self) -> Result<(), LaunchConfigParseError>;
}

impl CheckProcesses for LaunchConfig {
    fn check_processes(&self) -> Result<(), LaunchConfigParseError> {
        let mut faults = Vec::new();
        for p in &self.processes {
            if let Some(reason) = missing_bridge(p) {
                faults.push(LaunchFault {
                    line: Some(p.line),
                    kind: LaunchFaultKind::ProcessRefused {
                        process: p.name.clone(),
                        reason,
                    },
                });
                continue;
            }
            if p.exec.file_stem().and_then(|s| s.to_str()) != Some("agp-planner") {
                continue;
            }
            let out = std::process::Command::new(&p.exec)
                .arg("--check")
                .args(&p.args)
                .envs(&p.env)
                .envs(self.context_env(p))
                .stdin(std::process::Stdio::null())
                .stdout(std::process::Stdio::null())
                .stderr(std::process::Stdio::piped())
                .output();
            let reason = match out {
                Ok(o) if o.status.success() => continue,
                Ok(o) => {
                    let text = String::from_utf8_lossy(&o.stderr);
                    // The first line says it (clap's usage follows it).
                    text.lines()
                        .map(str::trim)
                        .find(|l| !l.is_empty())
                        .map(|l| {
                            l.trim_start_matches("agp-planner: ")
                                .trim_start_matches("error: ")
                                .to_owned()
                        })
                        .unwrap_or_else(|| format!("`--check` ended with {}", o.status))
                }
                Err(e) => format!("cannot run `{} --check`: {e}", p.exec.display()),
            };
            faults.push(LaunchFault {
                line: Some(p.line),
                kind: LaunchFaultKind::ProcessRefused {
                    process: p.name.clone(),
                    reason,
                },
            });
        }
        if faults.is_empty() {
            Ok(())
        } else {
            Err(LaunchConfigParseError {
                file: self.file.clone(),
                faults,
            })
        }
    }
}

#[cfg(test)]
use agp_launch::LaunchOptions;

#[cfg(test)]
#[path = "../../../libs/launch/tests/fixture/mod.rs"]
mod fixture;

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    use super::fixture::Fixture;

    /// A folder holding a launch file and the executables `bin/agp` and `bin/agp-fake`,
    /// its launch files parsed with the bridge's checks.
    fn new_fixture() -> Fixture {
        Fixture::new(&["bin/agp-fake", "bin/agp"], Some(BRIDGE_CHECKS))
    }

    /// A file whose planner is remote: physics here, the planner reached through the bridge.
    const REMOTE: &str = "instance = \"lab\"\nscenario = \"triangle\"\n\
        [[process]]\nname = \"physics\"\nexec = \"agp-fake\"\n\
        [[process]]\nname = \"planner\"\n\
        remote = { role = \"planner\", listen = \"tcp/127.0.0.1:7447\", insecure = true }\nends_run = true\n";

    #[test]
    fn a_remote_planner_runs_agp_bridge_on_the_robot_side_in_its_place() {
        let f = new_fixture();
        let config = f.parse(REMOTE).expect("a valid file");
        let planner = &config.processes[1];
        assert_eq!(planner.name, "planner");
        assert_eq!(planner.exec, f.path().join("bin/agp"));
        assert!(planner.ends_run);
        let expected = [
            "bridge",
            "--side",
            "robot",
            "--listen",
            "tcp/127.0.0.1:7447",
            "--topics",
            "all",
            "--link",
            "agp",
            "--insecure",
        ];
        assert_eq!(planner.args, expected);
        // Physics runs here: this supervisor owns the goals.
        assert!(!config.robot_is_remote());
        let text = REMOTE.replace(
            "role = \"planner\", listen = \"tcp/127.0.0.1:7447\"",
            "role = \"robot\", connect = \"tcp/127.0.0.1:7447\", topics = [\"ir_frames\", \"motor_commands\"], link = \"lab2\"",
        );
        let config = f.parse(&text).expect("a valid file");
        let expected = [
            "bridge",
            "--side",
            "planner",
            "--connect",
            "tcp/127.0.0.1:7447",
            "--topics",
            "ir_frames,motor_commands",
            "--link",
            "lab2",
            "--insecure",
        ];
        assert_eq!(config.processes[1].args, expected);
        // Physics runs under the far supervisor, which owns the goals.
        assert!(config.robot_is_remote());
    }

    #[test]
    fn a_remote_process_without_agp_bridge_beside_agp_is_refused_on_its_line_saying_how_to_build_it()
     {
        let f = new_fixture();
        let config = f.parse(REMOTE).expect("a valid file");
        let e = config.check_processes().expect_err("no agp-bridge in bin/");
        let shown = e.to_string();
        assert_eq!(e.faults.len(), 1, "{shown}");
        assert_eq!(e.faults[0].line, Some(7), "{shown}");
        assert!(shown.contains("agp-bridge is not built"), "{shown}");
        assert!(shown.contains("cargo build --workspace --bins"), "{shown}");
        // Beside agp, it starts.
        let f = Fixture::new(
            &["bin/agp-fake", "bin/agp", "bin/agp-bridge"],
            Some(BRIDGE_CHECKS),
        );
        let config = f.parse(REMOTE).expect("a valid file");
        config.check_processes().expect("agp-bridge is there");
    }

    #[test]
    fn a_remote_process_with_a_bad_role_endpoint_topic_or_an_exec_is_refused_on_its_line() {
        let f = new_fixture();
        let cases = [
            (
                "role = \"planner\"",
                "role = \"camera\"",
                "unknown remote role `camera`",
            ),
            (
                "listen = \"tcp/127.0.0.1:7447\"",
                "listen = \"udp/127.0.0.1:7447\"",
                "is not a TLS or TCP endpoint",
            ),
            (
                "listen = \"tcp/127.0.0.1:7447\"",
                "listen = \"tcp/127.0.0.1:0\"",
                "has no port",
            ),
            (
                "listen = \"tcp/127.0.0.1:7447\"",
                "listen = \"tcp/127.0.0.1:7447\", connect = \"tcp/127.0.0.1:7448\"",
                "needs one of `listen` and `connect`",
            ),
            (
                " }\nends_run",
                ", topics = [\"ground_truth\"] }\nends_run",
                "unknown topic `ground_truth`",
            ),
            (
                " }\nends_run",
                ", link = \"a/b\" }\nends_run",
                "bad `remote.link` `a/b`",
            ),
        ];
        for (from, to, says) in cases {
            let (line, shown, kind) = f.fault(&REMOTE.replace(from, to));
            assert_eq!(line, Some(8), "{shown}");
            assert!(matches!(kind, LaunchFaultKind::BadRemote { .. }), "{shown}");
            assert!(shown.contains(says), "{shown}");
        }
        let (line, shown, _) =
            f.fault(&REMOTE.replace("remote =", "exec = \"agp-fake\"\nremote ="));
        assert_eq!(line, Some(8), "{shown}");
        assert!(shown.contains("no `exec`"), "{shown}");
        let (line, shown, _) = f.fault(&REMOTE.replace("remote = ", "args = [\"x\"]\nremote = "));
        assert_eq!(line, Some(8), "{shown}");
        assert!(shown.contains("no `args`"), "{shown}");
        let text = REMOTE.replace(
            "remote = { role = \"planner\", listen = \"tcp/127.0.0.1:7447\", insecure = true }\n",
            "",
        );
        let (line, shown, _) = f.fault(&text);
        assert_eq!(line, Some(7), "{shown}");
        assert!(
            shown.contains("no `exec`: name an executable, or `remote"),
            "{shown}"
        );
    }

    #[test]
    fn a_remote_over_tls_takes_its_key_folder_from_beside_the_launch_file() {
        let f = new_fixture();
        agp_bridge::keygen(&f.path().join("keys"), &[]).expect("keygen");
        let text = REMOTE.replace(
            "listen = \"tcp/127.0.0.1:7447\", insecure = true",
            "listen = \"tls/127.0.0.1:7447\", tls = \"keys\"",
        );
        let config = f.parse(&text).expect("a valid file");
        let args = &config.processes[1].args;
        let at = args.iter().position(|a| a == "--tls").expect("--tls");
        assert_eq!(
            args[at + 1],
            f.path().join("keys").display().to_string(),
            "{args:?}"
        );
        assert!(args.contains(&"tls/127.0.0.1:7447".to_owned()), "{args:?}");
        assert!(!args.contains(&"--insecure".to_owned()), "{args:?}");
    }

    #[test]
    fn a_remote_without_tls_or_insecure_or_with_an_open_key_is_refused_on_its_line() {
        let f = new_fixture();
        let keys = f.path().join("keys");
        agp_bridge::keygen(&keys, &[]).expect("keygen");
        let (line, shown, _) =
            f.fault(&REMOTE.replace("\", insecure = true", "\", tls = \"keys\""));
        assert_eq!(line, Some(8), "{shown}");
        assert!(
            shown.contains("is plain TCP, but the link's keys were given"),
            "{shown}"
        );
        let open_key = keys.join(agp_bridge::tls::key_file(agp_bridge::Side::Robot));
        std::fs::set_permissions(&open_key, std::fs::Permissions::from_mode(0o644)).expect("chmod");
        let open_key = open_key.display().to_string();
        let cases = [
            (", insecure = true", "", "`remote` needs `tls = \"DIR\"`"),
            (
                "tcp/127.0.0.1:7447\", insecure = true",
                "tls/127.0.0.1:7447\", tls = \"keys\"",
                open_key.as_str(),
            ),
            (
                "tcp/127.0.0.1:7447\", insecure = true",
                "tls/127.0.0.1:7447\", tls = \"elsewhere\"",
                "no such file: make the key folder with `agp bridge keygen DIR`",
            ),
            (
                "tcp/127.0.0.1:7447\", insecure = true",
                "tls/127.0.0.1:7447\", insecure = true",
                "is a TLS endpoint: give the link's keys",
            ),
            (
                ", insecure = true",
                ", insecure = true, tls = \"keys\"",
                "names both `tls` and `insecure = true`",
            ),
        ];
        for (from, to, says) in cases {
            let (line, shown, kind) = f.fault(&REMOTE.replace(from, to));
            assert_eq!(line, Some(8), "{shown}");
            assert!(matches!(kind, LaunchFaultKind::BadRemote { .. }), "{shown}");
            assert!(shown.contains(says), "{shown}");
        }
    }
}
