"""The two levels of planner and `run`, which drives either under `agp up`.

Wheel level: subclass `Planner`; `agp.run` calls `on_goal(goal)` when a goal starts and
`step(obs)` once per physics frame, sending the `Wheels` it returns (None: the goal is
reached). Push level: subclass `PushPlanner`; `agp.run` starts `agp-planner --skills` as its
own child, which carries out each push the planner's `choose_push(obs)` returns (None: the
goal is reached) with the pipeline's own skills: travel, push, circling.

Either serves a live session's goals one after another with `--serve` among the script's
arguments (launch.toml: `args = ["--serve"]`), reporting each end to the supervisor, and
otherwise the scenario's goal (or `--goal X_MM,Y_MM,THETA_DEG`), once. It takes over on a hot swap (`AGP_EPOCH` > 0), hands
over when swapped out (SIGTERM), and carries on after a physics restart.
"""

from __future__ import annotations

import ctypes
import math
import os
import shutil
import signal
import subprocess
import sys
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import pipeline
from .gradient import Gradient
from .payloads import (
    CHOICE_DONE,
    CHOICE_PUSH,
    GRIDS_PER_ALPHA,
    TASK_KIND_PLACE,
    Goal as GoalPayload,
    GradientGrid,
    IrFrame,
    ObjectEstimate,
    PushChoice,
    PushRequest,
    Task,
)
from .pipeline import Control, Node, PhysicsRestarted, PipelineError, Ring, Shutdown


@dataclass(frozen=True)
class Wheels:
    """Wheel speeds, mm/s (the E-puck's reach +-130 mm/s)."""

    left_mm_s: float
    right_mm_s: float


@dataclass(frozen=True)
class Push:
    """A push: aimed at the border point the ray from the centroid at `contact_deg` meets
    (object frame), heading `alpha_deg` off the centroid's direction, `length_mm` long once
    in contact (the learned push is 50 mm)."""

    contact_deg: float
    alpha_deg: float
    length_mm: float = 50.0


@dataclass(frozen=True)
class Goal:
    """A goal: place the object at (x_mm, y_mm, theta_deg), world frame, within the
    tolerance. `id` is the live session's (0: the scenario's task)."""

    id: int
    x_mm: float
    y_mm: float
    theta_deg: float
    tolerance_mm: float
    tolerance_deg: float
    path_mm: tuple = field(default=())

    @classmethod
    def from_task(cls, goal_id: int, t: Task) -> "Goal":
        path = tuple((t.path[k][0] * 1e3, t.path[k][1] * 1e3) for k in range(t.path_len))
        return cls(
            goal_id,
            t.goal.x * 1e3,
            t.goal.y * 1e3,
            math.degrees(t.goal.theta),
            t.tolerance_m * 1e3,
            math.degrees(t.tolerance_rad),
            path,
        )


class Obs:
    """What a wheel-level planner sees at one frame, read in place from the loaned samples
    (valid during `step` only): `frame` (the IR frame) and `estimate` (the estimator's
    estimate of it) are ctypes views of sample memory, `ir` a numpy view of the readings."""

    __slots__ = ("frame", "estimate", "goal")

    def __init__(self) -> None:
        self.frame: IrFrame = IrFrame()
        self.estimate: ObjectEstimate = ObjectEstimate()
        self.goal: Goal | None = None

    @property
    def t(self) -> float:
        """Simulated time, s."""
        return self.frame.sim_time_s

    @property
    def step(self) -> int:
        return self.frame.step

    @property
    def ir(self) -> np.ndarray:
        """The raw IR readings IR1..IR8 (numpy view, no copy)."""
        return np.ctypeslib.as_array(self.frame.ir_raw)

    @property
    def robot(self) -> tuple[float, float, float]:
        """The robot's pose by the estimator: x_mm, y_mm, theta_deg."""
        r = self.estimate.robot
        return r.x * 1e3, r.y * 1e3, math.degrees(r.theta)

    @property
    def object(self) -> tuple[float, float, float] | None:
        """The object's estimated pose (x_mm, y_mm, theta_deg), None while it has none."""
        e = self.estimate
        if e.valid != 1:
            return None
        return e.pose.x * 1e3, e.pose.y * 1e3, math.degrees(e.pose.theta)

    @property
    def sigma(self) -> tuple[float, float]:
        """How far the object's estimate may be off: mm, deg."""
        e = self.estimate
        return e.sigma_xy * 1e3, math.degrees(e.sigma_theta)

    @property
    def front_gap_mm(self) -> float | None:
        g = self.estimate.front_gap_m
        return g * 1e3 if g >= 0.0 else None

    @property
    def contact(self) -> bool:
        return self.estimate.contact == 1

    @property
    def symmetry_order(self) -> int:
        return self.estimate.symmetry_order


