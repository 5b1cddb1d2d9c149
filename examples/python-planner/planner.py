#!/usr/bin/env python3
"""A planner for agp in Python, on the stock `iceoryx2` package (`pip install
iceoryx2==0.10.0`) and the standard library only.

It places the scenario's object at the scenario's goal, as `agp-planner --mode place` does,
with the paper's Algorithm 5 in its simplest honest form:

    approach the object; circle it           (the estimator matches the circled border to S)
    while the estimate is not within the tolerance of the goal:
        choose the push the gradient predicts best: contact point x learned alpha x length
        travel round the object to its start; approach; push; back off
        (the estimator carries the pose on by the announced push)
        circle again when the estimate's error bound calls for it

It perceives nothing itself: the robot's pose, the front gap, the object's pose and its
error bound are the estimator's (`agp/estimates`, one `ObjectEstimate` per frame). It reads
the affordance gradient from the estimator's grids (`agp/grids`), sends one motor command
per frame (`agp/motor_commands`, with the run's token) and tells the estimator what it does
(`agp/learn_events`: a circling begins and ends, a push begins with its plan and ends).

Start it with `agp up` from a launch file (see launch.toml): physics applies only commands
that carry the token the supervisor hands its planner in `AGP_TOKEN`.
"""

import ctypes
import math
import os
import signal
import sys
import time
import tomllib
from array import array
from pathlib import Path

import iceoryx2 as iox2

from agp_types import (
    COMMAND_PUBLISHED,
    ESTIMATE_PUBLISHED,
    ESTIMATOR_RECEIVED,
    FRAME_PUBLISHED,
    GRID_CELLS,
    GRID_DISPLACEMENT_SQ_MEAN,
    GRID_POSITION_X,
    GRID_POSITION_Y,
    GRID_PUSH_WEIGHT,
    GRID_ROTATION,
    GRID_ROTATION_SQ_MEAN,
    GRID_SHAPE,
    GRID_SIDE,
    GRIDS_PER_ALPHA,
    PLANNER_RECEIVED,
    TASK_CIRCLE_BEGIN,
    TASK_CIRCLE_END,
    TASK_KIND_PLACE,
    TASK_PUSH_BEGIN,
    TASK_PUSH_END,
    GradientGrid,
    GridHeader,
    IrFrame,
    LearnEvent,
    MotorCommand,
    ObjectEstimate,
    Task,
    instance_config,
)

REPO = Path(__file__).resolve().parents[2]
TAU = 2.0 * math.pi

# ---------------------------------------------------------------------------------------------
# What the planner knows: the robot (shared calibration data) and the task (the scenario's).


def wrap(a):
    """An angle wrapped to (-pi, pi]."""
    a = math.fmod(a + math.pi, TAU)
    if a <= 0.0:
        a += TAU
    return a - math.pi


def symmetric_error(a, order):
    """Orientation error `a` wrapped by the object's rotational symmetry (0: a disc)."""
    if order == 0:
        return 0.0
    period = TAU / order
    a = math.fmod(a, period)
    if a > 0.5 * period:
        a -= period
    elif a < -0.5 * period:
        a += period
    return a


class Robot:
    """The E-puck as `libs/world/data/epuck.toml` describes it (SI units)."""

    def __init__(self, path):
        with open(path, "rb") as f:
            d = tomllib.load(f)
        self.body_radius = d["body_radius_mm"] * 1e-3
        self.axle = d["axle_length_mm"] * 1e-3
        self.max_wheel = d["max_wheel_speed_mm_s"] * 1e-3
        self.ir_rate_hz = d["ir_rate_hz"]
        self.sensors = [
            (
                s["mount_mm"][0] * 1e-3,
                s["mount_mm"][1] * 1e-3,
                math.cos(math.radians(s["angle_deg"])),
                math.sin(math.radians(s["angle_deg"])),
            )
            for s in d["ir_sensors"]
        ]
        self.rows = [(r[0] * 1e-3, r[1], r[2]) for r in d["response"]["rows"]]
        self.max_range = self.rows[-1][0]
        # Where a reading places a border within 1 mm (one sigma): 40 mm for the E-puck
        # (agp_world::BORDER_MAX_SIGMA, ResponseCurve::usable_range).
        self.border_range = self._usable_range(1e-3)

    def distance(self, raw):
        """The distance (m) a raw reading implies, None when nothing is in range."""
        rows = self.rows
        if raw != raw or raw < rows[-1][1]:
            return None
        if raw >= rows[0][1]:
            return rows[0][0]
        for (d0, r0, _), (d1, r1, _) in zip(rows, rows[1:]):
            if raw >= r1:
                return d0 + (raw - r0) / (r1 - r0) * (d1 - d0)
        return None

    def _usable_range(self, max_sigma):
        rows, best = self.rows, 0.0
        for k in range(701):
            d = self.max_range * k / 700
            i = next((i for i in range(len(rows) - 1) if d <= rows[i + 1][0]), len(rows) - 2)
            (d0, r0, n0), (d1, r1, n1) = rows[i], rows[i + 1]
            t = (d - d0) / (d1 - d0)
            reading, frac = r0 + t * (r1 - r0), n0 + t * (n1 - n0)
            if frac * reading / abs((r1 - r0) / (d1 - d0)) > max_sigma:
                break
            best = d
        return best

    def ir_point(self, pose, sensor, raw, max_range):
        """Where sensor `sensor`'s ray meets something (world frame), None beyond `max_range`."""
        if raw <= 0.0:
            return None
        d = self.distance(raw)
        if d is None or d > max_range:
            return None
        mx, my, ux, uy = self.sensors[sensor]
        px, py = mx + d * ux, my + d * uy
        x, y, th = pose
        c, s = math.cos(th), math.sin(th)
        return (x + c * px - s * py, y + s * px + c * py)

    def wheels(self, v, omega):
        """Wheel speeds for body speed `v` and turn rate `omega`, both scaled down together
        when a wheel would pass its maximum."""
        h = 0.5 * self.axle
        l, r = v - omega * h, v + omega * h
        m = max(abs(l), abs(r))
        if m > self.max_wheel:
            k = self.max_wheel / m
            l, r = l * k, r * k
        return l, r


