#!/usr/bin/env python3
"""agp's Gymnasium environments beside gym-pusht, in one run on this machine (a benchmark,
not a test):

- steps/s and simulated seconds per wall second of `agp/Place-v0` at the wheel level (one
  step = 1/64 s: 10 physics steps at 640 Hz, the robot's IR and odometry sampled at the
  last, the estimator's estimate of that frame, the ground truth and the observation) and
  at the push level (one step = one push, with its travel and circling), random actions;
  with, per process, the microseconds a step spent on a CPU and runnable waiting for one
  (/proc/PID/schedstat: a loaded machine shows in the second);
- the same for `gym_pusht/PushT-v0` (state observations, 10 Hz control: 0.1 s a step),
  random actions, in rounds alternating with agp's wheel level;
- episodes per minute of `agp.policies.AffordancePolicy` (resets included), and its
  success rate.

    .venv-ci/bin/python tools/bench_gym.py [--rounds 3] [--seconds 10] [--episodes 10] [--json FILE] [--wheels-wait W]

gym-pusht and its dependencies (pymunk, pygame, opencv, ...) are not CI's: on first use this
script makes the virtual environment `.venv-bench/` from `tools/requirements-bench.txt`
(pinned) and runs gym-pusht there. agp's binaries come from target/release (`cargo build
--release --workspace --bins`; AGP_BIN_DIR to say), the AG file from results/triangle.ag
(AGP_AG to say).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
BENCH_VENV = REPO / ".venv-bench"
PUSHT_DT_S = 0.1  # gym-pusht: 10 Hz control

PUSHT_CHILD = r"""
import json, sys, time
import gymnasium as gym, gym_pusht  # noqa: F401
seconds = float(sys.argv[1])
env = gym.make("gym_pusht/PushT-v0", obs_type="state")
env.action_space.seed(0)
env.reset(seed=0)
def schedstat():
    with open("/proc/self/schedstat") as f:
        return [int(v) for v in f.read().split()[:2]]
s0 = schedstat()
n, t0 = 0, time.perf_counter()
while time.perf_counter() - t0 < seconds:
    _, _, terminated, truncated, _ = env.step(env.action_space.sample())
    n += 1
    if terminated or truncated:
        env.reset()
