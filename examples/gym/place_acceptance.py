#!/usr/bin/env python3
"""`agp.policies.AffordancePolicy` (and `RandomPolicy` beside it) through `agp/Place-v0` on
the goals of `agp bench place` (an acceptance run, not a test): every episode of a bench
JSON (its goals, by seed) is one episode of the environment, reset with the episode's seed
and goal; the judge's verdict from `info["verdict"]`. Prints the success rate per seed and
policy, and the bench's own planner's on the same goals.

    target/release/agp bench place --planners affordance --first-seed 200 --seeds 5 --json place.json --ag AG
    JOBS=2 .venv-ci/bin/python examples/gym/place_acceptance.py place.json AG
"""

import json
import os
import sys
from collections import defaultdict
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1] / "examples" / "python-planner"))
from place_bench import episodes  # noqa: E402  (the bench JSON's goals, each once)


def run(job):
    k, policy_name, rows, ag = job
    import gymnasium as gym

    import agp  # noqa: F401
    from agp.policies import AffordancePolicy, RandomPolicy

    env = gym.make("agp/Place-v0", scenario="triangle", ag=ag, instance=f"pa-{os.getpid() % 100000}-{k}")
    policy = AffordancePolicy(env) if policy_name == "affordance" else RandomPolicy(env, seed=k)
    out = []
    try:
        for seed, x, y, t, _ in rows:
            obs, info = env.reset(seed=int(seed), options={"goal": (x, y, t)})
            done = False
            while not done:
                obs, _, terminated, truncated, info = env.step(policy(obs, info))
                done = terminated or truncated
            v = info["verdict"]
            out.append((seed, x, y, t, v))
            print(f"{policy_name} seed {seed} goal ({x:.0f}, {y:.0f}) mm {t:.0f} deg: {'placed' if v['success'] else 'NOT placed'} "
                  f"({v.get('final_error_mm', 0):.1f} mm, {v.get('final_error_deg', 0):.1f} deg, {v['pushes']} pushes, {v['end']})", flush=True)
    finally:
        env.close()
    return policy_name, out


def main():
    bench = json.loads(Path(sys.argv[1]).read_text())
    ag = str(Path(sys.argv[2]).resolve())
    policies = os.environ.get("POLICIES", "affordance,random").split(",")
    jobs = int(os.environ.get("JOBS", "2"))
    rows = episodes(bench)
    if not rows:
        raise SystemExit(f"no episodes in {sys.argv[1]}")
    chunks = [rows[i::jobs] for i in range(jobs)]
    work = [(k, p, chunk, ag) for p in policies for k, chunk in enumerate(chunks)]
    results = defaultdict(lambda: defaultdict(list))
    with ProcessPoolExecutor(jobs) as pool:
        for name, out in pool.map(run, work):
            for seed, *_, v in out:
                results[name][seed].append(v["success"])
    theirs = defaultdict(list)
    for seed, *_, ok in rows:
        theirs[seed].append(ok)
    for seed in sorted(theirs):
        parts = [f"{p} {100 * sum(results[p][seed]) / len(results[p][seed]):.0f} % of {len(results[p][seed])}" for p in policies]
        print(f"seed {seed}: {', '.join(parts)}; bench's affordance planner {100 * sum(theirs[seed]) / len(theirs[seed]):.0f} %")
    for p in policies:
        n = sum(len(v) for v in results[p].values())
        a = sum(sum(v) for v in results[p].values())
        print(f"place_acceptance: {p} policy through agp/Place-v0: {a} of {n} placed ({100 * a / n:.1f} %)")


if __name__ == "__main__":
    main()