def scenario_task(scenario):
    """The place task of the scenario `AGP_SCENARIO` names (a built-in or a file): goal (m, rad),
    tolerance (m, rad), max pushes, seed."""
    path = Path(scenario)
    if not path.is_file():
        path = REPO / "libs" / "world" / "scenarios" / f"{scenario}.toml"
    with open(path, "rb") as f:
        t = tomllib.load(f)["task"]
    if t.get("kind", "place") != "place":
        raise SystemExit(f"planner.py: the scenario's task is `{t['kind']}`; this planner places only")
    g = t["goal"]
    return (
        (g["x_mm"] * 1e-3, g["y_mm"] * 1e-3, math.radians(g["theta_deg"])),
        t["tolerance"]["mm"] * 1e-3,
        math.radians(t["tolerance"]["deg"]),
        int(t.get("max_pushes", 150)),
        int(t.get("seed", 0)),
    )


# ---------------------------------------------------------------------------------------------
# The pipeline: one command per frame, each frame acted on once its estimate is in.


class Shutdown(Exception):
    """SIGTERM or SIGINT: `agp` stops the run."""


STOP = False


def _stop(_signum, _frame):
    global STOP
    STOP = True


def open_retrying(what, make, timeout_s=30.0):
    """`make()` until the service exists (physics and the estimator create them as they start)."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            return make()
        except Exception as e:  # iceoryx2's open errors: the service is not there yet
            if STOP:
                raise Shutdown() from e
            if time.monotonic() > deadline:
                raise SystemExit(f"planner.py: cannot open {what} within {timeout_s:.0f} s: {e!r}") from e
            time.sleep(0.05)


class Link:
    """The planner's ports on the instance, and the ring physics -> estimator -> planner.

    `step(l, r)` sends the command answering the latest frame and returns once it holds a
    later frame whose estimate is in and was made after the estimator read this planner's last
    event (in lockstep: the frame the command made; in realtime: the newest such frame)."""

    def __init__(self, instance, epoch, token, timeout_s=30.0):
        self.epoch, self.token, self.timeout_s = epoch, token, timeout_s
        self.node = (
            iox2.NodeBuilder.new()
            .name(iox2.NodeName.new("py-planner"))
            .signal_handling_mode(iox2.SignalHandlingMode.Disabled)
            .config(instance_config(instance))
            .create(iox2.ServiceType.Ipc)
        )

        def pubsub(name, t):
            return open_retrying(
                name,
                lambda: self.node.service_builder(iox2.ServiceName.new(name)).publish_subscribe(t).open(),
            )

        def event(name):
            return open_retrying(name, lambda: self.node.service_builder(iox2.ServiceName.new(name)).event().open())

        self.frames = pubsub("agp/ir_frames", IrFrame).subscriber_builder().create()
        self.estimates = pubsub("agp/estimates", ObjectEstimate).subscriber_builder().create()
        self.estimates_ev = event("agp/estimates.ev").listener_builder().create()
        self.commands = pubsub("agp/motor_commands", MotorCommand).publisher_builder().create()
        self.physics_inbox = event("agp/physics_inbox.ev").notifier_builder().create()
        self.events = pubsub("agp/learn_events", LearnEvent).publisher_builder().create()
        self.estimator_wake = event("agp/ir_frames.ev").notifier_builder().create()
        self.grids = pubsub("agp/grids", GradientGrid).subscriber_builder().create()
        self.task = pubsub("agp/task", Task).publisher_builder().create()
        self.frame = IrFrame()  # the latest frame acted on
        self.est = ObjectEstimate()  # the estimator's estimate of it
        self.received_ns = 0
        self._newest = ObjectEstimate()  # the newest estimate received
        self._recent = {}  # publish stamp -> frame, the frames received lately
        self.seq = 0
        self.sent_ns = 0  # when the last event went out
        self.steps = 0
        self._wait(-1)

    # -- the ring ------------------------------------------------------------------------------

    def _drain(self):
        """Takes every estimate, then every frame, that arrived; each read in place, the newest
        estimate and the recent frames copied out, every sample handed back at once."""
        while (s := self.estimates.receive()) is not None:
            e = ObjectEstimate.from_address(s.payload_ptr)
            if e.timing.stamps_ns[FRAME_PUBLISHED] > self._newest.timing.stamps_ns[FRAME_PUBLISHED]:
                ctypes.memmove(ctypes.addressof(self._newest), s.payload_ptr, ctypes.sizeof(ObjectEstimate))
            del e
            s.delete()
        while (s := self.frames.receive()) is not None:
            f = IrFrame()
            ctypes.memmove(ctypes.addressof(f), s.payload_ptr, ctypes.sizeof(IrFrame))
            s.delete()
            self._recent[f.timing.stamps_ns[FRAME_PUBLISHED]] = f
        if len(self._recent) > 32:
            for k in sorted(self._recent)[:-16]:
                del self._recent[k]

    def _took_in(self, e):
        """Whether the estimator made `e` after it took in this planner's last event. By the
        event's seq when the estimator's newest event is of this planner's session: exact even
        across `agp bridge`, where an event arrives a link's latency after it left. Otherwise
        (a planner swapped in sent since) by the clock: a frame the estimator received after
        the event went out, exact on one machine."""
        by_clock = e.timing.stamps_ns[ESTIMATOR_RECEIVED] >= self.sent_ns
        if e.event_session == self.epoch + 1:
            return by_clock and e.event_seq >= self.seq
        return by_clock

    def _wait(self, after_step):
        deadline = time.monotonic() + self.timeout_s
        while True:
            self._drain()
            e = self._newest
            f = self._recent.get(e.timing.stamps_ns[FRAME_PUBLISHED])
            if f is not None and f.step > after_step and self._took_in(e):
                self.received_ns = time.monotonic_ns()
                self.frame = f
                ctypes.memmove(ctypes.addressof(self.est), ctypes.addressof(e), ctypes.sizeof(ObjectEstimate))
                return
            if STOP:
                raise Shutdown()
            if time.monotonic() > deadline:
                raise SystemExit(
                    f"planner.py: no frame after step {after_step} with its estimate within "
                    f"{self.timeout_s:.0f} s: are agp-physics and agp-estimator running on this instance?"
                )
            self.estimates_ev.timed_wait(iox2.Duration.from_millis(20))

    def step(self, left, right):
        """Sends wheel speeds (m/s) for the latest frame; returns once the next is in."""
        f = self.frame
        u = self.commands.loan_uninit()
        c = MotorCommand.from_address(u.payload_ptr)
        ctypes.memset(ctypes.addressof(c), 0, ctypes.sizeof(MotorCommand))
        c.step, c.epoch, c.token = f.step, self.epoch, self.token
        c.left_mps, c.right_mps = left, right
        # The frame's trace and stamps, the estimator's, and this planner's: `agp profile`
        # times a Python planner's hops as it times any planner's.
        c.timing.trace_id = f.timing.trace_id
        c.timing.stamps_ns[FRAME_PUBLISHED] = f.timing.stamps_ns[FRAME_PUBLISHED]
        c.timing.stamps_ns[ESTIMATOR_RECEIVED] = self.est.timing.stamps_ns[ESTIMATOR_RECEIVED]
        c.timing.stamps_ns[ESTIMATE_PUBLISHED] = self.est.timing.stamps_ns[ESTIMATE_PUBLISHED]
        c.timing.stamps_ns[PLANNER_RECEIVED] = self.received_ns
        c.timing.stamps_ns[COMMAND_PUBLISHED] = time.monotonic_ns()
        del c
        u.assume_init().send()
        self.physics_inbox.notify()
        self.steps += 1
        self._wait(f.step)

    def tell(self, kind, flag=0, contact=(0.0, 0.0), alpha_deg=0.0, scale=1.0):
        """Tells the estimator an event about the latest frame (before the command answering it)."""
        f = self.frame
        u = self.events.loan_uninit()
        e = LearnEvent.from_address(u.payload_ptr)
        ctypes.memset(ctypes.addressof(e), 0, ctypes.sizeof(LearnEvent))
        self.seq += 1
        # A planner swapped in sends with a newer session than the one it replaces.
        e.seq, e.session, e.kind, e.flag = self.seq, self.epoch + 1, kind, flag
        e.step, e.ir_sample, e.ir_raw, e.odometry = f.step, f.ir_sample, f.ir_raw, f.odometry
        e.contact[0], e.contact[1] = contact
        e.alpha_deg, e.scale = alpha_deg, scale
        del e
        u.assume_init().send()
        self.estimator_wake.notify()
        self.sent_ns = time.monotonic_ns()

    def publish_task(self, goal, tol_m, tol_rad, max_pushes, seed):
        """The task under way, on the latched `agp/task` topic: what the judge scores."""
        u = self.task.loan_uninit()
        t = Task.from_address(u.payload_ptr)
        ctypes.memset(ctypes.addressof(t), 0, ctypes.sizeof(Task))
        t.kind = TASK_KIND_PLACE
        t.goal.x, t.goal.y, t.goal.theta = goal
        t.tolerance_m, t.tolerance_rad, t.max_pushes, t.seed = tol_m, tol_rad, max_pushes, seed
        del t
        u.assume_init().send()

    # -- what the estimator perceives ------------------------------------------------------------

    def now(self):
        return self.frame.sim_time_s

    def pose(self):
        r = self.est.robot
        return (r.x, r.y, r.theta)

    def front_gap(self):
        g = self.est.front_gap_m
        return g if g >= 0.0 else None


# ---------------------------------------------------------------------------------------------
# The affordance gradient, from the estimator's grids.

CELL_BYTES = 4 * GRID_CELLS
CELLS_OFFSET = ctypes.sizeof(GridHeader)
KEPT = (
    GRID_SHAPE,
    GRID_POSITION_X,
    GRID_POSITION_Y,
    GRID_PUSH_WEIGHT,
    GRID_ROTATION,
    GRID_DISPLACEMENT_SQ_MEAN,
    GRID_ROTATION_SQ_MEAN,
)


class Layer:
    """One learned alpha: the grids a prediction reads (weighted means and their weight)."""

    def __init__(self, alpha_deg, cell, ox, oy, shape_scale):
        self.alpha_deg, self.cell, self.ox, self.oy = alpha_deg, cell, ox, oy
        self.shape_scale = shape_scale
        self.g = {}

    def bilinear(self, x, y):
        """The cells and weights of a bilinear sample at (x, y), object frame (m)."""
        cx = (x - self.ox) / self.cell - 0.5
        cy = (y - self.oy) / self.cell - 0.5
        if not (-1.0 < cx < GRID_SIDE and -1.0 < cy < GRID_SIDE):
            return ()
        i0, j0 = math.floor(cx), math.floor(cy)
        fx, fy = cx - i0, cy - j0
        out = []
        for i, j, w in (
            (i0, j0, (1 - fx) * (1 - fy)),
            (i0 + 1, j0, fx * (1 - fy)),
            (i0, j0 + 1, (1 - fx) * fy),
            (i0 + 1, j0 + 1, fx * fy),
        ):
            if 0 <= i < GRID_SIDE and 0 <= j < GRID_SIDE and w > 0.0:
                out.append((j * GRID_SIDE + i, w))
        return out

    def predict(self, x, y):
        """What a push at this alpha with aim point (x, y) does, as
        `AffordanceGradient::predict` answers at a learned alpha: (dx, dy, rotation,
        confidence, displacement spread, rotation spread), None without evidence."""
        g = self.g
        weight, px, py, rot = g[GRID_PUSH_WEIGHT], g[GRID_POSITION_X], g[GRID_POSITION_Y], g[GRID_ROTATION]
        dsq, rsq = g[GRID_DISPLACEMENT_SQ_MEAN], g[GRID_ROTATION_SQ_MEAN]
        w = sx = sy = sr = sd = srr = 0.0
        # Bilinear over the weighted sums and the weights (mean * weight gives the sum back).
        for k, b in self.bilinear(x, y):
            bw = b * weight[k]
            w += bw
            sx += bw * px[k]
            sy += bw * py[k]
            sr += bw * rot[k]
            sd += bw * dsq[k]
            srr += bw * rsq[k]
        if w < 0.005:  # MIN_PREDICTION_EVIDENCE
            return None
        dx, dy, r = sx / w, sy / w, sr / w
        return (
            dx,
            dy,
            r,
            1.0 - math.exp(-w),
            math.sqrt(max(sd / w - dx * dx - dy * dy, 0.0)),
            math.sqrt(max(srr / w - r * r, 0.0)),
        )


def read_gradient(link, timeout_s=120.0):
    """The newest complete set of grids on `agp/grids`, as learned alphas (ascending)."""
    sets = {}  # seq -> {(alpha, kind): cells}, with the headers' geometry
    deadline = time.monotonic() + timeout_s
    said = False
    while True:
        while (s := link.grids.receive()) is not None:
            h = GridHeader.from_address(s.payload_ptr)
            seq, kind, alpha = h.seq, h.kind, h.alpha_deg
            entry = sets.setdefault(seq, {"count": 0, "alphas": {}, "need": h.alpha_count * GRIDS_PER_ALPHA})
            entry["count"] += 1
            layer = entry["alphas"].get(alpha)
            if layer is None:
                layer = Layer(alpha, h.cell_size_m, h.origin_x_m, h.origin_y_m, 0.0)
                entry["alphas"][alpha] = layer
            if kind == GRID_SHAPE:
                layer.shape_scale = h.shape_scale
            if kind in KEPT:
                # Read in place; the cells this planner keeps are copied out once.
                layer.g[kind] = array("f", ctypes.string_at(s.payload_ptr + CELLS_OFFSET, CELL_BYTES))
            del h
            s.delete()
        complete = [seq for seq, e in sets.items() if e["need"] and e["count"] >= e["need"]]
        if complete:
            layers = sets[max(complete)]["alphas"]
            return [layers[a] for a in sorted(layers)]
        if STOP:
            raise Shutdown()
        link._drain()
        if link._newest.learning == 1 and time.monotonic() > deadline - timeout_s + 1.0:
            # EstimatorLearning::Waiting: no AG file to serve, and this planner does not learn.
            raise SystemExit(
                "planner.py: the estimator has no gradients to serve and waits for a planner to "
                "learn them: learn results/<object>.ag first (the default `agp up` does), or give "
                "the estimator `--load FILE`"
            )
        if not said:
            print("planner.py: waiting for the estimator's gradient grids", flush=True)
            said = True
        if time.monotonic() > deadline:
            raise SystemExit(
                f"planner.py: no complete set of gradient grids within {timeout_s:.0f} s: does the "
                "estimator serve an AG file (`--reuse` with results/<object>.ag, or `--load FILE`)?"
            )
        time.sleep(0.01)


def combined_shape(layers):
    """S over every alpha, normalised to [0, 1] (`AffordanceGradient::combined_shape`)."""
    cells = [0.0] * GRID_CELLS
    for layer in layers:
        s, k = layer.g[GRID_SHAPE], layer.shape_scale
        for i in range(GRID_CELLS):
            cells[i] += s[i] * k
    peak = max(cells)
    return [c / peak for c in cells] if peak > 0 else cells


def contact_candidates(layers, shape, count=120, threshold=0.3):
    """Candidate aim points (object frame): on `count` rays from the centroid, walking in from
    the grid's edge, the centroid of the first band of S above `threshold`
    (`AffordanceGradient::contact_candidates`)."""
    ref = layers[0]

    def sample(x, y):
        return sum(shape[k] * w for k, w in ref.bilinear(x, y))

    step = 0.25 * ref.cell
    r_max = 0.5 * GRID_SIDE * ref.cell - ref.cell
    out = []
    for k in range(count):
        ux, uy = math.cos(TAU * k / count), math.sin(TAU * k / count)
        r = r_max
        s = sample(ux * r, uy * r)
        while r > 0.0 and s < threshold:
            r -= step
            s = sample(ux * r, uy * r)
        weight = moment = 0.0
        while r > 0.0 and s >= threshold:
            weight += s - threshold
            moment += (s - threshold) * r
            r -= step
            s = sample(ux * r, uy * r)
        if weight > 0.0:
            out.append((ux * moment / weight, uy * moment / weight))
    return out


def approach_start(cx, cy, alpha_deg, radius):
    """Where on the centroid-centred circle of `radius` a push at `alpha_deg` must start for its
    heading line to pass through aim point (cx, cy), and the heading (object frame);
    None if none does (`agp_affordance::approach_start`)."""
    length = math.hypot(cx, cy)
    if not radius > length > 0.0:
        return None
    alpha = math.radians(alpha_deg)
    q = radius * math.sin(alpha) / length
    if not -1.0 <= q <= 1.0:
        return None
    gamma = math.atan2(cy, cx)
    best = None
    for h in (gamma - math.asin(q), gamma - math.pi + math.asin(q)):
        ux, uy = math.cos(h), math.sin(h)
        cu = cx * ux + cy * uy
        t = cu + math.sqrt(cu * cu - length * length + radius * radius)
        sx, sy = cx - t * ux, cy - t * uy
        if t > 0.0 and -(ux * sx + uy * sy) > 0.0 and (best is None or t < best[0]):
            best = (t, sx, sy, math.atan2(uy, ux))
    return None if best is None else best[1:]


class PushChooser:
    """planBestPush: of every aim point x learned alpha x push length, the push whose predicted
    outcome is nearest the goal (`agp_planning::PushPlanner`, at the learned alphas only)."""

    FRACTIONS = (1.0, 0.5, 0.25)  # of the learned push (0.5 s at 100 mm/s)
    FRACTION_OFFSET = 0.23  # a push moves the object a little more than its length says
    MIN_CONFIDENCE = 0.5
    ORIENTATION_WEIGHT = 1e-3 * 180.0 / math.pi  # 1 mm per degree
    SPREAD_LEVER = 0.03

    def __init__(self, layers, contacts, start_radius, order):
        self.start_radius, self.order = start_radius, order
        # Every prediction depends on the gradient alone: made once, searched per push.
        self.options = []
        for cx, cy in contacts:
            for layer in layers:
                p = layer.predict(cx, cy)
                if p is None or p[3] < self.MIN_CONFIDENCE:
                    continue
                start = approach_start(cx, cy, layer.alpha_deg, start_radius)
                if start is not None:
                    self.options.append(((cx, cy), layer.alpha_deg, p, start))

    def plan(self, est, goal, full_only=False):
        ex, ey, et = est
        c, s = math.cos(et), math.sin(et)
        best = None
        for contact, alpha, p, (sx, sy, h) in self.options:
            dx, dy, rot, _, dspread, rspread = p
            for f in (1.0,) if full_only else self.FRACTIONS:
                scale = (f + self.FRACTION_OFFSET) / (1.0 + self.FRACTION_OFFSET)
                nx = ex + scale * (c * dx - s * dy)
                ny = ey + scale * (s * dx + c * dy)
                nt = et + scale * rot
                cost = (
                    math.hypot(nx - goal[0], ny - goal[1])
                    + self.ORIENTATION_WEIGHT * abs(symmetric_error(nt - goal[2], self.order))
                    + scale * (dspread + self.SPREAD_LEVER * rspread)
                )
                if best is None or cost < best[0]:
                    start = (ex + c * sx - s * sy, ey + s * sx + c * sy, wrap(h + et))
                    best = (cost, contact, alpha, f, scale, start)
        return best


# ---------------------------------------------------------------------------------------------
# Driving: the routines of libs/planning, simplified where the triangle allows.


class Circling:
    """TurnAroundObjCompShape (`agp_planning::CircleRoutine`, its core): turn in place to put the
    object on the left, then follow its contour once round, steering by the nearest point the
    IR has shown: that point's gap to the shell held at `GAP`, the heading along the tangent.
    Commands are computed once per IR sample. The estimator gathers the border it sees
    meanwhile; this routine only drives."""

    GAP, SPEED, MIN_GAP = 0.010, 0.06, 0.004
    GAP_GAIN, MAX_CORRECTION = 60.0, math.radians(50)
    HEADING_GAIN, MAX_TURN = 8.0, 3.0
    STOP_HEADING_ERROR, START_HEADING_ERROR = math.radians(70), math.radians(15)
    CLOSE_RADIUS, CLOSE_HEADING = 0.02, math.radians(20)
    TIMEOUT = 40.0
    KEEP = 3000  # points kept for steering: a few seconds of readings, enough round a convex object

    def __init__(self, robot, now):
        self.robot, self.started = robot, now
        self.points = []
        self.phase = "turn"
        self.outcome = None
        self.last_sample = None
        self.command = (0.0, 0.0)
        self.turned = 0.0
        self.last_theta = 0.0
        self.lap_start = (0.0, 0.0)
        self.closest = math.inf
        self.border_points = 0

    def update(self, now, ir_sample, pose, ir_raw):
        if self.outcome is not None:
            return (0.0, 0.0)
        if now - self.started > self.TIMEOUT:
            return self._finish("timeout")
        if self.last_sample == ir_sample:
            return self.command
        first = self.last_sample is None
        self.last_sample = ir_sample
        x, y, th = pose
        if not first and self.phase == "follow":
            self.turned += wrap(th - self.last_theta)
        self.last_theta = th
        for i in range(8):
            p = self.robot.ir_point(pose, i, ir_raw[i], self.robot.max_range)
            if p is not None:
                self.points.append(p)
                d = self.robot.distance(ir_raw[i])
                if d is not None and d <= self.robot.border_range:
                    self.border_points += 1
        if len(self.points) > 2 * self.KEEP:
            del self.points[: -self.KEEP]
        if not self.points:
            # Nothing seen yet: look round in place for a turn, then give up.
            if now - self.started > TAU / self.MAX_TURN:
                return self._finish("lost")
            return self._drive(0.0, -self.MAX_TURN)
        nx, ny = min(self.points, key=lambda p: (p[0] - x) ** 2 + (p[1] - y) ** 2)
        ax, ay = x - nx, y - ny
        rho = math.hypot(ax, ay)
        gap = rho - self.robot.body_radius
        if rho > 1e-9:
            normal = (ax / rho, ay / rho)
        else:
            normal = (math.cos(th - math.pi / 2), math.sin(th - math.pi / 2))
        # The tangent with the object on the left: the outward normal turned a quarter.
        tangent = math.atan2(normal[0], -normal[1])
        correction = max(-self.MAX_CORRECTION, min(self.MAX_CORRECTION, self.GAP_GAIN * (gap - self.GAP)))
        error = wrap(tangent + correction - th)
        omega = max(-self.MAX_TURN, min(self.MAX_TURN, self.HEADING_GAIN * error))
        if self.phase == "turn":
            if abs(error) < self.START_HEADING_ERROR:
                self.phase = "follow"
                self.lap_start, self.turned, self.closest = (x, y), 0.0, math.inf
            else:
                return self._drive(0.0, omega)
        if self.turned >= TAU - self.CLOSE_HEADING:
            # Close at the closest return to the lap's start.
            d = math.hypot(x - self.lap_start[0], y - self.lap_start[1])
            self.closest = min(self.closest, d)
            receding = d > self.closest + 0.0005
            if (receding and (self.closest <= self.CLOSE_RADIUS or self.turned >= TAU)) or self.turned >= TAU + math.pi / 2:
                return self._finish("closed")
        closing = math.cos(th) * normal[0] + math.sin(th) * normal[1] < 0.0
        if gap < self.MIN_GAP and closing:
            v = 0.0
        else:
            v = self.SPEED * max(0.0, min(1.0, 1.0 - abs(error) / self.STOP_HEADING_ERROR))
        return self._drive(v, omega)

    def _finish(self, outcome):
        self.outcome = outcome
        self.command = (0.0, 0.0)
        return self.command

    def _drive(self, v, omega):
        self.command = self.robot.wheels(v, omega)
        return self.command


class Driver:
    """The robot's moves over the link: approach, circle, travel, push, back off."""

    APPROACH_SPEED, PUSH_SPEED, STOP_GAP = 0.08, 0.1, 0.003
    PUSH_DURATION = 0.5  # the learned push's, s
    BACKOFF_S, BACKOFF_SPEED = 0.15, 0.08
    TRAVEL_SPEED, TRAVEL_TURN_IN_PLACE = 0.1, 0.3
    PASS_RADIUS, ARRIVE_RADIUS, HEADING_TOLERANCE = 0.006, 0.0015, 0.004
    ARC_STEP = 0.2

    def __init__(self, link, robot):
        self.link, self.robot = link, robot

    def approach_to_gap(self, gap, timeout):
        """Forward until the front gap is at most `gap`, or stops shrinking while the object is
        in sight (a corner met head-on slips between the front rays)."""
        link, t0 = self.link, self.link.now()
        gaps, last = [None] * 6, None
        while link.now() - t0 < timeout:
            g = link.front_gap()
            if g is not None and g <= gap:
                return True
            if last != link.frame.ir_sample:
                last = link.frame.ir_sample
                gaps = [g] + gaps[:5]
                expected = self.APPROACH_SPEED * 5.0 / self.robot.ir_rate_hz
                if gaps[0] is not None and gaps[5] is not None and gaps[5] - gaps[0] < 0.25 * expected:
                    return True
            link.step(self.APPROACH_SPEED, self.APPROACH_SPEED)
        return False

    def circle(self):
        """One circling, told to the estimator; whether it gave a usable border."""
        link = self.link
        routine = Circling(self.robot, link.now())
        link.tell(TASK_CIRCLE_BEGIN)
        while True:
            l, r = routine.update(link.now(), link.frame.ir_sample, link.pose(), link.frame.ir_raw)
            if routine.outcome is not None:
                usable = routine.outcome == "closed" or (
                    routine.outcome == "timeout" and routine.border_points >= 4 * 8
                )
                link.tell(TASK_CIRCLE_END, int(usable))
                link.step(0.0, 0.0)  # one frame for the estimator to match what it saw
                return usable
            link.step(l, r)

    def _turn_rate(self, e):
        return max(-3.0, min(3.0, 8.0 * e))

    def travel(self, waypoints, heading, timeout=30.0):
        """Through `waypoints` (world frame), then turn in place to `heading`."""
        link, t0, k = self.link, self.link.now(), 0
        while link.now() - t0 < timeout:
            x, y, th = link.pose()
            if k < len(waypoints):
                wx, wy = waypoints[k]
                last = k + 1 == len(waypoints)
                d = math.hypot(wx - x, wy - y)
                if d < (self.ARRIVE_RADIUS if last else self.PASS_RADIUS):
                    k += 1
                    continue
                e = wrap(math.atan2(wy - y, wx - x) - th)
                if abs(e) > self.TRAVEL_TURN_IN_PLACE:
                    link.step(*self.robot.wheels(0.0, self._turn_rate(e)))
                    continue
                v = (max(min(self.TRAVEL_SPEED, 4.0 * d), 0.01) if last else self.TRAVEL_SPEED) * math.cos(e)
                link.step(*self.robot.wheels(v, self._turn_rate(e)))
                continue
            e = wrap(heading - th)
            if abs(e) < self.HEADING_TOLERANCE:
                return True
            link.step(*self.robot.wheels(0.0, self._turn_rate(e)))
        return False

    def orbit_to(self, centre, radius, start):
        """Out to the circle of `radius` round `centre`, along it, and into `start` (x, y, heading)."""
        x, y, _ = self.link.pose()
        fx, fy = x - centre[0], y - centre[1]
        a0 = math.atan2(fy, fx) if math.hypot(fx, fy) > 1e-9 else math.atan2(start[1] - centre[1], start[0] - centre[0])
        turn = wrap(math.atan2(start[1] - centre[1], start[0] - centre[0]) - a0)
        n = math.ceil(abs(turn) / self.ARC_STEP)
        way = []
        if abs(math.hypot(fx, fy) - radius) > 1e-4:
            way.append((centre[0] + radius * math.cos(a0), centre[1] + radius * math.sin(a0)))
        for k in range(1, n):
            a = a0 + turn * k / n
            way.append((centre[0] + radius * math.cos(a), centre[1] + radius * math.sin(a)))
        way.append((start[0], start[1]))
        return self.travel(way, start[2])

    def face(self, point):
        x, y, _ = self.link.pose()
        return self.travel([], math.atan2(point[1] - y, point[0] - x), timeout=10.0)

    def push(self, duration, reach, stall_contact, plan):
        """Approach straight ahead until the front gap says contact, tell the estimator the push
        and its plan, push for `duration` s, let the object come to rest, tell the push's end.
        Whether the robot touched the object."""
        link, t0 = self.link, self.link.now()
        timeout = min(6.0, reach / self.APPROACH_SPEED)
        samples, last = 0, None
        while True:
            if last != link.frame.ir_sample:
                last = link.frame.ir_sample
                samples += 1
            g = link.front_gap()
            near = (g is not None and g <= self.STOP_GAP) or (stall_contact and link.est.stalled == 1 and samples > 5)
            if near:
                break
            if link.now() - t0 > timeout:
                return False
            link.step(self.APPROACH_SPEED, self.APPROACH_SPEED)
        contact, alpha_deg, scale = plan
        link.tell(TASK_PUSH_BEGIN, 1, contact, alpha_deg, scale)
        until = link.now() + duration
        while link.now() < until:
            link.step(self.PUSH_SPEED, self.PUSH_SPEED)
        rest = link.now()
        while link.now() - rest < 0.2:
            link.step(0.0, 0.0)
        link.tell(TASK_PUSH_END)
        return True

    def backoff(self):
        link, t0 = self.link, self.link.now()
        while link.now() - t0 < self.BACKOFF_S:
            link.step(-self.BACKOFF_SPEED, -self.BACKOFF_SPEED)


