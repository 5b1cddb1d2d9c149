//! What one instance may touch and who may touch it: cleaning one instance leaves every
//! other's files alone, the lock and the folders are not taken through links or from other
//! users, every file and segment of a running pipeline is owner-only, `agp down` cleans
//! after a supervisor killed with -9, and `agp up --detach` on a held instance says so.
//! Every test has an instance of its own and checks it leaves no file.

use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

use agp_runtime::Instance;
use agp_tests::{AgpUp, Finished, LaunchDir, bin_path, count_instance_files, run_agp};

/// Safety net of every wait; the checks never depend on it.
const TIMEOUT: Duration = Duration::from_secs(30);

/// A launch file of instance `instance`: two `agp-test-child` processes that run until
/// stopped, or, with `ends_at_once`, one that ends the run as soon as it starts.
fn launch(instance: &str, ends_at_once: bool) -> String {
    let body = if ends_at_once {
        "[[process]]\nname = \"job\"\nexec = \"agp-test-child\"\n\
         args = [\"--exit-after-ms\", \"0\", \"--status\", \"0\"]\nends_run = true\n"
    } else {
        "[[process]]\nname = \"alpha\"\nexec = \"agp-test-child\"\nargs = [\"--until-signal\"]\n\n\
         [[process]]\nname = \"beta\"\nexec = \"agp-test-child\"\nargs = [\"--until-signal\"]\n"
    };
    format!(
        "instance = \"{instance}\"\nscenario = \"triangle\"\n\n[clock]\nmode = \"lockstep\"\n\n{body}"
    )
}

