"""The Gymnasium environments (`agp/Place-v0`, `agp/Trajectory-v0`) over real pipelines:
Gymnasium's own checker without a warning at both action levels, the same seed giving the
same episode bit for bit, two environments side by side in an `AsyncVectorEnv`, and the
README's quickstart. Every test uses instance names of its own and leaves /dev/shm as it
found it. Needs the binaries beside `agp-py-reference` (target/debug) and `AGP_TEST_AG`."""

import os
import subprocess
import sys
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import agp  # noqa: F401  (registers the environments)

from conftest import REPO, reference_binary

NEAR = dict(goal_distance_mm=(60.0, 100.0), max_pushes=4)


@pytest.fixture
def pipeline_kwargs(ag_file):
    return dict(ag=str(ag_file), bin_dir=str(reference_binary().parent))


def shm_files(prefix: str) -> int:
    return sum(1 for f in os.listdir("/dev/shm") if f.startswith(f"agp_{prefix}"))


def name(tag: str) -> str:
    return f"te{tag}-{os.getpid() % 100000}"


# CI checks one pair for its time budget (a push-level check is about 8 resets, each a
# pipeline started and the executor's first circling: 23 s in debug under load);
# `AGP_TEST_ALL_CHECKS=1` checks both environments at both action levels.
PAIRS = [("agp/Trajectory-v0", "wheels")]
if os.environ.get("AGP_TEST_ALL_CHECKS") == "1":
    PAIRS += [("agp/Place-v0", "wheels"), ("agp/Place-v0", "push"), ("agp/Trajectory-v0", "push")]


@pytest.mark.parametrize("env_id,control", PAIRS)
def test_gymnasiums_checker_passes_without_a_warning(env_id, control, pipeline_kwargs):
    tag = f"c{env_id[4].lower()}{control[0]}"
    before = shm_files(name(tag))
    kwargs = dict(pipeline_kwargs, control=control, instance=name(tag))
    if control == "push":
        kwargs.update(NEAR)
    env = gym.make(env_id, **kwargs)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            check_env(env.unwrapped)
        assert [str(w.message) for w in caught] == []
    finally:
        env.close()
    assert shm_files(name(tag)) == before


def run_wheels(env, seed, steps):
    """Observations, rewards and ends of `steps` wheel-level steps from reset(seed), the
    wheels driving a fixed pattern."""
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for k in range(steps):
        action = np.array([0.8, 0.8 if k % 20 < 10 else 0.3], dtype=np.float32)
        obs, reward, terminated, truncated, _ = env.step(action)
        out.append((obs, reward, terminated, truncated))
    return out


def test_the_same_seed_gives_the_same_episode_bit_for_bit_whatever_ran_before(pipeline_kwargs):
    env = gym.make("agp/Place-v0", control="wheels", instance=name("d"), **pipeline_kwargs)
    try:
        first = run_wheels(env, 7, 60)
        run_wheels(env, 8, 30)
        again = run_wheels(env, 7, 60)
    finally:
        env.close()
    assert gym.utils.env_checker.data_equivalence(first, again, exact=True)
    # And the robot moved: the steps are not all the same.
    assert not np.array_equal(first[1][0]["robot"], first[-1][0]["robot"])


def test_physics_holding_each_command_ten_steps_runs_as_ten_commands_do(pipeline_kwargs):
    held = gym.make("agp/Place-v0", control="wheels", instance=name("h"), **pipeline_kwargs)
    stepped = gym.make("agp/Place-v0", control="wheels", physics_hold=False, instance=name("s"), **pipeline_kwargs)
    try:
        a, b = run_wheels(held, 5, 40), run_wheels(stepped, 5, 40)
        steps = (held.unwrapped._ring.frame.step, stepped.unwrapped._ring.frame.step)
    finally:
        held.close()
        stepped.close()
    assert steps == (400, 400)  # 40 steps of 10 physics steps each, from step 0
    assert gym.utils.env_checker.data_equivalence(a, b, exact=True)


def test_two_environments_run_side_by_side_in_an_async_vector_env_and_leave_no_file(pipeline_kwargs):
    prefix = f"tv-{os.getpid() % 100000}"
    before = shm_files(prefix)
    fns = [
        (lambda k=k: gym.make("agp/Place-v0", control="wheels", instance=f"{prefix}-{k}", **pipeline_kwargs))
        for k in range(2)
    ]
    envs = gym.vector.AsyncVectorEnv(fns)
    try:
        envs.reset(seed=3)
        assert shm_files(prefix) > before  # two pipelines of their own
        for _ in range(100):
            envs.step(envs.action_space.sample())
    finally:
        envs.close()
    assert shm_files(prefix) == before


def test_the_quickstart_prints_both_policies_success_rates(ag_file):
    env = dict(os.environ, AGP_AG=str(ag_file), AGP_BIN_DIR=str(reference_binary().parent))
    done = subprocess.run(
        # Near goals and 4 episodes a policy, for CI's time (the README's run is 10 each).
        [sys.executable, str(REPO / "examples" / "gym" / "quickstart.py"), "--short", "--episodes", "4"],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        cwd=REPO,
    )
    assert done.returncode == 0, done.stderr
    lines = done.stdout.strip().splitlines()
    assert lines[0].startswith("random: placed ") and lines[1].startswith("affordance: placed "), done.stdout
    assert lines[1] != "affordance: placed 0 of 4 (0 %)", done.stdout