# ---------------------------------------------------------------------------------------------
# Algorithm 5.


class Episode:
    MAX_PUSHES_BETWEEN_ESTIMATES = 5
    REESTIMATE_FRACTION = 0.3
    ORIENTATION_MATTERS_WITHIN = 0.1
    STOP_MARGIN, STOP_MARGIN_RELAX = 0.7, 0.02
    MAX_FAILED_ESTIMATES = 3

    def __init__(self, link, robot, chooser, goal, tol_m, tol_rad, max_pushes, order):
        self.link, self.robot, self.chooser = link, robot, chooser
        self.drive = Driver(link, robot)
        self.goal, self.tol_m, self.tol_rad, self.max_pushes, self.order = goal, tol_m, tol_rad, max_pushes, order
        self.pushes = self.circlings = self.near_pushes = 0

    def say(self, text):
        print(f"planner.py [t={self.link.now():.1f}s push {self.pushes}] {text}", flush=True)

    def estimate(self, guess):
        """EstimateOrientationObj: face the guessed centre, approach to the circling's gap,
        circle once; the estimator's fresh pose, None if it found none."""
        self.circlings += 1
        timeout = 5.0
        if guess is not None:
            self.drive.face(guess[:2])
            x, y, _ = self.link.pose()
            timeout = min((math.hypot(guess[0] - x, guess[1] - y) + 0.05) / Driver.APPROACH_SPEED, timeout)
        if not self.drive.approach_to_gap(Circling.GAP + 0.002, timeout):
            self.say("the approach saw nothing")
            return None
        before = self.link.est.match_seq
        if not self.drive.circle():
            self.say("the circling failed")
            return None
        e = self.link.est
        if e.valid != 1 or e.match_seq == before:
            self.say("the estimator found no pose")
            return None
        self.say(
            f"circled: the object at ({e.pose.x * 1e3:.1f}, {e.pose.y * 1e3:.1f}) mm, "
            f"{math.degrees(e.pose.theta):.1f} deg (match rms {e.match_rms_m * 1e3:.1f} mm)"
        )
        return {"pose": (e.pose.x, e.pose.y, e.pose.theta), "err_m": 0.0, "err_rad": 0.0, "since": 0}

    def margin(self):
        return min(self.STOP_MARGIN + self.STOP_MARGIN_RELAX * self.near_pushes, 1.0)

    def distance(self, est):
        return math.hypot(est["pose"][0] - self.goal[0], est["pose"][1] - self.goal[1])

    def done(self, est):
        off = abs(symmetric_error(est["pose"][2] - self.goal[2], self.order))
        return self.distance(est) <= self.margin() * self.tol_m and off <= self.margin() * self.tol_rad

    def needs_estimate(self, est):
        if est["since"] >= self.MAX_PUSHES_BETWEEN_ESTIMATES or not math.isfinite(est["err_m"]):
            return True
        d = self.distance(est)
        if est["err_m"] > max(self.tol_m, self.REESTIMATE_FRACTION * d):
            return True
        if d < self.ORIENTATION_MATTERS_WITHIN:
            off = abs(symmetric_error(est["pose"][2] - self.goal[2], self.order))
            return est["err_rad"] > max(self.tol_rad, self.REESTIMATE_FRACTION * off)
        return False

    def run(self):
        est = self.estimate(None)  # the robot starts facing the object
        if est is None:
            return "lost", None
        failed = 0
        planned_from, push_longer = None, False
        while True:
            if est["since"] == 0 and planned_from is not None:
                # Pushes that left the object where it was (a short push stopping short of
                # it) are followed by a full one.
                moved = math.hypot(est["pose"][0] - planned_from[0], est["pose"][1] - planned_from[1])
                turned = abs(symmetric_error(est["pose"][2] - planned_from[2], self.order))
                push_longer = moved < 0.003 and turned < math.radians(3)
                planned_from = None
            if self.done(est):
                if est["since"] == 0:
                    return "done", est["pose"]
                fresh = self.estimate(est["pose"])
                if fresh is not None:
                    est, failed = fresh, 0
                    continue
                failed += 1
                if failed >= self.MAX_FAILED_ESTIMATES:
                    return "lost", est["pose"]
            if self.pushes >= self.max_pushes:
                return "max pushes", est["pose"]
            best = self.chooser.plan(est["pose"], self.goal, full_only=push_longer)
            if best is None:
                return "lost", est["pose"]
            _, contact, alpha, fraction, scale, start = best
            if est["since"] == 0:
                planned_from = est["pose"]
            if self.distance(est) <= 2.0 * self.tol_m:
                self.near_pushes += 1
            touched = False
            if self.drive.orbit_to(est["pose"][:2], self.chooser.start_radius, start):
                touched = self.drive.push(
                    fraction * Driver.PUSH_DURATION,
                    self.chooser.start_radius + 0.03,
                    not push_longer,
                    (contact, alpha, scale),
                )
                self.drive.backoff()  # the estimator carried its pose on by the push meanwhile
            push_longer = False
            if touched:
                self.pushes += 1
                e = self.link.est
                if e.valid == 1:
                    est = {
                        "pose": (e.pose.x, e.pose.y, e.pose.theta),
                        "err_m": e.sigma_xy,
                        "err_rad": e.sigma_theta,
                        "since": est["since"] + 1,
                    }
                else:
                    est = dict(est, err_m=math.inf, since=est["since"] + 1)
            else:
                self.say("no contact")
                est = dict(est, err_m=math.inf)
            if self.needs_estimate(est):
                fresh = self.estimate(est["pose"])
                if fresh is not None:
                    est, failed = fresh, 0
                else:
                    failed += 1
                    if failed >= self.MAX_FAILED_ESTIMATES:
                        return "lost", est["pose"]


