#!/usr/bin/env python3
"""Every command of the README's ```sh blocks (and of examples/*/README.md), run from a fresh
clone after the first `agp up`: each exits as the README says.

    python3 tools/readme_commands.py --bin target/debug [--ag results/triangle.ag]
                                     [--python .venv-ci/bin/python] [--tree DIR] [--list]

The READMEs are the input: their ```sh and ```bash blocks are cut into commands (one a line,
`a && b` two, a comment after `#` dropped), and each command must match exactly one rule of
RULES below (a full match of the command as written), which says how it is checked:

- `run`: run as written, in the clone, expecting exit 0 (or the rule's code);
- `small`: run with smaller arguments that still exercise it (the rule says which and why:
  CI runs this on a debug build, within a budget of seconds, where the README's benchmarks
  take minutes in release);
- `args`: the command as written with `--help` appended: clap reads every argument before
  the `--help` and refuses an unknown flag or a bad value with exit 2, so exit 0 means the
  command's arguments are what the CLI takes; the rule names what runs it whole (a test, or
  nothing, and why);
- `skip`: not run at all, and why (a build, a file the reader writes, a second computer).

A README command with no rule, or a rule that matches no command, fails the check, so a
command that changes in the README is checked again (or given a rule). Rewritten when run:
`target/release/` becomes the `--bin` folder (CI builds debug), `.venv-ci/bin/python` and
`$PWD/.venv-ci` the `--python` one's, and the live session's instance `live` becomes
`rc-live-<pid>` (tests run side by side, each under its own instance).

The clone: `git clone` of this repository into a temporary folder (or `--tree`, an existing
one), then the first `agp up`'s effect: `results/triangle.ag` copied from `--ag` (without
it, the first `agp up` is run: minutes on a debug build). After every command, `git status
--porcelain` in the clone must be empty: what the README makes goes to ignored folders.

Before any command runs, `tools/doc_refs.py` checks that every path, test, Rust name, flag and
environment variable README.md, ARCHITECTURE.md and RELIABILITY.md cite exists in the tree, and
`tools/doc_behaviour.py` that each flag the docs give a binary is in its `--help` and each
refusal they quote is said so by the `--bin` build (a miss fails the check, as a command
without a rule does).

Exit 0 when every command exited as expected and the clone is clean; else 1, naming each
failure. The last lines list what was not run and why.
"""

from __future__ import annotations

import argparse
import os
import re
import shlex
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tools"))
import doc_behaviour  # noqa: E402  (tools/doc_behaviour.py: the docs' flags and quoted refusals hold)
import doc_refs  # noqa: E402  (tools/doc_refs.py: the docs' cited names exist)
# The README and every example's README (a new example's commands need rules too).
READMES = ["README.md"] + sorted(str(p.relative_to(ROOT)) for p in ROOT.glob("examples/*/README.md"))
TIMEOUT_S = 300  # a safety net per command; no check depends on it


@dataclass
class Rule:
    pattern: str  # a regular expression the command must match whole
    how: str  # run | small | args | skip
    why: str = ""
    instead: str = ""  # for `small`: the command run in its place ({cmd}: the one written)
    codes: tuple[int, ...] = (0,)  # the exit status the README promises, at each occurrence


# Commands as the README writes them; `R` is `target/release/` escaped.
R = re.escape("target/release/")
LIVE = "the live session started just above"

