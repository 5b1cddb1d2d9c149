"""`agp/Place-v0` and `agp/Trajectory-v0`: Gymnasium environments, each over a pipeline of
its own in lockstep (`agp-physics`, `agp-estimator` serving an AG file, and at the push
level the skills executor `agp-planner --skills`), which the environment starts and
`close()` stops, leaving nothing in /dev/shm.

The environment is the experimenter and the judge, as `agp bench place`'s private pipeline
is (tools/harness/src/pipeline_bench.rs): each `reset` starts a fresh pipeline, physics's
noise seeded from the episode's seed and the world at the scenario's start, so the same seed
gives the same episode bit for bit whatever ran before; and it alone reads ground truth,
for the reward, the end of the episode and the verdict. Ground truth is never in the
observation.

Actions (normalized Boxes, as Gymnasium recommends; `push_of`/`action_of`, `wheels_of`):

- `control="push"` (default): `[contact, alpha, length]` in [-1, 1]^3: the push aimed at the
  border point the ray from the centroid at `contact_deg = 180 (contact + 1)` meets (object
  frame), heading `alpha_deg = 15 alpha` off the centroid's direction, `length_mm` from 12.5
  (-1) to 50 (+1) once in contact. agp's skills (travel, push, circling to estimate again)
  carry it out; one step is one push.
- `control="wheels"`: `[left, right]` in [-1, 1]^2, times 130 mm/s, for one IR sample at the
  robot's 64 Hz: 10 physics steps at 640 Hz, which physics holds the command for
  (`agp-physics --hold-steps 10`: no round trip per physics step, and one frame a step,
  the one the robot senses at, for the estimator to estimate).

Observation (`Dict`, float32, mm and degrees, world frame unless said): `robot` (x, y,
theta) and `object` (x, y, theta, zeros while invalid) by the estimator, `object_valid`,
`sigma` (how far the object's estimate may be off: mm, deg; capped at 10 m, 360 deg),
`goal` (the goal's x, y, theta in the object's estimated frame; Trajectory: the point 100 mm
ahead on the path), `ir` (the eight raw IR readings of the latest frame, 0..4095).

Reward: how much the true pose error fell this step, the error being mm + `MM_PER_DEG` (1)
per degree of orientation error (modulo the object's symmetry); Trajectory: mm of path
left to go plus mm off the path. `terminated` once the object is within the task's
tolerance (by ground truth); `truncated` at `max_pushes` (push level, 60) or `max_steps`
(wheel level, 7,680: two simulated minutes), or when the skills executor ends the episode
itself (it lost the object, or a push had no start). `info["verdict"]` at the episode's end:
the judge's, by ground truth.
"""

from __future__ import annotations

import ctypes
import gc
import itertools
import math
import os
import shutil
import signal
import subprocess
import tempfile
import time
import tomllib
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from ..payloads import (
    CHOICE_DONE,
    GradientGrid,
    CHOICE_PUSH,
    Payload,
    Pose2,
    PushChoice,
    PushRequest,
    c_u8,
    c_u64,
    c_f64,
)
from ..pipeline import Node, PipelineError, Ring
from ..gradient import Gradient
from ..planner import Push, _die_with_parent, _read_gradient

#: Physics steps per wheel-level step: 640 Hz physics, the robot's 64 Hz IR sampling.
HOLD_STEPS = 10
#: The reward's weight of one degree of orientation error, in mm.
MM_PER_DEG = 1.0
WHEEL_MM_S = 130.0
ALPHA_DEG = 15.0
LENGTH_MM = (12.5, 50.0)
LOOKAHEAD_MM = 100.0
POSITION_BOUND_MM = 10_000.0
SIGMA_CAP = (10_000.0, 360.0)

_instances = itertools.count(1)


