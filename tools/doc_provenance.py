#!/usr/bin/env python3
"""Where a figure of the docs comes from, and whether the code it measures changed since.

    python3 tools/doc_provenance.py [--claims FILE] [--markdown]

For each claim (a doc, a phrase of it that holds the figure, the paths of the code it measures),
`git log -S PHRASE -- DOC` gives the commit that wrote the phrase (the oldest, its date), and
`git log COMMIT..HEAD -- PATHS` the commits since that touched the measured code: none means
the figure stands by reasoning (the code it measured is the code now); some means it was
measured on an older build, and the list says what changed. The claims are a tab-separated
file (doc, phrase, space-separated paths, a short name), by default the table of this script
(CLAIMS below), which docs/AUDIT.md was made from.

A phrase no commit wrote (it changed wording since) prints `?`: search a shorter phrase.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

# (doc, phrase, measured paths, name). The measured paths are the code a figure depends on.
PROCESSES = "processes/physics processes/estimator processes/planner libs/physics libs/perception libs/planning libs/affordance libs/world libs/runtime"
CLAIMS = [
    ("README.md", "82 MB", "Cargo.toml", "release agp binary size"),
    ("README.md", "8 min 15 s", "Cargo.toml Cargo.lock", "cold release build"),
    ("README.md", "5.5 GB", "Cargo.toml Cargo.lock", "target/ size after build and tests"),
    ("README.md", "1.96 mm and 0.68 deg", PROCESSES, "default run: first run's placement"),
    ("README.md", "91,959 published", PROCESSES, "default run: estimate block"),
    ("README.md", "0.97 s wall", PROCESSES, "default run: second run's wall time"),
    ("README.md", "10.6 pushes against 9.7", PROCESSES + " tools/harness", "status: model planner"),
    ("README.md", "5.2 mm, 1.0 deg; 12 pushes", PROCESSES + " python examples/python-planner", "status: Python planner placement"),
    ("README.md", "236,396", PROCESSES + " python", "status: Python live session account"),
    ("README.md", "28.7-35.9 k", PROCESSES + " python", "status: Python wheel-level throughput"),
    ("README.md", "recovers in 0.8 pushes", PROCESSES + " tools/harness/src/bench_adapt.rs", "status: adapt"),
    ("README.md", "500 injected faults survived", PROCESSES + " processes/supervisor tools/harness/src/bin/bench-faults.rs", "status: fault campaign"),
    ("README.md", "15.9 k steps/s", PROCESSES, "status/latency: block throughput"),
    ("README.md", "6.3 mm and 3.9 deg off", PROCESSES, "live session: one goal, quiet"),
    ("README.md", "1,062,215", PROCESSES + " processes/supervisor", "live session: swaps session"),
    ("README.md", "76,681 lockstep steps", PROCESSES + " libs/recording", "recording: default run recorded"),
    ("README.md", "6.87 / 6.86 us", PROCESSES + " libs/recording", "recording: cost on the ring (2026-11-25)"),
    ("README.md", "19.17 /", PROCESSES + " libs/recording libs/view", "recording: cost with Foxglove channels"),
    ("README.md", "0.41 ms, max 0.90", "processes/supervisor libs/runtime processes/physics", "hot swap handover"),
    ("README.md", "restarted 33 ms after", "processes/supervisor libs/runtime", "crash restart"),
    ("README.md", "2.9 mm and 1.0 deg off", PROCESSES, "realtime default placement"),
    ("README.md", "random: placed 0 of 10", "python " + PROCESSES, "gym quickstart"),
    ("README.md", "249,399", "libs/physics vendor/rapier2d tools/harness/src/bin/bench-physics.rs", "bench-physics table"),
    ("README.md", "0.46 | 0.50 | 0.54", "tools/harness/src/bin/bench-hop.rs Cargo.lock", "bench-hop table"),
    ("README.md", "128 k | 1.16 / 11.3", PROCESSES, "profile tables (futex events)"),
    ("README.md", "1,455,000 steps", PROCESSES, "allocation table, learning phase"),
    ("README.md", "physics 33 allocations in 5 steps", PROCESSES, "allocations, placement task"),
    ("README.md", "14.8 us | 5388 us", "libs/affordance libs/planning tools/harness/src/bin/bench-math.rs", "bench-math table"),
    ("README.md", "3.34 deg (2.61-3.87)", "libs/affordance libs/perception libs/physics libs/world tools/harness/src/learn_bench.rs tools/harness/src/bench_learn.rs", "learning table, seeds 1-10"),
    ("README.md", "3.32 deg (2.84-3.88)", "libs/affordance libs/perception libs/physics libs/world tools/harness/src/learn_bench.rs", "learning table, seeds 100-104"),
    ("README.md", "3.18 / 4.11 / 3.62", "libs/affordance libs/perception libs/planning libs/physics tools/harness/src/learn_bench.rs", "active learning 200-204"),
    ("README.md", "1.6 (0-4)", PROCESSES + " tools/harness/src/bench_adapt.rs", "adapt table"),
    ("README.md", "51.0 s against 44.1 s", "tools/sweep tools/harness/src/seeds.rs", "Ray sweep timing"),
    ("README.md", "p50 0.46 ms, max 8.4 ms", "processes/supervisor libs/runtime " + PROCESSES, "hot swap during a placement"),
    ("README.md", "(3.4 mm, 5.3 deg)", PROCESSES + " processes/supervisor", "crash restart placement"),
    ("README.md", "1.9 mm short of it after 2 s", "libs/physics libs/world/data/epuck.toml", "finite-force push"),
    ("README.md", "197 mm of their 198", "libs/physics libs/world/data/epuck.toml", "finite-force stall"),
    ("README.md", "out to 50 mm", "libs/world/data/epuck.toml libs/world/src/robot.rs", "IR usable range"),
    ("README.md", "38.8 / 73.5 / 55.7", "libs/affordance libs/perception libs/physics", "largest rotations, seed 7"),
    ("README.md", "in 2 min 17 s", "python " + PROCESSES, "gym quickstart run"),
    ("README.md", "2.8 mm 4.6 deg", PROCESSES + " python", "Python live session goals"),
    ("README.md", "(4.3 s, debug build", "libs/perception processes/estimator tools/harness", "online_from_prior test"),
    ("README.md", "Measured 2026-11-26 with the pushes past the centroid", PROCESSES + " tools/harness/src/bench_adapt.rs", "adapt section"),
    ("ARCHITECTURE.md", "17 per alpha", "libs/affordance", "grids per alpha"),
    ("RELIABILITY.md", "500 faults in 81 runs", PROCESSES + " processes/supervisor tools/harness/src/bin/bench-faults.rs", "fault campaign"),
    ("RELIABILITY.md", "40 faults across the link in 5 runs", PROCESSES + " libs/bridge processes/supervisor tools/harness/src/bin/bench-faults.rs", "lockstep bridge phase"),
    ("RELIABILITY.md", "200 faults across the link in 26 live sessions", PROCESSES + " libs/bridge processes/supervisor tools/harness/src/bin/bench-faults.rs", "live bridge phase"),
    ("RELIABILITY.md", "50 stop signals", "tools/harness/src/stop.rs tools/harness/src/bench_tasks.rs tools/harness/src/bin/bench-faults.rs processes/supervisor", "benchmark phase"),
    ("RELIABILITY.md", "8.70            8.70", PROCESSES + " processes/supervisor tools/harness/src/bin/bench-soak.rs", "soak"),
]


def git(*args: str) -> str:
    return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, check=True).stdout


def origin(doc: str, phrase: str) -> tuple[str, str] | None:
    log = git("log", "--format=%h %cs", "-S", phrase, "--", doc).split("\n")
    log = [line for line in log if line]
    if not log:
        return None
    h, d = log[-1].split()
    return h, d


def since(commit: str, paths: str) -> list[str]:
    return [line for line in git("log", "--format=%h %cs %s", f"{commit}..HEAD", "--", *paths.split()).split("\n") if line]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--claims", help="a tab-separated file of claims: doc, phrase, paths, name")
    ap.add_argument("--markdown", action="store_true", help="one markdown table row per claim")
    a = ap.parse_args()
    claims = CLAIMS
    if a.claims:
        claims = [tuple(line.split("\t")) for line in Path(a.claims).read_text().splitlines() if line.strip()]
    for doc, phrase, paths, name in claims:
        o = origin(doc, phrase)
        if o is None:
            print(f"? {doc}: `{phrase}` ({name}): no commit wrote this phrase")
            continue
        changed = since(o[0], paths)
        if a.markdown:
            first = "; ".join(c.split(" ", 2)[0] for c in changed[:6]) + (" ..." if len(changed) > 6 else "")
            print(f"| {name} | {doc} `{phrase}` | {o[0]} {o[1]} | {len(changed)} ({first}) |")
        else:
            print(f"{doc}: `{phrase}` ({name}): written {o[0]} {o[1]}; {len(changed)} commits since on {paths}")
            for c in changed[:8]:
                print(f"    {c[:110]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