RULES = [
    # The first lines of the README: builds and the test command itself.
    Rule(r"cargo build --release --workspace --bins", "skip", "the build; CI builds the workspace itself"),
    Rule(r"cargo build --release", "skip", "the first command's build (the default members: agp and the run's three processes); CI builds the workspace itself"),
    Rule(rf"{R}agp up", "skip", "the first `agp up` (the learning phase and a placement): its result, results/triangle.ag, is put in the clone instead; tests/tests/learn_pipeline.rs and supervisor_up.rs run it"),
    Rule(r"tools/setup\.sh", "skip", "the set-up the test command runs before this check"),
    Rule(r"cargo build --workspace --bins", "skip", "the build CI runs before this check"),
    Rule(r"cargo test --workspace", "skip", "the tests, of which this is one"),
    # Try it.
    Rule(rf"{R}agp probe push --scenario triangle --angle-deg 180 --alpha-deg 15", "run"),
    Rule(rf"{R}agp probe push --scenario triangle --angle-deg 180 --alpha-deg 15 --json results/push\.json", "run"),
    Rule(rf"{R}agp bench learn --scenario triangle --json results/learn\.json", "small",
         "one seed, 9 trials and 20 unseen pushes in place of 5 seeds x 60 trials per alpha x 200 (minutes on a debug build)",
         "{cmd} --seed 100 --trials 9 --eval 20"),
    Rule(rf"{R}agp bench place --scenario lshape --episodes 20 --json results/place\.json --plot results/place\.svg", "args",
         "20 episodes x 5 seeds x 3 planners over the pipeline plus learning the L: minutes; the shards below run `bench place` over the pipeline, tests/tests/bench_cli.rs runs it whole"),
    Rule(rf"{R}agp bench trajectory --scenario lshape --json results/trajectory\.json --plot results/trajectory\.svg", "args",
         "five paths x 5 seeds x 2 planners of 15-60 pushes each: minutes; tests/tests/bench_cli.rs runs one path"),
    Rule(rf"{R}agp bench paper --json results/paper\.json", "args",
         "15 minutes in release (891 s for 5 seeds, 2026-11-28); its --check is held by bench_paper.rs's each_target_made_unreachable_is_named_as_missed"),
    Rule(rf"{R}agp bench place --seeds 20 --shard 1/4 --json results/part-1\.json", "small",
         "2 seeds in 2 shards, one baseline episode each, on the AG of the first `agp up`, in place of 20 seeds of every planner: both shards run, then the merge below",
         "{bin}/agp bench place --seeds 2 --shard 1/2 --episodes 1 --planners baseline --ag results/triangle.ag --json results/part-1.json && "
         "{bin}/agp bench place --seeds 2 --shard 2/2 --episodes 1 --planners baseline --ag results/triangle.ag --json results/part-2.json"),
    Rule(rf"{R}agp bench merge results/part-\*\.json --json results/place\.json", "run"),
    Rule(rf"{R}agp bench adapt --scenario triangle --mass-kg 0\.3 --json results/adapt\.json", "args",
         "23 placements x 2 gradients x 5 seeds, each seed learning its AG: minutes; tests/tests/online_learning.rs runs the online learning"),
    Rule(rf"{R}agp bridge keygen results/bridge-keys", "run",
         "the second time (the bridge's section, for a reader who starts there) it finds the keys of the first and refuses to overwrite them",
         codes=(0, 1)),
    Rule(rf"{R}agp up examples/bridge/(robot|planner)\.toml", "args",
         "the two sides run together, on a fixed port and instance names: tests/tests/newcomer.rs (the_bridge_example_places_the_triangle_as_the_readme_gives_it) runs this example as written"),
    Rule(r"cp libs/world/scenarios/pentagon\.toml results/my-object\.toml", "run"),
    Rule(rf"{R}agp probe push --scenario results/my-object\.toml --angle-deg 90 --alpha-deg 0", "run"),
    Rule(rf"{R}agp bench place --scenario results/my-object\.toml --episodes 5", "args",
         "it learns the pentagon first (the paper's protocol, tens of seconds on a debug build): tests/tests/bench_cli.rs (a_scenario_file_of_the_users_own_is_learned_and_placed_with_no_code_change) does so with a scenario file of its own"),
    Rule(rf"{R}agp up results/my-launch\.toml", "skip", "a launch file the reader writes"),
    Rule(rf"{R}agp up launch-live\.toml --detach", "run"),
    Rule(rf"{R}agp goal --instance live --place 300 150 90", "run"),
    Rule(rf"{R}agp status --instance live", "run"),
    Rule(rf"{R}agp swap planner --instance live --exec {R}agp-planner", "run"),
    Rule(rf"{R}agp swap planner --instance live --watch {R}agp-planner", "args",
         "it watches until Ctrl-C; tests/tests/hot_swap.rs runs a watch through two builds"),
    Rule(rf"{R}agp profile --instance live --seconds 5 --json results/profile\.json --plot results/profile\.svg", "small",
         "1 s of sampling in place of 5",
         "{bin}/agp profile --instance {live} --seconds 1 --json results/profile.json --plot results/profile.svg"),
    Rule(rf"{R}agp down --instance live", "run"),
    # A live session.
    Rule(rf"{R}agp goal --instance live --place 200 -50 0", "run"),
    Rule(rf"{R}agp goal --instance live --path 200,-50 350,-50", "run"),
    Rule(rf"{R}agp swap planner --instance live", "run"),
    Rule(rf"{R}agp profile --instance live --seconds 5", "small", "1 s of sampling in place of 5",
         "{bin}/agp profile --instance {live} --seconds 1"),
    # Recording and replay.
    Rule(rf"{R}agp record --instance live --seconds 10 results/live\.mcap", "small",
         "1 s of a live session started for it (the one above is down by now), in place of 10 s",
         "{bin}/agp up launch-live.toml --instance {live} --detach && "
         "{bin}/agp record --instance {live} --seconds 1 results/live.mcap; "
         "s=$?; {bin}/agp down --instance {live}; exit $s"),
    Rule(rf"{R}agp replay results/run\.mcap --json results/replay\.json", "args",
         "needs a lockstep recording of a whole run (a launch file's `record`): tests/tests/record_replay.rs records one and replays it to the bit"),
    Rule(rf"{R}agp export old\.mcap new\.mcap", "args",
         "needs a recording made before the Foxglove channels: tests/tests/foxglove_recording.rs exports one"),
    Rule(r"\.venv-ci/bin/python tools/mcap_check\.py results/live\.mcap", "run"),
    Rule(r"\.venv-ci/bin/python tools/foxglove_decode\.py results/run\.mcap", "small",
         "on the live session's recording made above in place of a launch file's", "{python} tools/foxglove_decode.py results/live.mcap"),
    Rule(r"\.venv-ci/bin/python tools/rerun_check\.py entities results/run\.mcap", "skip",
         "tests/tests/foxglove_recording.rs runs it on a recorded placement; even its --help imports Rerun (6 s)"),
    # Live view.
    Rule(rf"{R}agp view --instance live( --port 0)?", "args",
         "it serves until Ctrl-C: tests/tests/foxglove_view.rs serves a live session to the stock client"),
    Rule(rf"{R}agp view results/run\.mcap --speed 2", "args",
         "it serves until Ctrl-C: tests/tests/foxglove_view.rs serves a recording"),
    # The Python planner's example.
    Rule(r'PATH="\$PWD/\.venv-ci/bin:\$PATH" ' + rf"{R}agp up examples/python-planner/launch\.toml", "args",
         "a placement by the Python planner: tests/tests/python_planner.rs runs it"),
]


