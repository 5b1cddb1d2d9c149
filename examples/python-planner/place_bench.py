#!/usr/bin/env python3
"""The push-level Python planner on the goals of `agp bench place` (an acceptance run, not a
test): for every episode of a bench JSON (its goals, by seed), `agp up` with lockstep physics
seeded with the episode's seed, the estimator serving the AG file and `push_planner.py
--goal X,Y,THETA`; the judge's verdict from the results JSON. Prints the success rate beside
the bench's own planner's on the same goals.

    agp bench place --planners affordance --first-seed 200 --seeds 5 --json rust.json --ag AG
    JOBS=2 .venv-ci/bin/python examples/python-planner/place_bench.py rust.json AG [BIN_DIR]
"""

import json
import os
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

HERE = Path(__file__).resolve().parent


def episodes(bench):
    """(seed, goal x, y, theta, the bench's success) of every episode the JSON holds (run it
    with `--planners affordance`), each once."""
    seen, out = set(), []

    def walk(v):
        if isinstance(v, dict):
            if "goal_x_mm" in v and "seed" in v and "success" in v:
                key = (v["seed"], v["goal_x_mm"], v["goal_y_mm"], v["goal_theta_deg"])
                if key not in seen:
                    seen.add(key)
                    out.append((*key, bool(v["success"])))
                return
            for w in v.values():
                walk(w)
        elif isinstance(v, list):
            for w in v:
                walk(w)

    walk(bench)
    return out


def run_episode(tmp, bins, wrapper, scenario, k, seed, x, y, t):
    """One `agp up` of the Python planner at goal (x, y, t), physics seeded `seed`: placed?"""
    name = f"pb-{os.getpid()}-{k}"
    d = tmp / name
    (d / "results").mkdir(parents=True)
    (d / "results" / "triangle.ag").symlink_to(tmp / "triangle.ag")
    (d / "launch.toml").write_text(
        f'instance = "{name}"\nscenario = "{scenario}"\nresults = "results"\n'
        '[clock]\nmode = "lockstep"\n'
        f'[[process]]\nname = "physics"\nexec = "agp-physics"\nargs = ["--seed", "{seed}"]\n'
        '[[process]]\nname = "estimator"\nexec = "agp-estimator"\nargs = ["--reuse"]\n'
        f'[[process]]\nname = "planner"\nexec = "{wrapper}"\n'
        f'args = ["{HERE / "push_planner.py"}", "--goal", "{x},{y},{t}"]\nends_run = true\n'
    )
    subprocess.run([str(bins / "agp"), "up", "launch.toml"], cwd=d, capture_output=True, timeout=1200)
    verdict = d / "results" / f"{name}-place.json"
    return verdict.is_file() and json.loads(verdict.read_text()).get("success") is True


def main():
    bench = json.loads(Path(sys.argv[1]).read_text())
    ag = Path(sys.argv[2]).resolve()
    bins = Path(sys.argv[3] if len(sys.argv) > 3 else HERE.parents[1] / "target" / "release").resolve()
    jobs = int(os.environ.get("JOBS", "2"))
    rows = episodes(bench)
    if not rows:
        raise SystemExit(f"no episodes in {sys.argv[1]}")
    scenario = bench.get("scenario", "triangle") if isinstance(bench, dict) else "triangle"
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / "triangle.ag").symlink_to(ag)
        wrapper = tmp / "python"
        wrapper.write_text(f'#!/bin/sh\nexec "{sys.executable}" "$@"\n')
        wrapper.chmod(0o755)
        with ThreadPoolExecutor(jobs) as pool:
            futures = [pool.submit(run_episode, tmp, bins, wrapper, scenario, k, *row[:4]) for k, row in enumerate(rows)]
            ours = []
            for row, f in zip(rows, futures):
                ok = f.result()
                ours.append(ok)
                seed, x, y, t, theirs_ok = row
                print(f"seed {seed} goal ({x:.0f}, {y:.0f}) mm {t:.0f} deg: python {'placed' if ok else 'NOT placed'}, rust {'placed' if theirs_ok else 'NOT placed'}", flush=True)
    n, a, b = len(rows), sum(ours), sum(r[4] for r in rows)
    print(f"place_bench: {n} goals: Python push-level planner {100 * a / n:.0f} % ({a}), Rust affordance planner {100 * b / n:.0f} % ({b})")


if __name__ == "__main__":
    main()
