//! `agp bridge` over Zenoh's TLS transport with mutual authentication, between two instances
//! on this machine: keys made by `agp bridge keygen`, a placement across the link, strangers
//! kept out (a Zenoh peer without a certificate, and one whose certificate another CA
//! signed), and the launch files and key files that are refused before anything starts.

use std::path::{Path, PathBuf};
use std::time::Duration;

use agp_tests::{
    AgpUp, LaunchDir, StepLog, assert_every_step_applied_once, assert_placed, count_instance_files,
    learned_ag, run_agp,
};
use zenoh::Wait;
use zenoh::bytes::ZBytes;

/// Safety net of the short waits; the checks never depend on it.
const TIMEOUT: Duration = Duration::from_secs(60);

/// Safety net of a placement across the bridge.
const PLACE_TIMEOUT: Duration = Duration::from_secs(600);

/// How long a stranger's Zenoh session tries to join before it gives up (a safety net: the
/// handshake is refused at once; the session only retries until then).
const STRANGER_TRIES_MS: u64 = 3_000;

/// A port of this test process's own: `k` (0-4) apart for each test.
fn port(k: u16) -> u16 {
    30_000 + (std::process::id() % 7_000) as u16 * 5 + k
}

/// An instance name of this test process's own, within the 20 characters a name may have
/// whatever the pid: `tls`, `what` without dashes cut to 8 letters, and the pid's last five
/// digits.
fn instance(what: &str) -> String {
    let what: String = what.chars().filter(|c| *c != '-').take(8).collect();
    format!("tls{what}-{}", std::process::id() % 100_000)
}

/// `agp bridge keygen DIR` in `dir`.
fn keygen(dir: &Path, keys: &Path) {
    let out = run_agp(
        dir,
        &["bridge", "keygen", keys.to_str().expect("a UTF-8 path")],
        TIMEOUT,
    );
    out.assert_success("`agp bridge keygen`");
}

/// Instance A: physics (logging every applied step), optionally the estimator serving `ag`;
/// the planner is remote, reached through the bridge listening on `port` with `security`
/// (`tls = "..."` or `insecure = true`). A's run ends when B's does.
fn robot_launch(instance: &str, ag: Option<&Path>, endpoint: &str, security: &str) -> String {
    let estimator = ag.map_or_else(String::new, |ag| {
        format!(
            "[[process]]\nname = \"estimator\"\nexec = \"agp-estimator\"\nargs = [\"--load\", \"{}\"]\n\n",
            ag.display()
        )
    });
    format!(
        "instance = \"{instance}\"\nscenario = \"triangle\"\n\n[clock]\nmode = \"lockstep\"\n\n\
         [[process]]\nname = \"physics\"\nexec = \"agp-physics\"\nargs = [\"--step-log\", \"steps.log\"]\n\n\
         {estimator}\
         [[process]]\nname = \"planner\"\n\
         remote = {{ role = \"planner\", listen = \"{endpoint}\", {security} }}\nends_run = true\n"
    )
}

/// Instance B: the affordance planner placing the triangle at the scenario's goal, physics
/// and estimator remote, reached by connecting to `endpoint` with `security`.
fn planner_launch(instance: &str, endpoint: &str, security: &str) -> String {
    format!(
        "instance = \"{instance}\"\nscenario = \"triangle\"\n\n[clock]\nmode = \"lockstep\"\n\n\
         [[process]]\nname = \"robot\"\n\
         remote = {{ role = \"robot\", connect = \"{endpoint}\", {security} }}\n\n\
         [[process]]\nname = \"planner\"\nexec = \"agp-planner\"\n\
         args = [\"--mode\", \"place\", \"--planner\", \"affordance\"]\nends_run = true\n"
    )
}

/// `tls = "DIR"` for a launch file.
fn tls(keys: &Path) -> String {
    format!("tls = \"{}\"", keys.display())
}