@dataclass
class Command:
    readme: str
    line: int
    text: str


def commands(root: Path) -> list[Command]:
    """Every command of the READMEs' ```sh and ```bash blocks, in order."""
    found = []
    for name in READMES:
        text = (root / name).read_text()
        for block in re.finditer(r"^```(?:sh|bash)\n(.*?)^```", text, re.S | re.M):
            first = text[: block.start()].count("\n") + 2
            for k, raw in enumerate(block.group(1).split("\n")):
                code = strip_comment(raw).strip()
                for part in (p.strip() for p in code.split(" && ")):
                    if part:
                        found.append(Command(name, first + k, part))
    return found


def strip_comment(line: str) -> str:
    """The line without a `#` comment (one outside quotes, after a space or at the start)."""
    quote = None
    for i, c in enumerate(line):
        if quote:
            quote = None if c == quote else quote
        elif c in "'\"":
            quote = c
        elif c == "#" and (i == 0 or line[i - 1] == " "):
            return line[:i]
    return line


def rule_of(cmd: Command) -> list[int]:
    return [i for i, r in enumerate(RULES) if re.fullmatch(r.pattern, cmd.text)]


def rewrite(text: str, subst: dict[str, str]) -> str:
    text = text.replace("target/release/", subst["bin"] + "/")
    text = text.replace("$PWD/.venv-ci/bin", str(Path(subst["python"]).parent))
    text = text.replace(".venv-ci/bin/python", subst["python"])
    text = re.sub(r"--instance live\b", "--instance " + subst["live"], text)
    text = re.sub(r"(agp up launch-live\.toml)(?! --instance)", r"\1 --instance " + subst["live"], text)
    return text


def run(shell: str, tree: Path) -> tuple[int, str, float]:
    start = time.monotonic()
    try:
        p = subprocess.run(
            ["bash", "-c", shell],
            cwd=tree,
            stdin=subprocess.DEVNULL,
            capture_output=True,
            text=True,
            timeout=TIMEOUT_S,
        )
        code, out = p.returncode, p.stdout + p.stderr
    except subprocess.TimeoutExpired as e:
        code, out = -1, f"timed out after {TIMEOUT_S} s (a safety net)\n{e.stdout or ''}{e.stderr or ''}"
    return code, out, time.monotonic() - start