class PushObs:
    """What a push-level planner sees before a push (the executor's request, read in place):
    the object's estimate, the goal, the robot, counts, and the affordance gradient `ag`."""

    __slots__ = ("request", "ag", "goal")

    def __init__(self, request: PushRequest, ag: Gradient, goal: Goal):
        self.request, self.ag, self.goal = request, ag, goal

    @property
    def object(self) -> tuple[float, float, float]:
        o = self.request.object
        return o.x * 1e3, o.y * 1e3, math.degrees(o.theta)

    @property
    def sigma(self) -> tuple[float, float]:
        r = self.request
        return r.sigma_xy * 1e3, math.degrees(r.sigma_theta)

    @property
    def robot(self) -> tuple[float, float, float]:
        o = self.request.robot
        return o.x * 1e3, o.y * 1e3, math.degrees(o.theta)

    @property
    def target(self) -> tuple[float, float, float]:
        """Where the object should go now (place: the goal; a path: the point ahead), mm, deg."""
        g = self.request.goal
        return g.x * 1e3, g.y * 1e3, math.degrees(g.theta)

    @property
    def pushes(self) -> int:
        return self.request.pushes

    @property
    def pushes_since_estimate(self) -> int:
        return self.request.pushes_since_estimate

    @property
    def symmetry_order(self) -> int:
        return self.request.symmetry_order

    @property
    def full_only(self) -> bool:
        """The last pushes left the object where it was: push full length now."""
        return self.request.full_only == 1

    @property
    def t(self) -> float:
        return self.request.sim_time_s


class Planner:
    """A wheel-level planner: override `step` (and `on_goal`, `on_restart` as needed)."""

    def on_goal(self, goal: Goal) -> None:
        """A goal starts (the scenario's, or the next of a live session)."""

    def step(self, obs: Obs) -> Wheels | None:
        """The wheels for this frame; None: the goal is reached (its end is reported)."""
        raise NotImplementedError

    def on_restart(self) -> None:
        """Physics restarted: a new world from the scenario's start (`on_goal` follows)."""


class PushPlanner:
    """A push-level planner: override `choose_push` (and `on_goal` as needed)."""

    def on_goal(self, goal: Goal) -> None:
        """A goal starts."""

    def choose_push(self, obs: PushObs) -> Push | None:
        """The next push; None: the goal is reached."""
        raise NotImplementedError


def _say(text: str) -> None:
    print(f"{Path(sys.argv[0]).name}: {text}", flush=True)


def _scenario_goal() -> Goal:
    """The scenario's place task (`AGP_SCENARIO`: a file, or a built-in name found under
    libs/world/scenarios/ above the working folder or this script)."""
    name = os.environ.get("AGP_SCENARIO", "triangle")
    path = Path(name)
    if not path.is_file():
        for start in (Path.cwd(), Path(sys.argv[0]).resolve().parent):
            for d in (start, *start.parents):
                p = d / "libs" / "world" / "scenarios" / f"{name}.toml"
                if p.is_file():
                    path = p
                    break
            if path.is_file():
                break
        else:
            raise SystemExit(f"{Path(sys.argv[0]).name}: cannot find scenario `{name}`")
    with open(path, "rb") as f:
        t = tomllib.load(f)["task"]
    g = t["goal"]
    return Goal(0, g["x_mm"], g["y_mm"], g["theta_deg"], t["tolerance"]["mm"], t["tolerance"]["deg"])


def _environment() -> tuple[str, int, int, bool]:
    instance = os.environ.get("AGP_INSTANCE")
    if not instance:
        raise SystemExit(f"{Path(sys.argv[0]).name}: AGP_INSTANCE is not set: start it with `agp up` from a launch file")
    return instance, int(os.environ.get("AGP_EPOCH", "0")), int(os.environ.get("AGP_TOKEN", "0")), "--serve" in sys.argv[1:]


def run(planner: Planner | PushPlanner) -> int:
    """Runs `planner` under `agp up` until its goal is reached (or, with `--serve`, until
    `agp down`). Returns the exit code; `sys.exit(agp.run(MyPlanner()))`."""
    pipeline.install_signal_handlers()
    try:
        if isinstance(planner, PushPlanner):
            return _run_push(planner)
        return _run_wheels(planner)
    except Shutdown:
        return 0
    except PipelineError as e:
        print(f"{Path(sys.argv[0]).name}: error: {e}", file=sys.stderr, flush=True)
        return 1


# -- wheel level -------------------------------------------------------------------------------


