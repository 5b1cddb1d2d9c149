//! The rules of the crate layout (ARCHITECTURE.md, "Crates and what each may depend on"),
//! read from the manifests themselves: the process crates are binaries over the libraries
//! that depend on no other process crate, libraries depend on no process or tool crate,
//! ground truth's readers (the harness) are never a dependency of a process but the
//! supervisor's, and the launch file's library links no iceoryx2.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ sits in the workspace")
        .to_path_buf()
}

/// Every member's package name, folder (relative) and the agp crates it depends on, in
/// every dependency table (normal, dev, build).
fn members() -> BTreeMap<String, (String, Vec<String>)> {
    let root = workspace_root();
    let text = std::fs::read_to_string(root.join("Cargo.toml")).expect("the workspace manifest");
    let ws: toml::Table = text.parse().expect("the workspace manifest is TOML");
    let list = ws["workspace"]["members"].as_array().expect("members");
    let mut out = BTreeMap::new();
    for m in list {
        let dir = m.as_str().expect("a member path").to_owned();
        let text = std::fs::read_to_string(root.join(&dir).join("Cargo.toml"))
            .unwrap_or_else(|e| panic!("{dir}/Cargo.toml: {e}"));
        let man: toml::Table = text.parse().expect("a member manifest is TOML");
        let name = man["package"]["name"].as_str().expect("name").to_owned();
        let mut deps = Vec::new();
        for table in ["dependencies", "dev-dependencies", "build-dependencies"] {
            if let Some(t) = man.get(table).and_then(|t| t.as_table()) {
                for (dep, spec) in t {
                    if dep.starts_with("agp-") && dep != &name {
                        deps.push(dep.clone());
                    }
                    let path = spec.get("path").and_then(|p| p.as_str()).unwrap_or("");
                    assert!(
                        path.is_empty() || path == ".",
                        "{dir}: `{dep}` by path `{path}`: internal crates come from [workspace.dependencies]"
                    );
                }
            }
        }
        out.insert(name, (dir, deps));
    }
    out
}

#[test]
fn no_process_crate_depends_on_another_process_crate_or_on_the_harness_but_the_supervisor() {
    let members = members();
    let processes: Vec<&String> = members
        .iter()
        .filter(|(_, (dir, _))| dir.starts_with("processes/"))
        .map(|(name, _)| name)
        .collect();
    assert_eq!(
        processes.len(),
        5,
        "five process crates (the bridge's too): {processes:?}"
    );
    for (name, (dir, deps)) in &members {
        if !dir.starts_with("processes/") {
            continue;
        }
        for d in deps {
            assert!(
                !processes.contains(&d),
                "process crate `{name}` depends on process crate `{d}`"
            );
            if d == "agp-harness" {
                assert_eq!(
                    name, "agp-supervisor",
                    "`{name}` depends on the harness (ground truth's reader)"
                );
            }
        }
    }
}

/// The README's first command, `cargo build --release`, builds the workspace's default
/// members: `agp` and the three processes of a run. None of them links Zenoh (the bridge is
/// the `agp-bridge` binary's, built by `--workspace --bins`): a third of a cold build.
#[test]
fn the_first_commands_build_links_no_zenoh_and_no_tls() {
    let out = std::process::Command::new(env!("CARGO"))
        .args(["tree", "--offline", "-e", "normal", "--prefix", "none"])
        .current_dir(workspace_root())
        .output()
        .expect("cargo tree runs");
    assert!(
        out.status.success(),
        "cargo tree: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let tree = String::from_utf8_lossy(&out.stdout);
    assert!(
        tree.lines().any(|l| l.starts_with("agp-supervisor ")),
        "the default members include `agp`:\n{tree}"
    );
    for heavy in ["zenoh ", "rustls ", "rcgen ", "agp-bridge-process "] {
        assert!(
            !tree.lines().any(|l| l.starts_with(heavy)),
            "`cargo build --release` would build `{}`",
            heavy.trim()
        );
    }
}

#[test]
fn libraries_depend_on_libraries_only() {
    let members = members();
    let libs: Vec<&String> = members
        .iter()
        .filter(|(_, (dir, _))| dir.starts_with("libs/") || dir == "shared-types")
        .map(|(name, _)| name)
        .collect();
    for (name, (dir, deps)) in &members {
        if !(dir.starts_with("libs/") || dir == "shared-types") {
            continue;
        }
        for d in deps {
            assert!(
                libs.contains(&d),
                "library `{name}` ({dir}) depends on `{d}`, which is not a library"
            );
        }
    }
}

#[test]
fn the_planners_logic_does_not_depend_on_perception_nor_perception_on_the_planner() {
    let members = members();
    let deps = |n: &str| {
        members
            .get(n)
            .unwrap_or_else(|| panic!("no crate `{n}`"))
            .1
            .clone()
    };
    // The planning library reads the estimator's estimates (shared-types payloads), never
    // its code; tests may use it (a dev-dependency) to drive the routines.
    let text = std::fs::read_to_string(workspace_root().join("libs/planning/Cargo.toml"))
        .expect("libs/planning/Cargo.toml");
    let man: toml::Table = text.parse().expect("TOML");
    assert!(
        man["dependencies"].get("agp-perception").is_none(),
        "agp-planning depends on agp-perception: {:?}",
        deps("agp-planning")
    );
    assert!(
        !deps("agp-perception").contains(&"agp-planning".to_owned()),
        "agp-perception depends on agp-planning"
    );
}

/// The Rust sources under `dir` (relative to the workspace), with their text.
fn sources(dir: &str) -> Vec<(PathBuf, String)> {
    let mut out = Vec::new();
    let mut stack = vec![workspace_root().join(dir)];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display())) {
            let path = entry.expect("a folder entry").path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                let text = std::fs::read_to_string(&path).expect("a source file");
                out.push((path, text));
            }
        }
    }
    out
}