def clone(into: Path) -> Path:
    tree = into / "clone"
    subprocess.run(["git", "clone", "--quiet", str(ROOT), str(tree)], check=True)
    return tree


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bin", required=False, default=str(ROOT / "target/release"), help="the folder of the built agp binaries")
    ap.add_argument("--ag", help="the AG file the first `agp up` learns (results/triangle.ag); without it the first `agp up` runs")
    ap.add_argument("--python", default=str(ROOT / ".venv-ci/bin/python"), help="the Python of tools/setup.sh's .venv-ci")
    ap.add_argument("--tree", help="run in this clone instead of a fresh one")
    ap.add_argument("--list", action="store_true", help="print each command and its rule, run nothing")
    a = ap.parse_args()

    found = commands(ROOT)
    # What the three docs cite (paths, tests, Rust names, flags, variables) exists in the tree.
    problems = doc_refs.check(ROOT)
    for cmd in found:
        n = len(rule_of(cmd))
        if n != 1:
            problems.append(f"{cmd.readme}:{cmd.line}: `{cmd.text}` matches {n} rules (want 1): give it one in tools/readme_commands.py")
    for i, r in enumerate(RULES):
        if not any(i in rule_of(c) for c in found):
            problems.append(f"rule `{r.pattern}` matches no README command: the README changed; update the rule")
    if problems:
        print("\n".join(problems))
        return 1
    if a.list:
        for cmd in found:
            r = RULES[rule_of(cmd)[0]]
            print(f"{r.how:5} {cmd.readme}:{cmd.line}: {cmd.text}" + (f"  ({r.why})" if r.why else ""))
        return 0

    bin_dir = str(Path(a.bin).resolve())
    held, misses = doc_behaviour.check(Path(bin_dir))
    print(f"docs' flags and quoted refusals: {held} held, {len(misses)} missed", flush=True)
    if misses:
        print("\n".join(misses))
        return 1
    subst = {"bin": bin_dir, "python": os.path.abspath(a.python), "live": f"rc-live-{os.getpid()}"}
    with tempfile.TemporaryDirectory() as tmp:
        tree = Path(a.tree).resolve() if a.tree else clone(Path(tmp))
        (tree / "results").mkdir(exist_ok=True)
        if a.ag:
            (tree / "results/triangle.ag").write_bytes(Path(a.ag).read_bytes())
        else:
            code, out, _ = run(f"{bin_dir}/agp up", tree)
            if code != 0:
                print(f"the first `agp up` exited {code}:\n{out}")
                return 1
        failed, not_run, seen = [], [], {}
        total = time.monotonic()
        try:
            for cmd in found:
                r = RULES[rule_of(cmd)[0]]
                where = f"{cmd.readme}:{cmd.line}"
                if r.how == "skip":
                    not_run.append(f"skip  {where}: {cmd.text}: {r.why}")
                    continue
                written = rewrite(cmd.text, subst)
                if r.how == "args":
                    shell = written + " --help"
                    not_run.append(f"args  {where}: {cmd.text}: {r.why}")
                elif r.how == "small":
                    shell = r.instead.format(cmd=written, **subst)
                else:
                    shell = written
                code, out, took = run(shell, tree)
                seen[id(r)] = seen.get(id(r), -1) + 1
                want = r.codes[min(seen[id(r)], len(r.codes) - 1)]
                ok = code == want
                print(f"{'ok' if ok else 'FAIL':4} {r.how:5} {where}: {cmd.text}  -> exit {code} ({took:.1f} s)", flush=True)
                if r.how == "small":
                    print(f"           ran: {shell}", flush=True)
                if not ok:
                    failed.append(f"{where}: `{cmd.text}` exited {code}, the README says {want}; ran `{shell}`:\n{out}")
        finally:
            run(f"{bin_dir}/agp down --instance {subst['live']}", tree)
        status = subprocess.run(["git", "status", "--porcelain", "--untracked-files=all"], cwd=tree, capture_output=True, text=True).stdout
        if status.strip():
            failed.append(f"`git status` in the clone is not clean after the README's commands:\n{status}")
        print(f"{len(found)} commands, {time.monotonic() - total:.1f} s; not run whole:")
        print("\n".join("  " + n for n in not_run))
        if failed:
            print("\n".join(failed))
            return 1
        print("every command exited as the README says; git status clean")
        return 0


if __name__ == "__main__":
    signal.signal(signal.SIGPIPE, signal.SIG_DFL)
    sys.exit(main())