class GroundTruth(Payload):
    """Mirror of shared-types' `GroundTruth` (72 bytes): the judge's alone."""

    TYPE_NAME = "agp::GroundTruth.v1"
    _fields_ = [
        ("step", c_u64),
        ("sim_time_s", c_f64),
        ("robot", Pose2),
        ("object", Pose2),
        ("contact", c_u8),
        ("_pad", c_u8 * 7),
    ]


# -- actions -----------------------------------------------------------------------------------


def push_of(action) -> Push:
    """The push a normalized push-level action stands for."""
    a = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
    lo, hi = LENGTH_MM
    return Push(float((a[0] + 1.0) * 180.0 % 360.0), float(a[1] * ALPHA_DEG), float(lo + (a[2] + 1.0) * 0.5 * (hi - lo)))


def action_of(push: Push) -> np.ndarray:
    """The normalized action of `push` (its contact in [0, 360) deg, alpha within +-15 deg,
    length 12.5 to 50 mm)."""
    lo, hi = LENGTH_MM
    return np.array(
        [
            (push.contact_deg % 360.0) / 180.0 - 1.0,
            np.clip(push.alpha_deg / ALPHA_DEG, -1.0, 1.0),
            np.clip((push.length_mm - lo) / (hi - lo) * 2.0 - 1.0, -1.0, 1.0),
        ],
        dtype=np.float32,
    )


def wheels_of(action) -> tuple[float, float]:
    """Wheel speeds, mm/s, of a normalized wheel-level action."""
    left, right = float(action[0]), float(action[1])
    return min(max(left, -1.0), 1.0) * WHEEL_MM_S, min(max(right, -1.0), 1.0) * WHEEL_MM_S


# -- the scenario ------------------------------------------------------------------------------


def _repo_dirs() -> list[Path]:
    """Where a checkout may be: the working folder and its parents."""
    cwd = Path.cwd()
    return [cwd, *cwd.parents]


def _scenario_file(name: str) -> Path:
    p = Path(name)
    if p.is_file():
        return p
    for d in _repo_dirs():
        f = d / "libs" / "world" / "scenarios" / f"{name}.toml"
        if f.is_file():
            return f
    raise gym.error.Error(f"cannot find scenario `{name}` (a file, or a built-in under libs/world/scenarios/ above the working folder)")


def _symmetry_order(obj: dict) -> int:
    """The shape's true rotational symmetry (0: a disc): the judge's, from the scenario."""
    if obj.get("shape") == "circle":
        return 0
    v = np.asarray(obj.get("vertices_mm", []), dtype=np.float64)
    if len(v) < 3:
        return 1
    x, y = v[:, 0], v[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area = cross.sum() / 2.0
    c = np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (6.0 * area)
    rel = v - c
    for k in range(len(v), 1, -1):
        a = 2.0 * math.pi / k
        rot = rel @ np.array([[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]])
        if all(np.min(np.hypot(*(rel - p).T)) < 0.25 for p in rot):  # vertices are given to 0.1 mm
            return k
    return 1


def _wrap_deg(a: float, order: int = 1) -> float:
    if order == 0:
        return 0.0
    period = 360.0 / order
    return (a + 0.5 * period) % period - 0.5 * period


def _find_binary(name: str, bin_dir: str | None) -> str:
    dirs = [bin_dir or os.environ.get("AGP_BIN_DIR")]
    for d in _repo_dirs():
        dirs += [str(d / "target" / "release"), str(d / "target" / "debug")]
    for d in dirs:
        if d and (Path(d) / name).is_file():
            return str(Path(d) / name)
    found = shutil.which(name)
    if found is None:
        raise gym.error.Error(
            f"cannot find {name}: build it (`cargo build --release --workspace --bins`), or pass bin_dir= (or set AGP_BIN_DIR)"
        )
    return found


def _find_ag(obj_name: str, ag: str | None) -> Path:
    if ag or os.environ.get("AGP_AG"):
        p = Path(ag or os.environ["AGP_AG"])
        if not p.is_file():
            raise gym.error.Error(f"no AG file at {p}")
        return p.resolve()
    for d in _repo_dirs():
        p = d / "results" / f"{obj_name}.ag"
        if p.is_file():
            return p.resolve()
    raise gym.error.Error(
        f"no AG file for `{obj_name}`: run `target/release/agp up` once (it learns results/{obj_name}.ag), or pass ag=PATH (or set AGP_AG)"
    )


# -- the processes -----------------------------------------------------------------------------


class _Child:
    """A child process of the environment, its stderr in a log file, SIGTERM when the
    environment's process dies."""

    def __init__(self, what: str, args: list[str], logs: Path, env: dict[str, str]):
        self.what = what
        self.log = logs / f"{what}.log"
        with open(self.log, "ab") as err:
            self.proc = subprocess.Popen(
                args, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=err, env=env, preexec_fn=_die_with_parent
            )

    def tail(self) -> str:
        try:
            lines = self.log.read_text(errors="replace").strip().splitlines()
        except OSError:
            return ""
        return " / ".join(lines[-3:])

    def stop(self, grace_s: float = 10.0) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout=grace_s)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