#[test]
fn a_planner_in_another_instance_joined_by_a_mutual_tls_bridge_places_the_object() {
    let ag = learned_ag("triangle");
    let keys_dir = tempfile::tempdir().expect("a temporary folder");
    let keys = keys_dir.path().join("keys");
    keygen(keys_dir.path(), &keys);
    let (a, b) = (instance("place-rob"), instance("place-pla"));
    let endpoint = format!("tls/127.0.0.1:{}", port(0));
    let robot = LaunchDir::new(&robot_launch(&a, Some(&ag), &endpoint, &tls(&keys)));
    let planner = LaunchDir::new(&planner_launch(&b, &endpoint, &tls(&keys)));
    let up_a = AgpUp::start(&robot.launch(), &[]);
    let up_b = AgpUp::start(&planner.launch(), &[]);
    let end_b = up_b.wait(PLACE_TIMEOUT);
    let end_a = up_a.wait(TIMEOUT);
    println!(
        "A:\n{}\n{}\nB:\n{}\n{}",
        end_a.stdout, end_a.stderr, end_b.stdout, end_b.stderr
    );
    assert!(
        end_b.stdout.contains("run over: `planner` finished it"),
        "{}",
        end_b.stderr
    );
    assert_eq!(end_a.status.code(), Some(0), "{}", end_a.stderr);
    // Both ends said they run on mutual TLS, and neither warned of plain TCP.
    for end in [&end_a, &end_b] {
        assert!(
            end.stdout.contains(&format!("{endpoint} (mutual TLS)")),
            "{}",
            end.stdout
        );
        assert!(!end.stderr.contains("plain TCP"), "{}", end.stderr);
    }
    let (mm, deg) = assert_placed(&robot.results(), &a, "triangle", &end_a.stdout);
    // Lockstep across the TLS link: no step lost or applied twice.
    let log = StepLog::new(robot.path().join("steps.log")).poll().to_vec();
    assert_every_step_applied_once(&log);
    assert_eq!(count_instance_files(&a), 0, "files of `{a}` remain");
    assert_eq!(count_instance_files(&b), 0, "files of `{b}` remain");
    println!(
        "placed across the TLS bridge: {} steps, final error {mm:.1} mm, {deg:.1} deg",
        log.len()
    );
}

/// A Zenoh peer of someone who is not on the link: it connects to `endpoint` trusting
/// `ca` (the link's CA certificate is no secret), showing `identity` (a certificate and its
/// key) if it has one. `give_up` makes opening fail when no link comes up; otherwise the
/// session keeps trying in the background.
fn stranger(
    endpoint: &str,
    ca: Option<&Path>,
    identity: Option<(PathBuf, PathBuf)>,
    give_up: bool,
) -> zenoh::Result<zenoh::Session> {
    let mut c = zenoh::Config::default();
    let q = |p: &Path| format!("\"{}\"", p.display());
    let mut set = vec![
        ("mode", "\"peer\"".to_owned()),
        ("listen/endpoints", "[]".to_owned()),
        ("connect/endpoints", format!("[\"{endpoint}\"]")),
        ("scouting/multicast/enabled", "false".to_owned()),
        ("scouting/gossip/enabled", "false".to_owned()),
        (
            "connect/timeout_ms",
            if give_up {
                STRANGER_TRIES_MS.to_string()
            } else {
                "-1".to_owned()
            },
        ),
        ("connect/exit_on_failure", give_up.to_string()),
    ];
    if let Some(ca) = ca {
        set.push(("transport/link/tls/root_ca_certificate", q(ca)));
    }
    if let Some((cert, key)) = &identity {
        set.push(("transport/link/tls/connect_certificate", q(cert)));
        set.push(("transport/link/tls/connect_private_key", q(key)));
        set.push(("transport/link/tls/enable_mtls", "true".to_owned()));
    }
    for (key, value) in set {
        c.insert_json5(key, &value).expect("a zenoh config key");
    }
    zenoh::open(c).wait()
}

/// What a stranger who reached the link would put on the robot side's key: a motor command
/// as the planner side's bridge sends it, then the planner side's `bye`, which would end
/// the robot's run.
fn publish_as_the_planner(session: &zenoh::Session) {
    let commands = agp_bridge::bridged_topic("motor_commands").expect("a bridged topic");
    let header = agp_bridge::wire::Header::Data {
        service: commands.service,
        type_name: commands.type_name,
    };
    let key = "agp/to_robot";
    session
        .put(key, vec![0u8; commands.size])
        .attachment(ZBytes::from(header.encode()))
        .wait()
        .expect("a put");
    session
        .put(key, Vec::<u8>::new())
        .attachment(ZBytes::from(agp_bridge::wire::Header::Bye.encode()))
        .wait()
        .expect("a put");
}