wall = time.perf_counter() - t0
s1 = schedstat()
env.close()
print(json.dumps({"steps": n, "wall_s": wall, "run_ns": s1[0] - s0[0], "wait_ns": s1[1] - s0[1]}))
"""


def bench_python() -> Path:
    """The interpreter of `.venv-bench/`, made on first use."""
    py = BENCH_VENV / "bin" / "python"
    if not py.is_file():
        print(f"bench_gym: making {BENCH_VENV.name}/ with gym-pusht (tools/requirements-bench.txt), once", flush=True)
        subprocess.run([sys.executable, "-m", "venv", str(BENCH_VENV)], check=True)
        subprocess.run(
            [str(py), "-m", "pip", "install", "--quiet", "--disable-pip-version-check", "-r", str(REPO / "tools" / "requirements-bench.txt")],
            check=True,
        )
    return py


def pusht(py: Path, seconds: float) -> dict:
    out = subprocess.run([str(py), "-c", PUSHT_CHILD, str(seconds)], capture_output=True, text=True, check=True)
    r = json.loads(out.stdout.strip().splitlines()[-1])
    rate = r["steps"] / r["wall_s"]
    cpu = {"python": (round(r["run_ns"] / r["steps"] / 1e3, 1), round(r["wait_ns"] / r["steps"] / 1e3, 1))}
    return {"steps_per_s": rate, "sim_s_per_wall_s": rate * PUSHT_DT_S, "steps": r["steps"], "cpu_us_per_step": cpu}


def schedstat(pid: int) -> tuple[int, int]:
    """(ns on a CPU, ns runnable but waiting for one) of process `pid` so far."""
    try:
        with open(f"/proc/{pid}/schedstat") as f:
            run, wait, _ = f.read().split()
        return int(run), int(wait)
    except (OSError, ValueError):
        return 0, 0


def pipeline_pids(env) -> dict[str, int]:
    """The wheel level's processes (at the push level none: its executor ends with each
    episode, inside a step)."""
    u = env.unwrapped
    if u.control != "wheels":
        return {}
    pids = {what: c.proc.pid for what, c in u._procs.items()}
    pids["python"] = os.getpid()
    return pids


def agp_random(env, seconds: float, seed: int) -> dict:
    """Random actions for `seconds` of wall time: steps/s and simulated s per wall s (the
    frames' simulated time; resets not counted in the wall time), and per process (physics,
    the estimator, this Python) the CPU time a step took and the time it waited for a CPU
    (/proc/PID/schedstat; at the wheel level, over the whole round, resets included)."""
    u = env.unwrapped
    env.action_space.seed(seed)
    env.reset(seed=seed)
    pids = pipeline_pids(env)
    before = {k: schedstat(p) for k, p in pids.items()}
    steps, wall, sim = 0, 0.0, 0.0
    t_end = time.perf_counter() + seconds
    while time.perf_counter() < t_end:
        sim0 = u._ring.frame.sim_time_s
        t0 = time.perf_counter()
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        wall += time.perf_counter() - t0
        steps += 1
        if terminated or truncated:
            sim += u._ring.frame.sim_time_s - sim0 if u.control == "wheels" else 0.0
            for k, p in pids.items():  # a new pipeline: its processes' time so far
                run, wait = schedstat(p)
                before[k] = (before[k][0] - run, before[k][1] - wait)
            env.reset()
            pids = pipeline_pids(env)
            for k, p in pids.items():
                run, wait = schedstat(p)
                b = before.get(k, (0, 0))
                before[k] = (b[0] + run, b[1] + wait)
            continue
        u._ring._drain()
        sim += u._ring.frame.sim_time_s - sim0
    cpu = {}
    for k, p in pids.items():
        run, wait = schedstat(p)
        cpu[k] = (round((run - before[k][0]) / steps / 1e3, 1), round((wait - before[k][1]) / steps / 1e3, 1))
    return {"steps_per_s": steps / wall, "sim_s_per_wall_s": sim / wall, "steps": steps, "cpu_us_per_step": cpu}


def affordance_episodes(env, episodes: int, seed: int) -> dict:
    from agp.policies import AffordancePolicy

    policy = AffordancePolicy(env)
    placed, pushes = 0, 0
    t0 = time.perf_counter()
    for k in range(episodes):
        obs, info = env.reset(seed=seed + k)
        done = False
        while not done:
            obs, _, terminated, truncated, info = env.step(policy(obs, info))
            done = terminated or truncated
        placed += info["verdict"]["success"]
        pushes += info["verdict"]["pushes"]
    wall = time.perf_counter() - t0
    return {"episodes": episodes, "placed": placed, "pushes": pushes, "wall_s": wall, "episodes_per_min": 60.0 * episodes / wall}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--episodes", type=int, default=10)
    ap.add_argument("--json", type=Path)
    ap.add_argument("--wheels-wait", help="the wheel level's `wait` (AGP_WAIT's values; default the environment's, block)")
    args = ap.parse_args()
    import gymnasium as gym

    import agp  # noqa: F401

    py = bench_python()
    load = os.getloadavg()
    wait = {"wait": args.wheels_wait} if args.wheels_wait else {}
    wheels = gym.make("agp/Place-v0", scenario="triangle", control="wheels", instance=f"bg-w-{os.getpid() % 100000}", **wait)
    push = gym.make("agp/Place-v0", scenario="triangle", instance=f"bg-p-{os.getpid() % 100000}")
    rows: dict[str, list[dict]] = {"gym-pusht": [], "agp wheels": [], "agp push": []}
    try:
        for k in range(args.rounds):
            rows["gym-pusht"].append(pusht(py, args.seconds))
            rows["agp wheels"].append(agp_random(wheels, args.seconds, 100 + k))
            rows["agp push"].append(agp_random(push, args.seconds, 200 + k))
            for name, r in rows.items():
                x = r[-1]
                cpu = "".join(f", {p} {c[0]}+{c[1]}" for p, c in x.get("cpu_us_per_step", {}).items())
                print(
                    f"round {k + 1}: {name:11s} {x['steps_per_s']:9.1f} steps/s {x['sim_s_per_wall_s']:7.1f} sim s/wall s ({x['steps']} steps"
                    f"{'; us a step on a CPU + waiting for one: ' + cpu[2:] if cpu else ''})",
                    flush=True,
                )
        aff = affordance_episodes(push, args.episodes, 300)
    finally:
        wheels.close()
        push.close()
    summary = {
        name: {
            "steps_per_s": [round(x["steps_per_s"], 1) for x in r],
            "sim_s_per_wall_s": [round(x["sim_s_per_wall_s"], 1) for x in r],
            "median_sim_s_per_wall_s": round(statistics.median(x["sim_s_per_wall_s"] for x in r), 1),
        }
        for name, r in rows.items()
    }
    summary["affordance"] = aff
    summary["load_average_at_start"] = load
    print(
        f"bench_gym: median sim s/wall s: agp wheels {summary['agp wheels']['median_sim_s_per_wall_s']}, "
        f"gym-pusht {summary['gym-pusht']['median_sim_s_per_wall_s']}, agp push {summary['agp push']['median_sim_s_per_wall_s']}; "
        f"affordance policy {aff['episodes_per_min']:.1f} episodes/min, placed {aff['placed']} of {aff['episodes']} "
        f"(load average {load[0]:.1f} at the start)"
    )
    if args.json:
        args.json.write_text(json.dumps(summary, indent=2) + "\n")


if __name__ == "__main__":
    main()