def main():
    signal.signal(signal.SIGTERM, _stop)
    signal.signal(signal.SIGINT, _stop)
    iox2.set_log_level_from_env_or(iox2.LogLevel.Fatal)
    instance = os.environ.get("AGP_INSTANCE")
    if not instance:
        raise SystemExit("planner.py: AGP_INSTANCE is not set: start it with `agp up` from a launch file")
    epoch = int(os.environ.get("AGP_EPOCH", "0"))
    token = int(os.environ.get("AGP_TOKEN", "0"))
    if epoch != 0:
        raise SystemExit("planner.py: started for a hot swap (AGP_EPOCH > 0), which it does not speak")
    robot = Robot(REPO / "libs" / "world" / "data" / "epuck.toml")
    goal, tol_m, tol_rad, max_pushes, seed = scenario_task(os.environ.get("AGP_SCENARIO", "triangle"))
    wall = time.monotonic()
    try:
        link = Link(instance, epoch, token)
        layers = read_gradient(link)
        shape = combined_shape(layers)
        contacts = contact_candidates(layers, shape)
        if not contacts:
            raise SystemExit("planner.py: the gradient's shape has no border")
        order = link.est.symmetry_order
        if order == 255:
            order = 1
        start_radius = max(math.hypot(*c) for c in contacts) + robot.body_radius + 0.02
        chooser = PushChooser(layers, contacts, start_radius, order)
        print(
            f"planner.py: gradient with alphas {', '.join(f'{l.alpha_deg:+.0f}' for l in layers)} deg, "
            f"{len(contacts)} aim points, {len(chooser.options)} pushes to choose from, "
            f"symmetry order {order}, pushes start {start_radius * 1e3:.0f} mm from the centroid",
            flush=True,
        )
        link.publish_task(goal, tol_m, tol_rad, max_pushes, seed)
        print(
            f"planner.py: place at ({goal[0] * 1e3:.0f}, {goal[1] * 1e3:.0f}) mm, "
            f"{math.degrees(goal[2]):.0f} deg within {tol_m * 1e3:.0f} mm, {math.degrees(tol_rad):.0f} deg",
            flush=True,
        )
        start_s = link.now()
        episode = Episode(link, robot, chooser, goal, tol_m, tol_rad, max_pushes, order)
        end, pose = episode.run()
    except Shutdown:
        return 0
    where = (
        ""
        if pose is None
        else f"; the object estimated at ({pose[0] * 1e3:.1f}, {pose[1] * 1e3:.1f}) mm, {math.degrees(pose[2]):.1f} deg"
    )
    print(
        f"planner.py: {end} after {episode.pushes} pushes and {episode.circlings} circlings, "
        f"{link.now() - start_s:.1f} s simulated, {link.steps} steps, {time.monotonic() - wall:.1f} s wall{where}",
        flush=True,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
