#!/usr/bin/env python3
"""What README.md, ARCHITECTURE.md and RELIABILITY.md cite exists in the tree (issue 36 item 5).

    python3 tools/doc_refs.py [--root DIR] [--verbose]

Each doc is read for the names a reader would look up, and each name is looked up:

- a path (a backticked token or a markdown link with a `/` or a file suffix, e.g.
  `tools/harness/src/seeds.rs`, [python/](python/)): the file or folder exists, tracked by git;
  a bare file name (`up.rs`) exists somewhere in the tree;
- a test name (a backticked snake_case name of five words or more): `fn NAME` exists, in the
  file cited just before it on a row of RELIABILITY's promises table (which names each
  test's file), else anywhere;
- a Rust path (`Type::item`, `crate::item`): each part after the crate is an identifier the
  Rust sources define or use;
- a command-line flag (`--name`) and an environment variable (`AGP_NAME`): the sources name it
  (a clap field `name`, an argparse or launch-file key `--name`, the variable's string).

Generated outputs (`results/...`, `target/...`), system paths (`/dev/shm`, `/proc`),
addresses, globs and the specs kept beside the repository (`../shared/spec/`) are not paths of
the tree and are skipped. Exit 0 when every name resolves, else 1 with each miss as
`DOC:LINE: kind `name`: why`. `tools/readme_commands.py` runs this first, so CI runs it.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
from pathlib import Path

DOCS = ["README.md", "ARCHITECTURE.md", "RELIABILITY.md"]
SUFFIXES = (".rs", ".py", ".toml", ".md", ".sh", ".cjs", ".svg", ".png", ".json", ".txt", ".allow", ".mcap", ".ag")
# Not paths of the tree: what runs write, the system's, the specs beside the repository,
# and the examples of names a reader makes up.
NOT_TREE = re.compile(
    r"^(/|results/|target/|\.\./shared/|https?:|ws://|tls/|tcp/|agp/|~|\$|/tmp/)"
    r"|[*<>{}]|\.\.\.|…"
)
MADE_UP = {
    "bad.toml", "realtime-learn.toml", "old.mcap", "new.mcap", "run.mcap", "run.rrd", "default.mcap",
    "faults.json", "bridge-faults.json", "live-faults.json", "bench-signals.json", "soak.json",
    "part-1.json", "all.json", "place.json", "my-launch.toml", "triangle.ag", "learn.json",
    "OLD.mcap", "NEW.mcap", "FILE.mcap", "ca.pem",
    # the specs kept beside the repository (ARCHITECTURE.md says where)
    "benchmarks.md", "pipeline.md",
}
# Cargo's own flags, which the docs' build commands use.
CARGO_FLAGS = {"timings", "release", "workspace", "bins", "all-targets", "no-fail-fast", "list", "test", "bin", "example"}
TEST_NAME = re.compile(r"^[a-z0-9]+(_[a-z0-9]+){4,}$")
RUST_PATH = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(::[A-Za-z_][A-Za-z0-9_]*)+$")
FLAG = re.compile(r"(?<![\w-])--([a-z][a-z0-9-]+)")
ENV = re.compile(r"\bAGP_[A-Z0-9_]+\b")


def tracked(root: Path) -> list[str]:
    out = subprocess.run(["git", "ls-files"], cwd=root, capture_output=True, text=True, check=True).stdout
    return [p for p in out.splitlines() if p]


class Tree:
    def __init__(self, root: Path):
        self.root = root
        self.files = tracked(root)
        self.paths = set(self.files)
        self.dirs = {str(Path(p).parents[i]) for p in self.files for i in range(len(Path(p).parents) - 1)}
        self.basenames = {Path(p).name for p in self.files}
        self.text: dict[str, str] = {}
        for p in self.files:
            if p.endswith((".rs", ".py", ".toml", ".sh", ".cjs")) or p in ("tools/long_functions.allow",):
                try:
                    self.text[p] = (root / p).read_text(errors="replace")
                except OSError:
                    pass
        self.rust = "\n".join(t for p, t in self.text.items() if p.endswith(".rs"))
        self.sources = "\n".join(self.text.values())
        self.words = set(re.findall(r"[A-Za-z_][A-Za-z0-9_]*", self.rust))
        self.fns = set(re.findall(r"\bfn ([A-Za-z_][A-Za-z0-9_]*)", self.rust))
        self.fns_in = {p: set(re.findall(r"\bfn ([A-Za-z_][A-Za-z0-9_]*)", t)) for p, t in self.text.items() if p.endswith(".rs")}

    def exists(self, path: str) -> bool:
        p = path.rstrip("/")
        return p in self.paths or p in self.dirs

    def exists_within(self, path: str) -> bool:
        """A path relative to a folder the text is about (`data/epuck.toml` of libs/world/)."""
        p = path.rstrip("/")
        return self.exists(p) or any(q.endswith("/" + p) for q in self.paths | self.dirs)


def cited(doc: str, text: str):
    """(line, kind, token) for each backticked token and markdown link of the doc."""
    for n, line in enumerate(text.split("\n"), 1):
        for m in re.finditer(r"\]\(([^)\s]+)\)", line):
            yield n, "link", m.group(1)
        for m in re.finditer(r"`([^`]+)`", line):
            yield n, "code", m.group(1)


def check_doc(tree: Tree, doc: str) -> list[str]:
    text = (tree.root / doc).read_text()
    lines = text.split("\n")
    misses = []
    current_file = None  # the last .rs file cited, for the test names that follow it
    for n, kind, tok in cited(doc, text):
        where = f"{doc}:{n}"
        # Links: a file or folder of the tree (or an address).
        if kind == "link":
            if not re.match(r"^(https?:|#)", tok) and not tree.exists(tok.split("#")[0]):
                misses.append(f"{where}: link `{tok}`: no such file or folder in the tree")
            continue
        # Flags and environment variables anywhere in a code span (commands included).
        for f in FLAG.findall(tok):
            if not flag_known(tree, f):
                misses.append(f"{where}: flag `--{f}`: no source names it")
        for e in ENV.findall(tok):
            if e not in tree.sources:
                misses.append(f"{where}: environment variable `{e}`: no source names it")
        if " " in tok.strip():
            continue
        t = tok.strip().rstrip(",.;:")
        # Paths: with a folder or a known suffix.
        if ("/" in t or t.endswith(SUFFIXES)) and re.fullmatch(r"[\w./-]+", t):
            if NOT_TREE.search(t) or t in MADE_UP:
                continue
            if "/" in t.rstrip("/"):
                if not tree.exists_within(t):
                    misses.append(f"{where}: path `{t}`: no such file or folder in the tree")
                elif t.endswith(".rs"):
                    current_file = t
            elif not re.fullmatch(r"[\w-]+(\.[a-z]+)?/?", t):
                continue  # `env.unwrapped.ag`, `.mcap`: an attribute or a suffix, not a file
            elif t.rstrip("/") not in tree.basenames and not tree.exists_within(t):
                misses.append(f"{where}: file `{t}`: no file of that name in the tree")
            elif t.endswith(".rs"):
                current_file = None
            continue
        # Test names: `fn NAME` in the file cited before, else anywhere.
        if TEST_NAME.fullmatch(t):
            fns = tree.fns_in.get(current_file, set()) if current_file else tree.fns
            if t not in fns:
                if t in tree.fns:
                    # RELIABILITY's promises table names the file each test is in; prose may not.
                    if doc == "RELIABILITY.md" and lines[n - 1].lstrip().startswith("|"):
                        misses.append(f"{where}: test `{t}`: not in `{current_file}`, but elsewhere")
                elif t not in tree.words:  # a field or constant is named so too
                    misses.append(f"{where}: test `{t}`: no `fn {t}` in the tree")
            continue
        # Rust paths: every part after the first is a name the sources know.
        if RUST_PATH.fullmatch(t):
            for part in t.split("::")[1:]:
                if part not in tree.words:
                    misses.append(f"{where}: Rust path `{t}`: `{part}` is named nowhere in the Rust sources")
                    break
    return misses


def flag_known(tree: Tree, flag: str) -> bool:
    if flag in CARGO_FLAGS:
        return True
    field = flag.replace("-", "_")
    return (
        field in tree.words
        or f"--{flag}" in tree.sources
        or f'"{flag}"' in tree.sources
    )


def check(root: Path) -> list[str]:
    tree = Tree(root)
    misses = []
    for doc in DOCS:
        misses += check_doc(tree, doc)
    return misses


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--root", default=str(Path(__file__).resolve().parent.parent))
    a = ap.parse_args()
    misses = check(Path(a.root))
    print("\n".join(misses))
    print(f"{len(misses)} cited names not found in the tree" if misses else "every cited path, test, Rust name, flag and variable exists")
    return 1 if misses else 0


if __name__ == "__main__":
    sys.exit(main())