/// `agp <args...>` in `dir` with `AGP_IOX2_ROOT` set to `base`, run to its end.
fn run_agp_in_base(dir: &Path, base: &Path, args: &[&str]) -> Finished {
    let child = Command::new(bin_path("agp"))
        .args(args)
        .current_dir(dir)
        .env(agp_runtime::ROOT_ENV, base)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start agp");
    let pid = child.id();
    // `agp up` of these launch files ends by itself, or is refused at once.
    let out = child.wait_with_output().expect("wait for agp");
    Finished {
        pid,
        status: out.status,
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

/// The lock file of instance `name` under base folder `base`.
fn lock_path(base: &Path, name: &str) -> PathBuf {
    base.join(format!("{name}.lock"))
}

/// The uid of this process.
fn euid() -> u32 {
    // SAFETY: geteuid(2) has no preconditions and cannot fail.
    unsafe { libc::geteuid() }
}

#[test]
fn cleaning_instance_pc_leaves_the_files_of_instance_pc_x_alone() {
    let (pc, pc_x) = ("t-iso-pc", "t-iso-pc_x");
    let dir_x = LaunchDir::new(&launch(pc_x, false));
    let mut up_x = AgpUp::start(&dir_x.launch(), &[]);
    up_x.wait_for_lines("started", 2, TIMEOUT);
    let files_x = Instance::new(pc_x).expect("valid name").files();
    assert!(files_x.len() > 1, "`{pc_x}` runs with files: {files_x:?}");

    // A run of `pc` cleans `pc`'s leftovers first, then ends at once and removes its files.
    let dir = LaunchDir::new(&launch(pc, true));
    let run = run_agp(
        dir.path(),
        &["up", dir.launch().to_str().expect("UTF-8")],
        TIMEOUT,
    );
    assert!(run.status.success(), "{}\n{}", run.stdout, run.stderr);
    assert_eq!(count_instance_files(pc), 0, "files of `{pc}` remain");

    let still = Instance::new(pc_x).expect("valid name").files();
    let gone: Vec<_> = files_x.iter().filter(|f| !still.contains(f)).collect();
    assert!(
        gone.is_empty(),
        "`{pc}` removed files of `{pc_x}`: {gone:?}"
    );
    let status = run_agp(dir_x.path(), &["status", "--instance", pc_x], TIMEOUT);
    assert!(status.status.success(), "{}", status.stderr);
    let down = run_agp(dir_x.path(), &["down", "--instance", pc_x], TIMEOUT);
    assert!(down.status.success(), "{}", down.stderr);
    let end = up_x.wait(TIMEOUT);
    assert_eq!(end.status.code(), Some(0), "{}\n{}", end.stdout, end.stderr);
    assert_eq!(count_instance_files(pc_x), 0, "files of `{pc_x}` remain");
}

#[test]
fn a_symlink_planted_at_the_lock_path_is_refused_and_its_target_left_untouched() {
    let name = "t-iso-lock-link";
    let base = tempfile::tempdir().expect("a base folder");
    std::fs::set_permissions(base.path(), std::fs::Permissions::from_mode(0o700))
        .expect("chmod the base");
    let target = base.path().join("precious");
    std::fs::write(&target, "precious\n").expect("write the target");
    std::os::unix::fs::symlink(&target, lock_path(base.path(), name)).expect("plant the link");

    let dir = LaunchDir::new(&launch(name, true));
    let run = run_agp_in_base(dir.path(), base.path(), &["up", "launch.toml"]);
    assert!(
        !run.status.success(),
        "a run took a linked lock:\n{}",
        run.stdout
    );
    let lock = lock_path(base.path(), name);
    assert!(
        run.stderr.contains(&lock.display().to_string())
            && run.stderr.contains("symbolic link")
            && run.stderr.lines().count() == 1,
        "{}",
        run.stderr
    );
    assert_eq!(
        std::fs::read_to_string(&target).expect("the target"),
        "precious\n"
    );
    assert_eq!(
        std::fs::metadata(&target).expect("the target").mode() & 0o777,
        0o644,
        "the target's mode changed"
    );
    assert_eq!(count_instance_files(name), 0, "files of `{name}` remain");
}

#[test]
fn a_base_folder_of_another_user_is_refused_and_one_of_ours_is_tightened_to_0700() {
    let name = "t-iso-base";
    let parent = tempfile::tempdir().expect("a temporary folder");
    let dir = LaunchDir::new(&launch(name, true));

    // Ours but open to everyone, as `/tmp/agp` was once created: tightened, and the run works.
    let base = parent.path().join("ours");
    std::fs::create_dir(&base).expect("create the base");
    std::fs::set_permissions(&base, std::fs::Permissions::from_mode(0o777)).expect("chmod");
    let run = run_agp_in_base(dir.path(), &base, &["up", "launch.toml"]);
    assert!(run.status.success(), "{}\n{}", run.stdout, run.stderr);
    let mode = std::fs::metadata(&base).expect("the base").mode() & 0o777;
    assert_eq!(mode, 0o700, "the base is {mode:o}");
    assert_eq!(count_instance_files(name), 0, "files of `{name}` remain");

    // A link where the base should be is refused, not followed.
    let link = parent.path().join("link");
    std::os::unix::fs::symlink(&base, &link).expect("plant the link");
    let run = run_agp_in_base(dir.path(), &link, &["up", "launch.toml"]);
    assert!(!run.status.success(), "a linked base was used");
    assert!(
        run.stderr.contains(&link.display().to_string()) && run.stderr.contains("not a folder"),
        "{}",
        run.stderr
    );

    // Another user's: refused by name (only root can give a folder away to check this).
    if euid() != 0 {
        return;
    }
    let theirs = parent.path().join("theirs");
    std::fs::create_dir(&theirs).expect("create the base");
    std::os::unix::fs::chown(&theirs, Some(65534), Some(65534)).expect("chown");
    let run = run_agp_in_base(dir.path(), &theirs, &["up", "launch.toml"]);
    assert!(!run.status.success(), "another user's base was used");
    assert!(
        run.stderr.contains(&theirs.display().to_string())
            && run.stderr.contains("belongs to uid 65534")
            && run.stderr.lines().count() == 1,
        "{}",
        run.stderr
    );
    assert!(
        std::fs::read_dir(&theirs).expect("list").next().is_none(),
        "something was written into another user's folder"
    );
    assert_eq!(count_instance_files(name), 0, "files of `{name}` remain");
}

/// Every entry under `path` (itself included), not following links.
fn walk(path: &Path, out: &mut Vec<PathBuf>) {
    out.push(path.to_path_buf());
    let is_dir = std::fs::symlink_metadata(path).is_ok_and(|m| m.is_dir());
    if is_dir && let Ok(entries) = std::fs::read_dir(path) {
        for e in entries.filter_map(Result::ok) {
            walk(&e.path(), out);
        }
    }
}

#[test]
fn no_file_or_segment_of_a_running_pipeline_is_writable_by_group_or_others() {
    let name = "t-iso-perm";
    // Physics and the scripted planner, pushing for longer than the test runs.
    let dir = LaunchDir::new(&format!(
        "instance = \"{name}\"\nscenario = \"square\"\n\n[clock]\nmode = \"lockstep\"\n\n\
         [[process]]\nname = \"physics\"\nexec = \"agp-physics\"\n\n\
         [[process]]\nname = \"planner\"\nexec = \"agp-scripted-drive\"\n\
         args = [\"--pushes\", \"100000\", \"--push-ms\", \"200\"]\n\
         ends_run = true\n"
    ));
    let mut up = AgpUp::start(&dir.launch(), &[]);
    up.wait_for_lines("scripted drive:", 1, TIMEOUT);

    let instance = Instance::new(name).expect("valid name");
    let base = instance.root_dir().parent().expect("a base").to_path_buf();
    let mut entries = Vec::new();
    for f in instance.files() {
        walk(&f, &mut entries);
    }
    entries.push(base.clone());
    entries.push(lock_path(&base, name));
    assert!(
        entries
            .iter()
            .any(|e| e.to_string_lossy().ends_with(".global_mgmt")),
        "no global management segment among {entries:?}"
    );
    let open: Vec<String> = entries
        .iter()
        .filter_map(|e| {
            let m = std::fs::symlink_metadata(e).ok()?;
            (m.mode() & 0o022 != 0 || m.uid() != euid())
                .then(|| format!("{:o} uid {} {}", m.mode() & 0o7777, m.uid(), e.display()))
        })
        .collect();
    assert!(open.is_empty(), "writable by others or not ours: {open:#?}");
    for folder in [&base, &instance.root_dir().to_path_buf()] {
        let mode = std::fs::metadata(folder).expect("a folder").mode() & 0o777;
        assert_eq!(mode, 0o700, "{} is {mode:o}", folder.display());
    }

    up.signal(libc::SIGTERM);
    let end = up.wait(TIMEOUT);
    assert!(
        end.stdout.contains("stopped by"),
        "{}\n{}",
        end.stdout,
        end.stderr
    );
    assert_eq!(count_instance_files(name), 0, "files of `{name}` remain");
}

#[test]
fn down_after_a_supervisor_killed_with_9_removes_its_files_and_says_so() {
    let name = "t-iso-down-dead";
    let dir = LaunchDir::new(&launch(name, false));
    let mut up = AgpUp::start(&dir.launch(), &[]);
    up.wait_for_lines("started", 2, TIMEOUT);
    up.signal(libc::SIGKILL);
    let killed = up.wait(TIMEOUT);
    assert!(
        killed.status.code().is_none(),
        "the supervisor was not killed"
    );
    assert!(
        count_instance_files(name) > 0,
        "a killed supervisor left no file"
    );

    let down = run_agp(dir.path(), &["down", "--instance", name], TIMEOUT);
    assert!(down.status.success(), "{}\n{}", down.stdout, down.stderr);
    assert!(
        down.stdout.contains("had no supervisor") && down.stdout.contains("removed"),
        "{}",
        down.stdout
    );
    assert_eq!(count_instance_files(name), 0, "files of `{name}` remain");
    let base = Instance::new(name).expect("valid name");
    let lock = lock_path(base.root_dir().parent().expect("a base"), name);
    assert!(!lock.exists(), "the lock file remains");
}

#[test]
fn down_of_an_instance_without_supervisor_names_its_live_processes_and_leaves_their_files() {
    let name = "t-iso-down-live";
    let instance = Instance::new(name).expect("valid name");
    instance.remove_files().expect("clean start");
    // A process of the instance that no supervisor started: this test, with a node.
    let node = instance
        .node("t-iso-stranger", false)
        .expect("a node of the instance");
    let before = instance.files();

    let dir = tempfile::tempdir().expect("a temporary folder");
    let down = run_agp(dir.path(), &["down", "--instance", name], TIMEOUT);
    assert!(!down.status.success(), "agp down cleaned under a live node");
    assert!(
        down.stderr.contains("t-iso-stranger")
            && down.stderr.contains(&format!("pid {}", std::process::id())),
        "{}",
        down.stderr
    );
    assert_eq!(
        instance.files(),
        before,
        "agp down removed files of live nodes"
    );

    drop(node);
    instance.remove_files().expect("clean up");
    assert_eq!(count_instance_files(name), 0, "files of `{name}` remain");
}

#[test]
fn detach_on_an_instance_another_supervisor_holds_says_it_is_already_up_and_fails() {
    let name = "t-iso-detach-held";
    let dir = LaunchDir::new(&launch(name, false));
    let mut up = AgpUp::start(&dir.launch(), &[]);
    up.wait_for_lines("started", 2, TIMEOUT);

    let again = run_agp(dir.path(), &["up", "--detach"], TIMEOUT);
    assert!(
        !again.status.success(),
        "a second `up --detach` said it started:\n{}",
        again.stdout
    );
    assert!(
        again.stderr.contains("already up") && again.stderr.contains(&format!("pid {}", up.pid())),
        "{}",
        again.stderr
    );
    assert!(
        !again.stdout.contains("runs in the background"),
        "{}",
        again.stdout
    );

    // The holder runs on, untouched.
    let status = run_agp(dir.path(), &["status", "--instance", name], TIMEOUT);
    assert!(status.status.success(), "{}", status.stderr);
    up.signal(libc::SIGTERM);
    let end = up.wait(TIMEOUT);
    assert!(end.stdout.contains("stopped by"), "{}", end.stdout);
    assert_eq!(count_instance_files(name), 0, "files of `{name}` remain");
}