class _TaskPublisher:
    """The latched `agp/task`: the goal under way, what the judge scores."""

    def __init__(self, node: Node):
        self.pub = node.pubsub("agp/task", Task).publisher_builder().create()

    def send(self, goal: Goal) -> None:
        u = self.pub.loan_uninit()
        t = Task.from_address(u.payload_ptr)
        ctypes.memset(ctypes.addressof(t), 0, ctypes.sizeof(Task))
        t.kind = TASK_KIND_PLACE
        t.goal.x, t.goal.y, t.goal.theta = goal.x_mm * 1e-3, goal.y_mm * 1e-3, math.radians(goal.theta_deg)
        t.tolerance_m, t.tolerance_rad = goal.tolerance_mm * 1e-3, math.radians(goal.tolerance_deg)
        t.max_pushes = 150
        del t
        u.assume_init().send()


def _run_wheels(planner: Planner) -> int:
    instance, epoch, token, serve = _environment()
    node = Node(instance, f"py-planner-{os.getpid()}")
    ring = Ring(node, epoch, token)
    control = Control(node) if (epoch > 0 or serve) else None
    if epoch > 0:
        ring.take_over(control)
    tasks = _TaskPublisher(node)
    goals = node.pubsub("agp/goal", GoalPayload).subscriber_builder().create() if serve else None
    period = 1.0 / float(os.environ.get("AGP_RATE_HZ", "640")) if os.environ.get("AGP_CLOCK", "lockstep") == "lockstep" else 0.0
    latest = GoalPayload()
    ended = 0
    goal: Goal | None = None
    if not serve:
        goal = _scenario_goal()
        argv = sys.argv[1:]
        if "--goal" in argv[:-1]:
            x, y, t = (float(v) for v in argv[argv.index("--goal") + 1].split(","))
            goal = Goal(0, x, y, t, goal.tolerance_mm, goal.tolerance_deg)
    obs = Obs()
    started, wall, steps = ring.frame.sim_time_s, time.monotonic(), 0
    try:
        while True:
            if serve and goal is None:
                latest = pipeline.latest_goal(goals, latest)
                if latest.id != 0 and latest.id != ended:
                    goal = Goal.from_task(latest.id, latest.task)
            if goal is not None and obs.goal is not goal:
                obs.goal = goal
                tasks.send(goal)
                started, wall, steps = ring.frame.sim_time_s, time.monotonic(), ring.steps
                _say(f"goal {goal.id}: place at ({goal.x_mm:.0f}, {goal.y_mm:.0f}) mm, {goal.theta_deg:.0f} deg")
                planner.on_goal(goal)
            try:
                if goal is None:
                    ring.idle(period)
                    continue
                obs.frame, obs.estimate = ring.frame, ring.estimate
                wheels = planner.step(obs)
                if wheels is None:
                    spent = ring.frame.sim_time_s - started
                    n, w = ring.steps - steps, time.monotonic() - wall
                    _say(f"goal {goal.id} done after {spent:.1f} s simulated, {n} steps in {w:.2f} s wall ({n / max(w, 1e-9):.0f} steps/s)")
                    if not serve:
                        return 0
                    answer = control.goal_done(goal.id, "done", spent)
                    if answer.ok == 0:
                        _say(f"the supervisor did not take goal {goal.id} as ended: {pipeline.read_str(answer.message)}")
                    ended, goal, obs.goal = goal.id, None, None
                    continue
                ring.step(wheels.left_mm_s * 1e-3, wheels.right_mm_s * 1e-3)
            except PhysicsRestarted:
                _say("physics restarted: the goal starts over")
                planner.on_restart()
                obs.goal = None  # on_goal again, from the new world
    finally:
        ring.close()


# -- push level --------------------------------------------------------------------------------


def _planner_binary() -> str:
    """`agp-planner`: $AGP_PLANNER_BIN, else beside the `agp` that started this process
    (the supervisor), else on PATH."""
    if os.environ.get("AGP_PLANNER_BIN"):
        return os.environ["AGP_PLANNER_BIN"]
    try:
        parent = Path(os.readlink(f"/proc/{os.getppid()}/exe").removesuffix(" (deleted)"))
        candidate = parent.parent / "agp-planner"
        if candidate.is_file():
            return str(candidate)
    except OSError:
        pass
    found = shutil.which("agp-planner")
    if found is None:
        raise PipelineError("cannot find agp-planner (set AGP_PLANNER_BIN, or put it on PATH)")
    return found


def _die_with_parent() -> None:
    """In the child, before exec: SIGTERM when this process dies (prctl PR_SET_PDEATHSIG)."""
    libc = ctypes.CDLL(None, use_errno=True)
    PR_SET_PDEATHSIG = 1
    libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)