/// The robot side's `agp up` whose bridge listens on `endpoint` with `security`, once the
/// bridge said it is ready.
fn start_robot_side(dir: &LaunchDir, endpoint: &str) -> AgpUp {
    let mut up = AgpUp::start(&dir.launch(), &[]);
    up.wait_for_lines(&format!("listening on {endpoint}"), 1, TIMEOUT);
    up
}

/// `agp down` of instance `name`, and what its `agp up` printed.
fn down(dir: &LaunchDir, name: &str, up: AgpUp) -> agp_tests::Finished {
    let down = run_agp(dir.path(), &["down", "--instance", name], TIMEOUT);
    down.assert_success("agp down");
    up.wait(TIMEOUT)
}

#[test]
fn strangers_without_a_certificate_of_the_links_ca_cannot_join_the_link_nor_publish_into_the_instance()
 {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let (keys, other) = (dir.path().join("keys"), dir.path().join("other"));
    keygen(dir.path(), &keys);
    keygen(dir.path(), &other);
    let a = instance("strangers");
    let endpoint = format!("tls/127.0.0.1:{}", port(1));
    let robot = LaunchDir::new(&robot_launch(&a, None, &endpoint, &tls(&keys)));
    let up = start_robot_side(&robot, &endpoint);

    let ca = keys.join("ca.pem");
    // A peer without a certificate, and a peer with a certificate another CA signed (of
    // keygen's other folder); both trust the link's CA, so only the robot side refuses them.
    let no_certificate = stranger(&endpoint, Some(&ca), None, true);
    let other_ca = stranger(
        &endpoint,
        Some(&ca),
        Some((other.join("planner.pem"), other.join("planner-key.pem"))),
        true,
    );
    // Plain TCP to the TLS port: no link either.
    let plain = stranger(&endpoint.replace("tls/", "tcp/"), None, None, true);
    for (who, session) in [
        ("without a certificate", &no_certificate),
        ("with another CA's certificate", &other_ca),
        ("over plain TCP", &plain),
    ] {
        assert!(
            session.is_err(),
            "a stranger {who} opened a session with the robot side"
        );
        println!(
            "a stranger {who}: {}",
            session
                .as_ref()
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default()
        );
    }
    // The same client with the link's planner certificate joins: the strangers' failures
    // are their certificates', not the client's.
    let member = stranger(
        &endpoint,
        Some(&ca),
        Some((keys.join("planner.pem"), keys.join("planner-key.pem"))),
        true,
    )
    .expect("the planner's certificate joins the link");
    let joined = member.info().peers_zid().wait().count();
    assert_eq!(joined, 1, "the member sees the robot side's peer");
    member.close().wait().expect("close");

    // Strangers that keep trying and publish what a planner side would: a motor command,
    // and `bye`, which would end the robot's run. Their sessions never join the link.
    let persistent: Vec<zenoh::Session> = [
        None,
        Some((other.join("planner.pem"), other.join("planner-key.pem"))),
    ]
    .into_iter()
    .map(|identity| stranger(&endpoint, Some(&ca), identity, false).expect("a session"))
    .collect();
    for s in &persistent {
        publish_as_the_planner(s);
        assert_eq!(
            s.info().peers_zid().wait().count(),
            0,
            "a stranger joined the link"
        );
    }
    for s in persistent {
        s.close().wait().expect("close");
    }
    let end = down(&robot, &a, up);
    println!("A:\n{}\n{}", end.stdout, end.stderr);
    assert_eq!(end.status.code(), Some(0), "{}", end.stderr);
    // The robot side's bridge received nothing: no command, no `bye` (it was stopped, the
    // far end never ended it), and physics applied no step.
    assert!(
        end.stdout
            .contains(&format!("agp: bridge of instance `{a}` ended: stopped")),
        "{}",
        end.stdout
    );
    let received = end
        .stdout
        .lines()
        .find(|l| l.trim_start().starts_with("motor_commands "))
        .expect("the bridge's motor_commands line");
    assert!(
        received.trim_end().ends_with("received         0"),
        "{received}"
    );
    let mut log = StepLog::new(robot.path().join("steps.log"));
    assert!(log.is_empty(), "physics applied steps: {:?}", log.poll());
    assert_eq!(count_instance_files(&a), 0, "files of `{a}` remain");
}

