//! Functions a reader can hold: no non-test function of the workspace is longer than 150
//! lines, as `tools/long_functions.py` counts them (from the `fn` line to the closing brace),
//! but those on `tools/long_functions.allow`, each with the reason it is still long. A listed
//! function that is no longer over the limit fails too, so the list only shrinks.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;

const LIMIT: usize = 150;

fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ sits in the workspace")
        .to_path_buf()
}

/// A function the script lists.
#[derive(Debug)]
struct Long {
    path: String,
    name: String,
    line: usize,
    lines: usize,
}

impl Long {
    fn key(&self) -> String {
        format!("{}::{}", self.path, self.name)
    }
}

/// The functions over `max` lines under `root`, as the script lists them.
fn long_functions(root: &Path, max: usize) -> Vec<Long> {
    let script = workspace_root().join("tools/long_functions.py");
    let out = Command::new("python3")
        .arg(&script)
        .args(["--max", &max.to_string(), "--tsv"])
        .arg(root)
        .output()
        .unwrap_or_else(|e| {
            panic!("cannot run python3 ({e}): install Python 3 (`apt-get install python3`)")
        });
    assert!(
        out.status.success(),
        "{} failed ({}): {}",
        script.display(),
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout)
        .expect("the script prints UTF-8")
        .lines()
        .map(|l| {
            let f: Vec<&str> = l.split('\t').collect();
            assert_eq!(f.len(), 4, "a line of the script's --tsv output: {l:?}");
            Long {
                path: f[0].to_owned(),
                name: f[1].to_owned(),
                line: f[2].parse().expect("a line number"),
                lines: f[3].parse().expect("a line count"),
            }
        })
        .collect()
}

/// The allow-list's entries (`path::function`); every entry must say why (`# ...`).
fn allowed() -> BTreeSet<String> {
    let path = workspace_root().join("tools/long_functions.allow");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut out = BTreeSet::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let (entry, why) = line.split_once('#').unwrap_or((line, ""));
        assert!(
            !why.trim().is_empty(),
            "{}:{}: `{}` says not why it is allowed (`path::function  # why`)",
            path.display(),
            n + 1,
            entry.trim()
        );
        assert!(
            out.insert(entry.trim().to_owned()),
            "{}:{}: `{}` is listed twice",
            path.display(),
            n + 1,
            entry.trim()
        );
    }
    out
}

#[test]
fn no_function_is_longer_than_150_lines_but_those_the_allow_list_names_and_each_of_those_is() {
    let long = long_functions(&workspace_root(), LIMIT);
    let allowed = allowed();
    let over: Vec<String> = long
        .iter()
        .filter(|f| !allowed.contains(&f.key()))
        .map(|f| format!("  {}:{}  {}  {} lines", f.path, f.line, f.name, f.lines))
        .collect();
    let keys: BTreeSet<String> = long.iter().map(Long::key).collect();
    let stale: Vec<String> = allowed
        .iter()
        .filter(|a| !keys.contains(*a))
        .map(|a| format!("  {a}"))
        .collect();
    let mut message = String::new();
    if !over.is_empty() {
        message += &format!(
            "functions longer than {LIMIT} lines (split each into parts named for what they do):\n{}\n",
            over.join("\n")
        );
    }
    if !stale.is_empty() {
        message += &format!(
            "on tools/long_functions.allow but no longer over {LIMIT} lines (or gone): remove them:\n{}\n",
            stale.join("\n")
        );
    }
    assert!(message.is_empty(), "{message}");
}

/// The script on a made-up crate: it counts from `fn` to the closing brace, sees no braces
/// in strings, chars and comments, and leaves test code out.
#[test]
fn the_script_counts_a_functions_lines_and_leaves_out_test_code_and_text() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let body = |n: usize| "    let _x = 1;\n".repeat(n);
    // Each function below spans its body's lines plus two (the `fn` line and the brace).
    let src = format!(
        "/// a doc line, not counted\n#[inline]\nfn long_one() {{\n{}}}\n\n\
         fn short_one() {{\n{}}}\n\n\
         fn tricky() {{\n    let _s = \"}}}}\";\n    let _r = r#\"{{ \"# ;\n    let _c = '}}';\n    let _l: &'static str = \"\";\n    // }}\n    /* {{ /* }} */ */\n{}}}\n\n\
         #[cfg(test)]\nmod tests {{\n    fn long_in_tests() {{\n{}    }}\n}}\n\n\
         #[test]\nfn long_test() {{\n{}}}\n\n\
         trait T {{\n    fn declared(&self);\n}}\n",
        body(149),
        body(148),
        body(143),
        body(200),
        body(200),
    );
    std::fs::create_dir_all(dir.path().join("src")).expect("src/");
    std::fs::create_dir_all(dir.path().join("tests")).expect("tests/");
    std::fs::write(dir.path().join("src/lib.rs"), src).expect("src/lib.rs");
    std::fs::write(
        dir.path().join("tests/it.rs"),
        format!("fn in_tests_folder() {{\n{}}}\n", body(200)),
    )
    .expect("tests/it.rs");
    let got: Vec<(String, usize, usize)> = long_functions(dir.path(), 150)
        .into_iter()
        .map(|f| (f.key(), f.line, f.lines))
        .collect();
    // long_one: 149 + 2 = 151 lines from line 3; tricky: 6 lines of text + 143 + 2 = 151.
    let tricky_line = 3 + 151 + 1 + 150 + 1;
    assert_eq!(
        got,
        vec![
            ("src/lib.rs::long_one".to_owned(), 3, 151),
            ("src/lib.rs::tricky".to_owned(), tricky_line, 151),
        ]
    );
    let at_limit = long_functions(dir.path(), 151);
    assert!(at_limit.is_empty(), "none is over 151 lines: {at_limit:?}");
}