def _read_gradient(node: Node, timeout_s: float = 120.0) -> Gradient:
    """The newest complete grid set on `agp/grids` (from the topic's history), read in
    place: every grid of the gradient is a numpy view over its loaned sample, and the
    gradient holds those samples (and their subscriber) for as long as it lives. The
    service lets one reader hold a whole set (`Qos::grids` in agp-runtime). A set that a
    newer one overtook before it was complete is handed back at once."""
    sub = node.pubsub("agp/grids", GradientGrid).subscriber_builder().create()
    sets: dict[int, list] = {}
    need: dict[int, int] = {}
    deadline = time.monotonic() + timeout_s
    size = ctypes.sizeof(GradientGrid)
    while True:
        while (s := sub.receive()) is not None:
            h = GradientGrid.from_address(s.payload_ptr).header
            if h.seq not in sets:
                # History delivers in publication order: an older set still incomplete
                # when a newer one starts never completes.
                for seq in [q for q in sets if q < h.seq and len(sets[q]) < need[q]]:
                    for old, _ in sets.pop(seq):
                        old.delete()
            sets.setdefault(h.seq, []).append((s, (ctypes.c_uint8 * size).from_address(s.payload_ptr)))
            need[h.seq] = h.alpha_count * GRIDS_PER_ALPHA
        complete = [seq for seq, grids in sets.items() if len(grids) >= need[seq]]
        if complete:
            newest = max(complete)
            for seq in [q for q in sets if q != newest]:
                for old, _ in sets.pop(seq):
                    old.delete()
            held = sets[newest]
            ag = Gradient.from_buffers(view for _, view in held)
            ag.hold((sub, [sample for sample, _ in held]))
            return ag
        if pipeline.stop_requested():
            raise Shutdown()
        if time.monotonic() > deadline:
            raise PipelineError(
                f"no complete set of gradient grids within {timeout_s:.0f} s: does the estimator serve "
                "an AG file (`--reuse` with results/<object>.ag, or `--load FILE`)?"
            )
        time.sleep(0.01)


def _run_push(planner: PushPlanner) -> int:
    instance, epoch, _token, serve = _environment()
    node = Node(instance, f"py-push-planner-{os.getpid()}")
    qos = {"history": 1, "buffer": 4}
    requests = node.pubsub("agp/push_requests", PushRequest, create=qos).subscriber_builder().create()
    choices = node.pubsub("agp/push_choices", PushChoice, create=qos).publisher_builder().create()
    args = [_planner_binary(), "--mode", "serve" if serve else "place", "--planner", "affordance", "--skills"]
    argv = sys.argv[1:]
    if "--goal" in argv[:-1]:  # X_MM,Y_MM,THETA_DEG instead of the scenario's, as agp-planner takes it
        args += ["--goal", argv[argv.index("--goal") + 1]]
    child = subprocess.Popen(args, env=os.environ.copy(), preexec_fn=_die_with_parent)
    try:
        ag = _read_gradient(node)
        _say(f"gradient with alphas {', '.join(f'{a:+.0f}' for a in ag.alphas_deg)} deg (grids seq {ag.seq})")
        answered, goal_key, goal = 0, None, None
        while True:
            code = child.poll()
            if code is not None:
                return code
            if pipeline.stop_requested():
                raise Shutdown()
            s = requests.receive()
            if s is None:
                time.sleep(0.0005)
                continue
            r = PushRequest.from_address(s.payload_ptr)
            if r.epoch != epoch or r.seq <= answered:
                del r
                s.delete()
                continue
            key = (r.goal_id, r.goal.x, r.goal.y, r.goal.theta)
            if key != goal_key:
                goal_key = key
                goal = Goal(r.goal_id, r.goal.x * 1e3, r.goal.y * 1e3, math.degrees(r.goal.theta), r.tolerance_m * 1e3, math.degrees(r.tolerance_rad))
                planner.on_goal(goal)
            push = planner.choose_push(PushObs(r, ag, goal))
            answered = r.seq
            del r
            s.delete()
            u = choices.loan_uninit()
            c = PushChoice.from_address(u.payload_ptr)
            ctypes.memset(ctypes.addressof(c), 0, ctypes.sizeof(PushChoice))
            c.seq, c.epoch = answered, epoch
            if push is None:
                c.kind = CHOICE_DONE
            else:
                c.kind = CHOICE_PUSH
                c.contact_deg, c.alpha_deg, c.length_mm = push.contact_deg, push.alpha_deg, push.length_mm
            del c
            u.assume_init().send()
    finally:
        if child.poll() is None:
            child.send_signal(signal.SIGTERM)
            try:
                child.wait(timeout=10)
            except subprocess.TimeoutExpired:
                child.kill()
                child.wait()