#[test]
fn on_a_plain_tcp_bridge_a_stranger_reaches_the_instance_which_is_why_it_needs_insecure() {
    let a = instance("plain");
    let endpoint = format!("tcp/127.0.0.1:{}", port(2));
    let robot = LaunchDir::new(&robot_launch(&a, None, &endpoint, "insecure = true"));
    let up = start_robot_side(&robot, &endpoint);
    let session = stranger(&endpoint, None, None, true).expect("plain TCP lets anyone in");
    publish_as_the_planner(&session);
    // The stranger's `bye` ends the robot's run, as the planner side's would.
    let end = up.wait(TIMEOUT);
    session.close().wait().expect("close");
    println!("A:\n{}\n{}", end.stdout, end.stderr);
    assert!(
        end.stderr
            .contains("agp: warning: the bridge runs on plain TCP"),
        "{}",
        end.stderr
    );
    assert!(
        end.stdout.contains(&format!(
            "agp: bridge of instance `{a}` ended: the far end stopped"
        )),
        "{}",
        end.stdout
    );
    let received = end
        .stdout
        .lines()
        .find(|l| l.trim_start().starts_with("motor_commands "))
        .expect("the bridge's motor_commands line");
    assert!(
        received.trim_end().ends_with("received         1"),
        "{received}"
    );
    assert_eq!(count_instance_files(&a), 0, "files of `{a}` remain");
}

#[test]
fn a_private_key_open_to_others_and_a_remote_with_neither_tls_nor_insecure_are_refused_before_anything_starts()
 {
    use std::os::unix::fs::PermissionsExt;

    let dir = tempfile::tempdir().expect("a temporary folder");
    let keys = dir.path().join("keys");
    keygen(dir.path(), &keys);
    let key = keys.join("robot-key.pem");
    std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o644)).expect("chmod");
    let a = instance("refused");
    let endpoint = format!("tls/127.0.0.1:{}", port(3));

    // In a launch file: refused on the remote's line, naming the key file.
    let open_key = LaunchDir::new(&robot_launch(&a, None, &endpoint, &tls(&keys)));
    let remote_line = robot_launch(&a, None, &endpoint, &tls(&keys))
        .lines()
        .position(|l| l.starts_with("remote = "))
        .expect("a remote line")
        + 1;
    let up = run_agp(
        open_key.path(),
        &["up", open_key.launch().to_str().expect("UTF-8")],
        TIMEOUT,
    );
    assert_ne!(up.status.code(), Some(0), "{}", up.stdout);
    assert!(
        up.stderr.contains(&format!("launch.toml:{remote_line}:")),
        "{}",
        up.stderr
    );
    assert!(
        up.stderr
            .contains(&format!("run `chmod 600 {}`", key.display())),
        "{}",
        up.stderr
    );
    // By hand: `agp bridge --tls` refuses it too, naming it.
    let by_hand = run_agp(
        dir.path(),
        &[
            "bridge",
            "--instance",
            &a,
            "--side",
            "robot",
            "--listen",
            &endpoint,
            "--tls",
            keys.to_str().expect("UTF-8"),
        ],
        TIMEOUT,
    );
    assert_ne!(by_hand.status.code(), Some(0), "{}", by_hand.stdout);
    assert!(
        by_hand.stderr.contains(&key.display().to_string()),
        "{}",
        by_hand.stderr
    );

    // A remote with neither `tls` nor `insecure`: refused on its line.
    let neither = LaunchDir::new(&robot_launch(
        &a,
        None,
        &endpoint.replace("tls/", "tcp/"),
        "link = \"agp\"",
    ));
    let up = run_agp(
        neither.path(),
        &["up", neither.launch().to_str().expect("UTF-8")],
        TIMEOUT,
    );
    assert_ne!(up.status.code(), Some(0), "{}", up.stdout);
    assert!(
        up.stderr.contains(&format!(
            "launch.toml:{remote_line}: process `planner`: `remote` needs `tls = \"DIR\"`"
        )),
        "{}",
        up.stderr
    );
    // Nothing started: no file of the instance.
    assert_eq!(count_instance_files(&a), 0, "files of `{a}` remain");
}

