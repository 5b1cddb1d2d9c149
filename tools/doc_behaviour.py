#!/usr/bin/env python3
"""What README.md, ARCHITECTURE.md and RELIABILITY.md say a command does, run against a build.

    python3 tools/doc_behaviour.py --bin target/debug [--verbose]

Two kinds of checks, each a few milliseconds to a second, none that learns or places:

- flags: each `--flag` the docs give a binary or verb is in that binary's `--help` (the help
  is the CLI's own word on what it takes);
- refusals: the error lines the docs quote, run as the docs show them on files made for the
  purpose in a temporary folder (a scenario whose polygon crosses itself, a realtime launch
  file that may learn, a bad `AGP_WAIT`, a launch file with a `remote` that names neither
  `tls` nor `insecure`, a live session detached with no AG file to serve), checked for the
  exit status and the quoted text.

Exit 0 when every check holds, else 1 naming each. `tools/readme_commands.py` runs it with its
`--bin` folder, so CI runs it.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

# (binary and verb, flags the docs give it)
FLAGS = [
    ("agp up", "--detach --instance"),
    ("agp down", "--instance --stale"),
    ("agp status", "--instance --json"),
    ("agp goal", "--instance --place --path --keep-heading"),
    ("agp swap planner", "--instance --exec --watch --timeout-s"),
    ("agp profile", "--instance --seconds --floor-seconds --json --plot"),
    ("agp record", "--instance --seconds"),
    ("agp replay", "--json"),
    ("agp view", "--instance --port --host --rate-hz --loop --alpha-deg --speed"),
    ("agp bridge", "--wait --far-timeout-s --insecure"),
    ("agp bridge keygen", "--host"),
    ("agp bridge floor", "--tls --insecure"),
    ("agp probe push", "--scenario --angle-deg --alpha-deg --json"),
    ("agp bench learn", "--scenario --json --seeds --first-seed --seed --shard --protocol --trials --curve --eval"),
    ("agp bench place", "--scenario --episodes --json --plot --seeds --first-seed --seed --shard --planners --ag"),
    ("agp bench trajectory", "--scenario --json --plot --seeds --first-seed --in-process --ag --keep-heading"),
    ("agp bench paper", "--json --seeds --first-seed --check"),
    ("agp bench adapt", "--scenario --mass-kg --json --seeds"),
    ("agp bench online", "--scenario --seeds --first-seed --episodes --json --in-process"),
    ("agp bench merge", "--json --allow-partial"),
    ("agp-physics", "--hold-steps --step-log"),
    ("agp-estimator", "--learn-online --from-prior --load --reuse --perceive-only"),
    ("agp-planner", "--mode --planner --skills --check --keep-heading --learn-if-missing --from-prior"),
    ("bench-faults", "--faults --seed --json --trials-per-alpha --phases --faults-per-run --recovery-timeout-s "
     "--bridge-only --bridge-faults --bridge-live-faults --bench-signals-only --bench-signals"),
    ("bench-soak", "--minutes --interval-s --json"),
    ("bench-hop", "--strategy"),
]

# A scenario whose polygon crosses itself on line 4 (README, Scenario files).
BAD_SCENARIO = """name = "bad"
[object]
shape = "polygon"
vertices_mm = [[0, 0], [40, 40], [40, 0], [0, 40]]
mass_kg = 0.1
floor_friction = 0.4
contact_friction = 0.3
start = { x_mm = 0, y_mm = 0, theta_deg = 0 }
"""

# A realtime launch file whose planner may learn, named on line 12 (README, launch.toml).
REALTIME_LEARN = """# A launch file on the realtime clock whose planner may run the learning phase.
instance = "INSTANCE"
scenario = "triangle"
results = "results"
[clock]
mode = "realtime"
rate_hz = 640
[[process]]
name = "physics"
exec = "agp-physics"
[[process]]
name = "planner"
args = ["--mode", "place", "--learn-if-missing"]
exec = "agp-planner"
ends_run = true
"""

# A launch file whose remote names neither tls nor insecure (RELIABILITY promise 14).
REMOTE_NEITHER = """instance = "INSTANCE"
scenario = "triangle"
results = "results"
[clock]
mode = "lockstep"
[[process]]
name = "physics"
exec = "agp-physics"
[[process]]
name = "planner"
remote = { role = "planner", listen = "tcp/127.0.0.1:7999" }
"""


def run(argv: list[str], cwd: Path, env: dict[str, str] | None = None) -> tuple[int, str]:
    e = dict(os.environ)
    e.update(env or {})
    p = subprocess.run(argv, cwd=cwd, env=e, capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
    return p.returncode, p.stdout + p.stderr


def check(bin_dir: Path, verbose: bool = False) -> tuple[int, list[str]]:
    """(checks that held, each miss) of the binaries in `bin_dir`."""
    misses: list[str] = []
    ok = 0

    for cmd, flags in FLAGS:
        exe, *verb = cmd.split()
        code, out = run([str(bin_dir / exe), *verb, "--help"], ROOT)
        if code != 0:
            misses.append(f"`{cmd} --help` exited {code}: {out.strip()[:200]}")
            continue
        for f in flags.split():
            if f not in out.replace(f"{f}=", f"{f} "):
                misses.append(f"`{cmd} --help` has no `{f}`, which the docs give it")
            else:
                ok += 1

    instance = f"docb-{os.getpid()}"
    with tempfile.TemporaryDirectory() as tmp:
        t = Path(tmp)
        (t / "bad.toml").write_text(BAD_SCENARIO)
        (t / "realtime-learn.toml").write_text(REALTIME_LEARN.replace("INSTANCE", instance))
        (t / "remote-neither.toml").write_text(REMOTE_NEITHER.replace("INSTANCE", instance))
        (t / "launch.toml").write_text((ROOT / "launch.toml").read_text().replace('instance = "default"', f'instance = "{instance}"'))
        (t / "launch-live.toml").write_text((ROOT / "launch-live.toml").read_text().replace('instance = "live"', f'instance = "{instance}"'))
        agp = str(bin_dir / "agp")
        env_path = {"PATH": f"{bin_dir}:{os.environ.get('PATH', '')}"}
        checks = [
            # README, Scenario files: the quoted refusal, nothing started.
            ([agp, "probe", "push", "--scenario", "bad.toml", "--angle-deg", "0"], {}, None,
             ["agp: error: bad.toml:4: `vertices_mm`: edges 1 and 3 cross: the polygon crosses itself"]),
            # README, launch.toml: a realtime file whose planner may learn, refused before anything starts.
            ([agp, "up", "realtime-learn.toml"], env_path, 2,
             ["agp: error: realtime-learn.toml:12: process `planner`: `--learn-if-missing` may run the learning phase, "
              "which needs the lockstep clock: learn first (`agp up` with launch.toml, or `agp bench learn`), then run "
              "without it (the clock is `realtime`)", "agp: nothing was started"]),
            # README, Speed and latency: `agp up` refuses an AGP_WAIT that names no strategy.
            ([agp, "up", "launch.toml"], {**env_path, "AGP_WAIT": "sometimes"}, 2, ["AGP_WAIT"]),
            # README, Faults: `agp up --detach` whose planner fails in its first 2 s (no AG file
            # to serve) stops the run, prints its error line and exits 1.
            ([agp, "up", "launch-live.toml", "--detach"], {}, 1,
             ["agp-planner: error: no AG file at", "failed at start-up", "the run was stopped"]),
            # RELIABILITY 14: a remote with neither tls nor insecure is refused on its line.
            ([agp, "up", "remote-neither.toml"], env_path, 2, ["remote-neither.toml:11"]),
        ]
        for argv, env, want_code, texts in checks:
            code, out = run(argv, t, env)
            shown = " ".join(Path(x).name if x == agp else x for x in argv)
            if code == 0 or (want_code is not None and code != want_code):
                misses.append(f"`{shown}` exited {code}, the docs say {want_code or 'non-zero'}:\n{out}")
                continue
            for text in texts:
                if text not in out:
                    misses.append(f"`{shown}` did not say what the docs quote:\n  quoted: {text}\n  said:   {out.strip()}")
                else:
                    ok += 1
            if verbose:
                print(f"`{shown}` -> exit {code}: {out.strip()}")
        run([agp, "down", "--instance", instance], t)
    return ok, misses


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bin", default=str(ROOT / "target/debug"), help="the folder of the built binaries")
    ap.add_argument("--verbose", action="store_true")
    a = ap.parse_args()
    ok, misses = check(Path(a.bin).resolve(), a.verbose)
    print("\n".join(misses))
    print(f"{ok} checks held, {len(misses)} missed" if misses else f"every flag and quoted refusal of the docs holds ({ok} checks)")
    return 1 if misses else 0


if __name__ == "__main__":
    sys.exit(main())
