#!/usr/bin/env python3
"""agp as a Gymnasium environment: the random and the affordance policy, 10 episodes each
on `agp/Place-v0` (the triangle, push level), and their success rates by the judge.

    .venv-ci/bin/python examples/gym/quickstart.py                     # from the repository
    .venv-ci/bin/python examples/gym/quickstart.py --short             # near goals (CI's run)

Needs the binaries (target/release, else target/debug; AGP_BIN_DIR to say) and an AG file
(results/triangle.ag, which `target/release/agp up` learns; AGP_AG to say).
"""

import argparse

import gymnasium as gym

import agp  # registers agp/Place-v0 and agp/Trajectory-v0
from agp.policies import AffordancePolicy, RandomPolicy

parser = argparse.ArgumentParser()
parser.add_argument("--episodes", type=int, default=10)
parser.add_argument("--seed", type=int, default=0)
parser.add_argument("--short", action="store_true", help="goals 60-100 mm away, at most 4 pushes (CI's run)")
args = parser.parse_args()
options = dict(goal_distance_mm=(60.0, 100.0), max_pushes=4) if args.short else {}

env = gym.make("agp/Place-v0", scenario="triangle", seed=args.seed, **options)
for name, policy in (("random", RandomPolicy(env, seed=args.seed)), ("affordance", AffordancePolicy(env))):
    placed = 0
    for episode in range(args.episodes):
        obs, info = env.reset(seed=args.seed + episode)
        done = False
        while not done:
            obs, reward, terminated, truncated, info = env.step(policy(obs, info))
            done = terminated or truncated
        placed += info["verdict"]["success"]
    print(f"{name}: placed {placed} of {args.episodes} ({100 * placed / args.episodes:.0f} %)", flush=True)
env.close()