class AgpEnv(gym.Env):
    """One agp pipeline as a Gymnasium environment (see the module's doc). Prefer
    `gymnasium.make("agp/Place-v0", ...)`."""

    metadata = {"render_modes": []}

    def __init__(
        self,
        scenario: str = "triangle",
        task: str = "place",
        control: str = "push",
        seed: int | None = None,
        goal: tuple[float, float, float] | None = None,
        path: list[tuple[float, float]] | None = None,
        max_pushes: int = 60,
        max_steps: int = 7680,
        ag: str | None = None,
        bin_dir: str | None = None,
        instance: str | None = None,
        goal_distance_mm: tuple[float, float] = (250.0, 500.0),
        timeout_s: float = 300.0,
        physics_hold: bool = True,
        wait: str | None = None,
    ):
        """`physics_hold=False` (wheel level): one command per physics step, the round trip
        each time, instead of physics holding each for 10 (the same run, slower).

        `wait`: how the pipeline's processes and this one wait for each other (`AGP_WAIT`'s
        values, which the environment gives its processes). By default, at the wheel level
        `block`: each sleeps until notified. A polling wait (`spin-then-block:200`, the
        pipeline's default) yields the CPU between polls, and on a machine shared with
        other work each yield lets another process run out its time slice: at load 22 a
        wheel step took 3 times as long polling (406 us against 117). At the push level
        the pipeline's default: there the executor, physics and the estimator hand over
        at every physics step, where blocking's system calls cost more than they save
        (43 simulated s per wall s blocking, 54 polling, at load 23)."""
        if task not in ("place", "trajectory"):
            raise gym.error.Error(f"task must be `place` or `trajectory`, not `{task}`")
        if control not in ("push", "wheels"):
            raise gym.error.Error(f"control must be `push` or `wheels`, not `{control}`")
        self.task, self.control = task, control
        self.max_pushes, self.max_steps = int(max_pushes), int(max_steps)
        self.timeout_s = float(timeout_s)
        self.physics_hold = bool(physics_hold)
        self.wait = str(wait) if wait is not None else ("block" if control == "wheels" else "spin-then-block:200")
        self._first_seed = seed
        self._fixed_goal = goal
        self._goal_distance = goal_distance_mm
        path_file = _scenario_file(scenario)
        self.scenario_arg = str(path_file) if Path(scenario).is_file() else scenario
        with open(path_file, "rb") as f:
            sc = tomllib.load(f)
        self.scenario_name = sc.get("name", path_file.stem)
        o, r, t = sc["object"]["start"], sc["robot"]["start"], sc["task"]
        self.object_start = (o["x_mm"], o["y_mm"], o["theta_deg"])
        self.robot_start = (r["x_mm"], r["y_mm"], r["theta_deg"])
        self.tolerance = (float(t["tolerance"]["mm"]), float(t["tolerance"]["deg"]))
        self.true_order = _symmetry_order(sc["object"])
        if path is None:
            pts = t.get("path_mm")
            path = [tuple(p) for p in pts] if pts else [self.object_start[:2], (self.object_start[0] + 600.0, self.object_start[1])]
        self.path = np.asarray(path, dtype=np.float64)
        self.ag_path = _find_ag(self.scenario_name, ag)
        self.bins = {n: _find_binary(n, bin_dir) for n in ("agp-physics", "agp-estimator", "agp-planner")}
        self.instance = instance or f"gym-{os.getpid() % 100000}-{next(_instances)}"

        if control == "push":
            self.action_space = spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)
        else:
            self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        pose_lo = np.array([-POSITION_BOUND_MM, -POSITION_BOUND_MM, -180.0], dtype=np.float32)
        pose = spaces.Box(pose_lo, -pose_lo, dtype=np.float32)
        self.observation_space = spaces.Dict(
            {
                "robot": pose,
                "object": pose,
                "object_valid": spaces.Discrete(2),
                "sigma": spaces.Box(np.zeros(2, np.float32), np.array(SIGMA_CAP, np.float32), dtype=np.float32),
                "goal": pose,
                "ir": spaces.Box(0.0, 4095.0, shape=(8,), dtype=np.float32),
            }
        )
        self._procs: dict[str, _Child] = {}
        self._logs: Path | None = None
        self._node = self._ring = None
        self._ag = None
        self._episode: dict[str, Any] | None = None
        self.start_radius_mm: float | None = None
        self.symmetry_order: int | None = None
        self._reset_count = 0

    # -- the pipeline --------------------------------------------------------------------------

    def _start(self, noise_seed: int) -> None:
        """A fresh pipeline: physics (its noise seeded `noise_seed`, the world at the
        scenario's start) and the estimator. Every episode gets one, so an episode is the
        same whatever ran before it (an estimator that served an earlier episode remembers
        its planner's events)."""
        self._stop_pipeline()
        self._started = True
        self._remove_files()
        self._logs = Path(tempfile.mkdtemp(prefix=f"agp-{self.instance}-"))
        common = ["--instance", self.instance, "--scenario", self.scenario_arg]
        physics = [self.bins["agp-physics"], *common, "--clock", "lockstep", "--idle-timeout-s", "0", "--seed", str(noise_seed)]
        if self.control == "wheels" and self.physics_hold:
            physics += ["--hold-steps", str(HOLD_STEPS)]
        try:
            self._procs["physics"] = _Child("physics", physics, self._logs, self._child_env())
            self._procs["estimator"] = _Child(
                "estimator", [self.bins["agp-estimator"], *common, "--load", str(self.ag_path)], self._logs, self._child_env()
            )
            self._node = Node(self.instance, f"gym-env-{os.getpid()}", timeout_s=self.timeout_s)
            n = self._node
            self._truth = n.pubsub("agp/ground_truth", GroundTruth).subscriber_builder().buffer_size(1).create()
            qos = {"history": 1, "buffer": 4}
            self._requests = n.pubsub("agp/push_requests", PushRequest, create=qos).subscriber_builder().create()
            self._choices = n.pubsub("agp/push_choices", PushChoice, create=qos).publisher_builder().create()
            self._ring = Ring(self._node, 0, 0, buffer=1, wait=self.wait)
        except Exception as e:
            why = "; ".join(f"{k}: {c.tail()}" for k, c in self._procs.items() if c.proc.poll() is not None)
            self.close()
            raise PipelineError(f"cannot start the pipeline of `{self.instance}`: {e}{' (' + why + ')' if why else ''}") from e

    def _child_env(self) -> dict[str, str]:
        """The environment of the pipeline's processes: this one's, with the environment's
        `wait`, and no supervisor's session (the pipeline is the environment's own)."""
        env = {k: v for k, v in os.environ.items() if k not in ("AGP_EPOCH", "AGP_TOKEN", "AGP_SESSION_KEY")}
        env["AGP_WAIT"] = self.wait
        return env

    @property
    def ag(self):
        """The affordance gradient the estimator serves, as `agp.Gradient`: read from the
        grids topic on the first reset and copied once (9 MB), since it outlives each
        episode's pipeline."""
        if self._ag is None:
            if self._node is None:
                raise gym.error.ResetNeeded("call reset() before reading the AG")
            view = _read_gradient(self._node, self.timeout_s)
            sub, samples = view._held
            size = ctypes.sizeof(GradientGrid)
            buffers = [bytearray((ctypes.c_uint8 * size).from_address(s.payload_ptr)) for s in samples]
            del view
            for s in samples:
                s.delete()
            del sub, samples
            self._ag = Gradient.from_buffers(buffers)
        return self._ag

    def _remove_files(self) -> None:
        base = Path(os.environ.get("AGP_IOX2_ROOT", "/tmp/agp"))
        prefix = f"agp_{self.instance}."
        try:
            for f in os.listdir("/dev/shm"):
                if f.startswith(prefix):
                    try:
                        os.remove(os.path.join("/dev/shm", f))
                    except FileNotFoundError:
                        pass
        except FileNotFoundError:
            pass
        shutil.rmtree(base / self.instance, ignore_errors=True)

    def close(self) -> None:
        """Stops the pipeline's processes and removes every file of its instance."""
        self._stop_pipeline()
        self._ag = None

    def _stop_pipeline(self) -> None:
        self._end_executor()
        for what in ("estimator", "physics"):
            c = self._procs.pop(what, None)
            if c is not None:
                c.stop()
        self._procs.clear()
        if self._ring is not None:
            self._ring.close()
        for a in ("_ring", "_truth", "_requests", "_choices", "_node"):
            if hasattr(self, a):
                setattr(self, a, None)
        gc.collect()
        if getattr(self, "_started", False):  # a copy made by name never started removes nothing
            self._remove_files()
            self._started = False
        if self._logs is not None:
            shutil.rmtree(self._logs, ignore_errors=True)
            self._logs = None

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass

    # -- the judge ------------------------------------------------------------------------------

    def _true_pose(self) -> tuple[float, float, float]:
        while (s := self._truth.receive()) is not None:
            o = GroundTruth.from_address(s.payload_ptr).object
            self._truth_pose = (o.x * 1e3, o.y * 1e3, math.degrees(o.theta))
            del o
            s.delete()
        return self._truth_pose

    def _path_error(self, x: float, y: float) -> tuple[float, float, float]:
        """(mm of path left from the nearest point, mm off the path, arc length there)."""
        p = self.path
        seg = p[1:] - p[:-1]
        lengths = np.hypot(seg[:, 0], seg[:, 1])
        best = (math.inf, 0.0)
        along = 0.0
        for k in range(len(seg)):
            t = 0.0 if lengths[k] == 0 else float(np.clip(((x - p[k, 0]) * seg[k, 0] + (y - p[k, 1]) * seg[k, 1]) / lengths[k] ** 2, 0.0, 1.0))
            q = p[k] + t * seg[k]
            d = math.hypot(x - q[0], y - q[1])
            if d < best[0]:
                best = (d, along + t * lengths[k])
            along += lengths[k]
        return along - best[1], best[0], best[1]

    def _error(self, pose) -> tuple[float, float, float]:
        """The true error: (reward's error, mm, deg)."""
        x, y, th = pose
        if self.task == "place":
            gx, gy, gth = self.goal
            mm = math.hypot(x - gx, y - gy)
            deg = abs(_wrap_deg(th - gth, self.true_order))
            return mm + MM_PER_DEG * deg, mm, deg
        left, off, _ = self._path_error(x, y)
        end = self.path[-1]
        return left + off, math.hypot(x - end[0], y - end[1]), off

    def _within(self, mm: float, deg: float) -> bool:
        if self.task == "place":
            return mm <= self.tolerance[0] and deg <= self.tolerance[1]
        return mm <= self.tolerance[0]

    # -- observation ----------------------------------------------------------------------------

    def _target(self, ox: float, oy: float) -> tuple[float, float, float]:
        if self.task == "place":
            return self.goal
        p = self.path
        _, _, s = self._path_error(ox, oy)
        s += LOOKAHEAD_MM
        for k in range(len(p) - 1):
            d = math.hypot(*(p[k + 1] - p[k]))
            if s <= d and d > 0:
                q = p[k] + s / d * (p[k + 1] - p[k])
                return float(q[0]), float(q[1]), 0.0
            s -= d
        return float(p[-1, 0]), float(p[-1, 1]), 0.0

    def _obs(self, robot, obj, valid: bool, sigma, ir) -> dict:
        b = POSITION_BOUND_MM
        ox, oy, oth = obj if valid else (0.0, 0.0, 0.0)
        gx, gy, gth = self._target(ox, oy)
        c, s = math.cos(math.radians(oth)), math.sin(math.radians(oth))
        dx, dy = gx - ox, gy - oy
        rx, ry, rth = robot
        lx, ly = c * dx + s * dy, -s * dx + c * dy
        sig_mm = sigma[0] if sigma[0] == sigma[0] else SIGMA_CAP[0]  # NaN: unknown
        sig_deg = sigma[1] if sigma[1] == sigma[1] else SIGMA_CAP[1]
        # One array, its parts the observation's (a step's observation allocates once).
        # Physics clamps the IR readings to 0..4095.
        v = np.array(
            (
                min(max(rx, -b), b), min(max(ry, -b), b), (rth + 180.0) % 360.0 - 180.0,
                min(max(ox, -b), b), min(max(oy, -b), b), (oth + 180.0) % 360.0 - 180.0,
                min(max(sig_mm, 0.0), SIGMA_CAP[0]), min(max(sig_deg, 0.0), SIGMA_CAP[1]),
                min(max(lx, -b), b), min(max(ly, -b), b), (gth - oth + 180.0) % 360.0 - 180.0,
                *ir,
            ),
            dtype=np.float32,
        )  # fmt: skip
        return {
            "robot": v[0:3],
            "object": v[3:6],
            "object_valid": int(valid),
            "sigma": v[6:8],
            "goal": v[8:11],
            "ir": v[11:19],
        }

    def _frame_obs(self, drain: bool = True) -> dict:
        r = self._ring
        if drain:
            r._drain()
        e = r.estimate
        robot, pose = e.robot, e.pose
        valid = e.valid == 1
        return self._obs(
            (robot.x * 1e3, robot.y * 1e3, math.degrees(robot.theta)),
            (pose.x * 1e3, pose.y * 1e3, math.degrees(pose.theta)),
            valid,
            (e.sigma_xy * 1e3, math.degrees(e.sigma_theta)) if valid else SIGMA_CAP,
            r.frame.ir_raw,
        )

    def _request_obs(self) -> dict:
        q = self._request
        self._ring._drain()
        return self._obs(
            (q.robot.x * 1e3, q.robot.y * 1e3, math.degrees(q.robot.theta)),
            (q.object.x * 1e3, q.object.y * 1e3, math.degrees(q.object.theta)),
            True,
            (q.sigma_xy * 1e3, math.degrees(q.sigma_theta)),
            self._ring.frame.ir_raw,
        )

    # -- episodes -------------------------------------------------------------------------------

    def _sample_goal(self) -> tuple[float, float, float]:
        d = self.np_random.uniform(*self._goal_distance)
        a = self.np_random.uniform(0.0, 2.0 * math.pi)
        th = self.np_random.uniform(-180.0, 180.0)
        ox, oy, _ = self.object_start
        return (float(ox + d * math.cos(a)), float(oy + d * math.sin(a)), float(th))

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        if seed is None and self._first_seed is not None:
            seed = self._first_seed
        self._first_seed = None  # make(..., seed=S): the first reset's seed only
        super().reset(seed=seed)
        options = options or {}
        noise_seed = int(self.np_random.integers(1, 2**63 - 1))
        sampled = self._sample_goal()
        goal = options.get("goal", self._fixed_goal)
        self.goal = tuple(float(v) for v in goal) if goal is not None else sampled
        if self.task == "trajectory":
            end = self.path[-1]
            self.goal = (float(end[0]), float(end[1]), 0.0)
        self._start(noise_seed)
        self._first_truth()
        self._episode = {"steps": 0, "pushes": 0, "start_sim_s": self._ring.frame.sim_time_s, "off_path": []}
        if self.control == "push":
            self.ag  # read while the estimator serves it (the policies ask for it)
            self._start_executor()
            if not self._await_request():
                raise PipelineError(f"the skills executor ended before its first push request: {self._executor_tail}")
            obs = self._request_obs()
        else:
            obs = self._frame_obs()
        self._last_error = self._error(self._true_pose())[0]
        return obs, {"goal": self.goal, "noise_seed": noise_seed}

    def _first_truth(self) -> None:
        """Until the ground truth of the frame the ring holds is in."""
        self._truth_pose = None
        deadline = time.monotonic() + self.timeout_s
        while self._truth_pose is None:
            s = self._truth.receive()
            if s is None:
                if time.monotonic() > deadline:
                    raise PipelineError(f"no ground truth within {self.timeout_s:.0f} s")
                time.sleep(50e-6)
                continue
            g = GroundTruth.from_address(s.payload_ptr)
            self._truth_pose = (g.object.x * 1e3, g.object.y * 1e3, math.degrees(g.object.theta))
            del g
            s.delete()

    # -- push level ----------------------------------------------------------------------------

    def _start_executor(self) -> None:
        gx, gy, gth = self.goal
        args = [
            self.bins["agp-planner"],
            "--instance", self.instance,
            "--scenario", self.scenario_arg,
            "--clock", "lockstep",
            "--planner", "affordance",
            "--mode", "place",
            "--skills",
            "--goal", f"{gx!r},{gy!r},{gth!r}",
        ]  # fmt: skip
        env = self._child_env()
        self._answered = 0
        self._request = None
        self._request_sample = None
        with open(self._logs / "executor.log", "wb") as err:
            proc = subprocess.Popen(args, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=err, env=env, preexec_fn=_die_with_parent)
        self._executor = proc

    @property
    def _executor_tail(self) -> str:
        try:
            return " / ".join((self._logs / "executor.log").read_text(errors="replace").strip().splitlines()[-3:])
        except OSError:
            return ""

    def _await_request(self) -> bool:
        """Until the executor's next push request (True) or its exit (False)."""
        deadline = time.monotonic() + self.timeout_s
        pause = 50e-6
        while True:
            s = self._requests.receive()
            if s is not None:
                r = PushRequest.from_address(s.payload_ptr)
                if r.epoch != 0 or r.seq <= self._answered:
                    del r
                    s.delete()
                    continue
                if self._request_sample is not None:
                    self._request = None
                    self._request_sample.delete()
                self._request_sample, self._request = s, r
                self.start_radius_mm = r.start_radius_m * 1e3
                self.symmetry_order = r.symmetry_order
                self.full_only = r.full_only == 1
                return True
            if self._executor is None or self._executor.poll() is not None:
                return False
            if time.monotonic() > deadline:
                raise PipelineError(f"no push request within {self.timeout_s:.0f} s: {self._executor_tail}")
            # The topic has no event to wake on: polls, from every 50 us to every 1 ms
            # while a push (tenths of a second of wall time) is carried out, so the polls
            # take little of the CPU the pipeline needs.
            time.sleep(pause)
            pause = min(2.0 * pause, 1e-3)

    def _answer(self, kind: int, push: Push | None = None) -> None:
        seq = self._request.seq
        u = self._choices.loan_uninit()
        c = PushChoice.from_address(u.payload_ptr)
        ctypes.memset(ctypes.addressof(c), 0, ctypes.sizeof(PushChoice))
        c.seq, c.epoch, c.kind = seq, 0, kind
        if push is not None:
            c.contact_deg, c.alpha_deg, c.length_mm = push.contact_deg, push.alpha_deg, push.length_mm
        del c
        u.assume_init().send()
        self._answered = seq
        self._request = None
        self._request_sample.delete()
        self._request_sample = None

    def _end_executor(self) -> None:
        proc = getattr(self, "_executor", None)
        if proc is None:
            return
        if proc.poll() is None and getattr(self, "_request", None) is not None:
            self._answer(CHOICE_DONE)
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                pass
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        if getattr(self, "_request_sample", None) is not None:
            self._request = None
            self._request_sample.delete()
            self._request_sample = None
        self._executor = None

    # -- steps ---------------------------------------------------------------------------------

    def step(self, action):
        if self._episode is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        ep = self._episode
        ep["steps"] += 1
        ended_by_executor = False
        if self.control == "push":
            push = push_of(action)
            self._answer(CHOICE_PUSH, push)
            ep["pushes"] += 1
            if self._await_request():
                obs = self._request_obs()
            else:
                ended_by_executor = True
                obs = self._frame_obs()
        else:
            left, right = wheels_of(action)
            if self.physics_hold:
                self._ring.step(left * 1e-3, right * 1e-3, HOLD_STEPS)
            else:
                for _ in range(HOLD_STEPS):
                    self._ring.step(left * 1e-3, right * 1e-3)
            # The ring's wait took in the frame and its estimate, and physics publishes no
            # other before the next command.
            obs = self._frame_obs(drain=False)
        pose = self._true_pose()
        err, mm, deg = self._error(pose)
        reward = float(self._last_error - err)
        self._last_error = err
        if self.task == "trajectory":
            ep["off_path"].append(deg)
        terminated = bool(self._within(mm, deg))
        limit = ep["pushes"] >= self.max_pushes if self.control == "push" else ep["steps"] >= self.max_steps
        truncated = bool(not terminated and (limit or ended_by_executor))
        info: dict[str, Any] = {"pushes": ep["pushes"], "steps": ep["steps"]}
        if terminated or truncated:
            if self.control == "push":
                self._end_executor()
            end = "done" if terminated else ("executor ended" if ended_by_executor else "limit")
            info["verdict"] = self._verdict(mm, deg, end)
            self._episode = None
        return obs, reward, terminated, truncated, info

    def _verdict(self, mm: float, deg: float, end: str) -> dict:
        sim_s = self._ring.frame.sim_time_s - self._episode["start_sim_s"]
        v = {
            "success": bool(self._within(mm, deg)),
            "end": end,
            "pushes": self._episode["pushes"],
            "steps": self._episode["steps"],
            "sim_time_s": round(sim_s, 6),
            "tolerance_mm": self.tolerance[0],
        }
        if self.task == "place":
            v.update(final_error_mm=mm, final_error_deg=deg, tolerance_deg=self.tolerance[1])
        else:
            off = self._episode["off_path"]
            v.update(final_distance_mm=mm, mean_off_path_mm=float(np.mean(off)) if off else 0.0)
        return v


class PlaceEnv(AgpEnv):
    """`agp/Place-v0`: place the object at a goal pose (by default drawn from the seed:
    250 to 500 mm from the object's start in any direction, any orientation)."""

    def __init__(self, **kwargs):
        super().__init__(task="place", **kwargs)


class TrajectoryEnv(AgpEnv):
    """`agp/Trajectory-v0`: push the object along a path (by default the scenario's, or
    600 mm straight along +x from its start) to its end."""

    def __init__(self, **kwargs):
        super().__init__(task="trajectory", **kwargs)