#[test]
fn the_links_floor_is_a_bare_zenoh_ping_pong_over_tls_or_plain_tcp() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let keys = dir.path().join("keys");
    keygen(dir.path(), &keys);
    for (security, says) in [
        (vec!["--tls", keys.to_str().expect("UTF-8")], "(mutual TLS)"),
        (vec!["--insecure"], "(plain TCP)"),
    ] {
        let mut args = vec!["bridge", "floor", "--seconds", "0.2"];
        args.extend(security);
        let out = run_agp(dir.path(), &args, TIMEOUT);
        out.assert_success("`agp bridge floor`");
        println!("{}", out.stdout);
        assert!(out.stdout.contains(says), "{}", out.stdout);
        assert!(out.stdout.contains("one way p50"), "{}", out.stdout);
    }
}

#[test]
fn agp_profile_across_a_tls_bridge_sets_the_bridged_hops_against_the_links_zenoh_floor() {
    let ag = learned_ag("triangle");
    let dir = tempfile::tempdir().expect("a temporary folder");
    let keys = dir.path().join("keys");
    keygen(dir.path(), &keys);
    let (a, b) = (instance("prof-rob"), instance("prof-pla"));
    let endpoint = format!("tls/127.0.0.1:{}", port(4));
    // Live sessions: both run until `agp down`; B's planner serves A's goals.
    let robot = LaunchDir::new(
        &robot_launch(&a, Some(&ag), &endpoint, &tls(&keys)).replace("\nends_run = true\n", "\n"),
    );
    let planner = LaunchDir::new(
        &planner_launch(&b, &endpoint, &tls(&keys))
            .replace("\"place\"", "\"serve\"")
            .replace("\nends_run = true\n", "\n"),
    );
    let up_a = AgpUp::start(&robot.launch(), &[]);
    let mut up_b = AgpUp::start(&planner.launch(), &[]);
    up_b.wait_for_lines("serving the goals", 1, PLACE_TIMEOUT);
    for goal in [["300", "150", "90"], ["0", "0", "0"]] {
        let mut args = vec!["goal", "--instance", a.as_str(), "--place"];
        args.extend(goal);
        run_agp(robot.path(), &args, TIMEOUT).assert_success("a goal");
    }
    let profile = run_agp(
        robot.path(),
        &[
            "profile",
            "--instance",
            &a,
            "--seconds",
            "1",
            "--floor-seconds",
            "0.3",
        ],
        TIMEOUT,
    );
    for (dir, name) in [(planner.path(), &b), (robot.path(), &a)] {
        run_agp(dir, &["down", "--instance", name], TIMEOUT).assert_success("agp down");
    }
    let (end_b, end_a) = (up_b.wait(TIMEOUT), up_a.wait(TIMEOUT));
    println!("{}\n{}", profile.stdout, profile.stderr);
    profile.assert_success("agp profile across the TLS bridge");
    assert!(
        profile.stdout.contains("link floor (mutual TLS)"),
        "{}",
        profile.stdout
    );
    assert!(
        profile
            .stdout
            .contains("the bridged hops against it (p50, mutual TLS): estimator->planner "),
        "{}",
        profile.stdout
    );
    assert_eq!(end_a.status.code(), Some(0), "{}", end_a.stderr);
    assert_eq!(end_b.status.code(), Some(0), "{}", end_b.stderr);
    assert_eq!(count_instance_files(&a), 0, "files of `{a}` remain");
    assert_eq!(count_instance_files(&b), 0, "files of `{b}` remain");
}