#[test]
fn the_estimator_and_the_planners_code_never_reads_the_objects_truth_from_the_scenario() {
    // The object's spec (polygon, size, pose, mass, friction) is ground truth: the
    // estimator and the planner get a `ScenarioBrief` (and the learning protocol's
    // experimenter an `Experimenter`), never the `ObjectSpec`. One file is the exception,
    // by design: the `model` planner's pushing model of the true object
    // (`PushModel::from_scenario`), a ground-truth reader that says so in its doc (checked
    // here) and in every report, as the `oracle` does.
    let forbidden = [".object.", "object.shape", "ObjectShape", "ObjectSpec"];
    let model_door = std::path::Path::new("libs/planning/src/push_model.rs");
    let door = std::fs::read_to_string(workspace_root().join(model_door)).expect("push_model.rs");
    assert!(
        door.contains("reads\n//! ground truth by design"),
        "push_model.rs no longer says it reads ground truth"
    );
    let mut found = Vec::new();
    for dir in [
        "processes/estimator/src",
        "processes/planner/src",
        "libs/perception/src",
        "libs/planning/src",
    ] {
        for (path, text) in sources(dir) {
            if path.ends_with(model_door) {
                continue;
            }
            for (n, line) in text.lines().enumerate() {
                if line.trim_start().starts_with("//") {
                    continue;
                }
                if let Some(f) = forbidden.iter().find(|f| line.contains(**f)) {
                    found.push(format!(
                        "{}:{}: `{f}`: {}",
                        path.display(),
                        n + 1,
                        line.trim()
                    ));
                }
            }
        }
    }
    assert!(
        found.is_empty(),
        "the object's truth read in:\n{}",
        found.join("\n")
    );
}

/// The agp crates `name` links, directly or through others: its `[dependencies]` and
/// theirs (dev- and build-dependencies link into tests and build scripts only).
fn linked(name: &str) -> std::collections::BTreeSet<String> {
    let root = workspace_root();
    let members = members();
    let normal = |crate_name: &str| -> Vec<String> {
        let (dir, _) = members
            .get(crate_name)
            .unwrap_or_else(|| panic!("no crate `{crate_name}`"));
        let text = std::fs::read_to_string(root.join(dir).join("Cargo.toml"))
            .unwrap_or_else(|e| panic!("{dir}/Cargo.toml: {e}"));
        let man: toml::Table = text.parse().expect("a member manifest is TOML");
        man.get("dependencies")
            .and_then(|t| t.as_table())
            .map(|t| {
                t.keys()
                    .filter(|d| d.starts_with("agp-"))
                    .cloned()
                    .collect()
            })
            .unwrap_or_default()
    };
    let mut seen = std::collections::BTreeSet::new();
    let mut todo = normal(name);
    while let Some(d) = todo.pop() {
        if seen.insert(d.clone()) {
            todo.extend(normal(&d));
        }
    }
    seen
}

#[test]
fn the_planner_process_decides_and_links_no_perception_and_no_ground_truth_reader() {
    // ARCHITECTURE.md: the planner reads the estimator's estimates, never runs the
    // estimator's perception (the scripted drive that did is the harness's
    // `agp-scripted-drive`), and never reads ground truth but through the oracle's port.
    let members = members();
    let planner = members
        .iter()
        .find(|(_, (dir, _))| dir == "processes/planner")
        .map(|(name, _)| name.clone())
        .expect("the planner process crate");
    let links = linked(&planner);
    for forbidden in ["agp-perception", "agp-harness", "agp-physics"] {
        assert!(
            !links.contains(forbidden),
            "`{planner}` links `{forbidden}` (all it links: {links:?})"
        );
    }
    let mut found = Vec::new();
    for (path, text) in sources("processes/planner/src") {
        for (n, line) in text.lines().enumerate() {
            if line.contains("agp_perception") || line.contains("ObjectTracker") {
                found.push(format!("{}:{}: {}", path.display(), n + 1, line.trim()));
            }
        }
    }
    assert!(
        found.is_empty(),
        "the planner process's code names perception:\n{}",
        found.join("\n")
    );
}

#[test]
fn the_launch_library_links_no_iceoryx2_no_runtime_and_no_process_starter() {
    // ARCHITECTURE.md: a launch file is read and validated by a pure library; what opens
    // shared memory (iceoryx2, agp-runtime), carries the link (agp-bridge) or runs a
    // process (the supervisor) stays out of it. shared-types's `ZeroCopySend` derive
    // (iceoryx2-bb-*) is no runtime and is allowed.
    let members = members();
    let mut links = linked("agp-launch");
    for forbidden in ["agp-runtime", "agp-bridge", "agp-view", "agp-supervisor"] {
        assert!(
            !links.contains(forbidden),
            "`agp-launch` links `{forbidden}` (all it links: {links:?})"
        );
    }
    links.insert("agp-launch".to_owned());
    for name in &links {
        let (dir, _) = members
            .get(name)
            .unwrap_or_else(|| panic!("no crate `{name}`"));
        let text = std::fs::read_to_string(workspace_root().join(dir).join("Cargo.toml"))
            .unwrap_or_else(|e| panic!("{dir}/Cargo.toml: {e}"));
        let man: toml::Table = text.parse().expect("a member manifest is TOML");
        let deps = man.get("dependencies").and_then(|t| t.as_table());
        assert!(
            deps.is_none_or(|t| !t.contains_key("iceoryx2")),
            "`agp-launch` links iceoryx2 through `{name}` ({dir}/Cargo.toml)"
        );
    }
}
