"""The planner's ports on an agp instance and the ring physics -> estimator -> planner, as
`processes/planner/src/ring.rs` and `libs/runtime/src/driver.rs` drive it, over the stock
`iceoryx2` package.

One command per frame, each frame acted on once the estimator's estimate of it is in
(matched by the frame's publish stamp) and was made after the estimator took in this
planner's last event (by the event's seq when the estimator's newest event is of this
planner's session, else by the clock). The frame and its estimate are read in place from
the loaned samples: `Ring.frame` and `Ring.estimate` are ctypes views of sample memory,
valid until the next `Ring.step`, which hands the samples back to iceoryx2.
"""

from __future__ import annotations

import ctypes
import os
import signal
import time
from typing import Callable

import iceoryx2 as iox2

from .payloads import (
    COMMAND_APPLIED,
    COMMAND_PUBLISHED,
    CONTROL_DRIVING,
    CONTROL_GOAL_DONE,
    CONTROL_READY,
    ESTIMATE_PUBLISHED,
    ESTIMATOR_RECEIVED,
    FRAME_PUBLISHED,
    PLANNER_RECEIVED,
    ActiveEpoch,
    ControlRequest,
    ControlResponse,
    Goal,
    IrFrame,
    LearnEvent,
    MotorCommand,
    ObjectEstimate,
)

U64 = (1 << 64) - 1


class Shutdown(Exception):
    """SIGTERM or SIGINT: `agp` stops the run, or a hot swap stops this planner."""


class PhysicsRestarted(Exception):
    """Physics restarted: a new world from the scenario's start."""


class PipelineError(RuntimeError):
    """The pipeline did not answer (a process missing, a port error)."""


_stop = False


def install_signal_handlers() -> None:
    """SIGTERM and SIGINT set a flag the waits look at (and raise `Shutdown`)."""

    def handler(_signum, _frame):
        global _stop
        _stop = True

    signal.signal(signal.SIGTERM, handler)
    signal.signal(signal.SIGINT, handler)


def stop_requested() -> bool:
    return _stop


def instance_config(name: str) -> "iox2.config.Config":
    """The iceoryx2 config of agp instance `name`, as libs/runtime/src/instance.rs builds it:
    prefix `agp_<name>.`, root `<base>/<name>/` (base /tmp/agp or $AGP_IOX2_ROOT),
    creation timeout 2 s."""
    base = os.environ.get("AGP_IOX2_ROOT", "/tmp/agp")
    cfg = iox2.config.default()
    cfg.global_cfg.prefix = iox2.FileName.new(f"agp_{name}.")
    cfg.global_cfg.root_path = iox2.Path.new(os.path.join(base, name) + "/")
    cfg.global_cfg.creation_timeout = iox2.Duration.from_secs(2)
    return cfg


def _retrying(what: str, make: Callable, timeout_s: float):
    """`make()` until the service exists (physics and the estimator create them as they
    start)."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            return make()
        except Exception as e:  # iceoryx2's open errors: the service is not there yet
            if _stop:
                raise Shutdown() from e
            if time.monotonic() > deadline:
                raise PipelineError(f"cannot open {what} within {timeout_s:.0f} s: {e!r}") from e
            time.sleep(0.02)


class Node:
    """An iceoryx2 node on the instance, and the services a planner opens."""

    def __init__(self, instance: str, name: str, timeout_s: float = 30.0):
        iox2.set_log_level_from_env_or(iox2.LogLevel.Fatal)
        self.timeout_s = timeout_s
        self.node = (
            iox2.NodeBuilder.new()
            .name(iox2.NodeName.new(name))
            .signal_handling_mode(iox2.SignalHandlingMode.Disabled)
            .config(instance_config(instance))
            .create(iox2.ServiceType.Ipc)
        )

    def _builder(self, name: str):
        return self.node.service_builder(iox2.ServiceName.new(name))

    def pubsub(self, name: str, t, create: dict | None = None):
        """Opens topic `name` of payload `t`; with `create` (its QoS: history, buffer), opens
        or creates it."""
        if create is None:
            return _retrying(name, lambda: self._builder(name).publish_subscribe(t).open(), self.timeout_s)
        return _retrying(
            name,
            lambda: self._builder(name)
            .publish_subscribe(t)
            .history_size(create.get("history", 0))
            .subscriber_max_buffer_size(create.get("buffer", 4))
            .max_publishers(4)
            .max_subscribers(4)
            .max_nodes(16)
            .open_or_create(),
            self.timeout_s,
        )

    def event(self, name: str):
        return _retrying(name, lambda: self._builder(name).event().open(), self.timeout_s)

    def control(self):
        return _retrying(
            "agp/control",
            lambda: self._builder("agp/control").request_response(ControlRequest, ControlResponse).open(),
            self.timeout_s,
        )


class Control:
    """The supervisor's control service (`agp/control`): Ready, Driving, GoalDone."""

    def __init__(self, node: Node):
        self.client = node.control().client_builder().create()

    def ask(self, fill: Callable[[ControlRequest], None], timeout_s: float = 30.0) -> ControlResponse:
        req = self.client.loan_uninit()
        r = ControlRequest.from_address(req.payload_ptr)
        ctypes.memset(ctypes.addressof(r), 0, ctypes.sizeof(ControlRequest))
        fill(r)
        del r
        pending = req.assume_init().send()
        deadline = time.monotonic() + timeout_s
        while True:
            resp = pending.receive()
            if resp is not None:
                out = ControlResponse()
                ctypes.memmove(ctypes.addressof(out), resp.payload_ptr, ctypes.sizeof(ControlResponse))
                resp.delete()
                pending.delete()
                return out
            if time.monotonic() > deadline:
                pending.delete()
                raise PipelineError(f"the supervisor did not answer within {timeout_s:.0f} s")
            time.sleep(0.001)

    def ready(self, epoch: int) -> ControlResponse:
        def fill(r):
            r.kind, r.epoch = CONTROL_READY, epoch

        return self.ask(fill)

    def driving(self, epoch: int, handover_ns: int) -> ControlResponse:
        def fill(r):
            r.kind, r.epoch, r.value_ns = CONTROL_DRIVING, epoch, max(handover_ns, 0)

        return self.ask(fill)

    def goal_done(self, goal_id: int, end: str, sim_time_s: float) -> ControlResponse:
        def fill(r):
            r.kind = CONTROL_GOAL_DONE
            r.goal.id = goal_id
            data = end.encode()[: len(r.name)]
            ctypes.memmove(ctypes.addressof(r.name), data, len(data))
            r.value_ns = int(max(sim_time_s, 0.0) * 1e9)

        return self.ask(fill)


def read_str(field) -> str:
    return bytes(field).split(b"\0", 1)[0].decode(errors="replace")


def spin_seconds(wait: str) -> float:
    """How long a wait polls before it blocks, by `AGP_PY_WAIT` (the Python planner's alone),
    else `AGP_WAIT`, as the Rust processes read it:
    `block` 0, `spin` and `yield` (always poll) 1 s slices, `spin-then-block:US` US
    microseconds, and the default (unset or unknown) 200 us."""
    if wait == "block":
        return 0.0
    if wait in ("spin", "yield"):
        return 1.0
    if wait.startswith("spin-then-block:"):
        try:
            return max(float(wait.split(":", 1)[1]), 0.0) * 1e-6
        except ValueError:
            pass
    return 200e-6


class Ring:
    """The ring for a wheel-level planner: `step(l, r)` sends the command answering the
    latest frame and returns once a later frame and its estimate are in."""

    def __init__(self, node: Node, epoch: int, token: int, buffer: int | None = None, wait: str | None = None):
        """`buffer`: how many frames and estimates the subscribers keep (the newest); None,
        the services' most. 1 suits a reader of the newest alone, as the Gymnasium
        environment with physics holding each command for several steps. `wait`: how the
        waits wait (`AGP_WAIT`'s values); None, `AGP_PY_WAIT`, else `AGP_WAIT`."""
        self.node, self.epoch, self.token = node, epoch, token
        self.timeout_s = node.timeout_s

        def subscriber(name, t):
            b = node.pubsub(name, t).subscriber_builder()
            return (b.buffer_size(buffer) if buffer else b).create()

        self.frames = subscriber("agp/ir_frames", IrFrame)
        self.estimates = subscriber("agp/estimates", ObjectEstimate)
        self.estimates_ev = node.event("agp/estimates.ev").listener_builder().create()
        self.commands = node.pubsub("agp/motor_commands", MotorCommand).publisher_builder().create()
        self.physics_inbox = node.event("agp/physics_inbox.ev").notifier_builder().create()
        self.events = node.pubsub("agp/learn_events", LearnEvent).publisher_builder().create()
        self.estimator_wake = node.event("agp/ir_frames.ev").notifier_builder().create()
        self.epochs = node.pubsub("agp/active_epoch", ActiveEpoch).subscriber_builder().create()
        # The samples held: the latest frame and the newest estimate, read in place.
        self._frame_s = None
        self._est_s = None
        self.frame: IrFrame = IrFrame()
        self.estimate: ObjectEstimate = ObjectEstimate()
        self._run_base = None  # trace_id - step of the physics run being driven
        self._estimator_start = 0
        self.restarted = False  # physics restarted since the last look
        self.received_ns = 0
        self.seq = 0  # this planner's events
        self.sent_ns = 0
        self.steps = 0
        if wait is None:
            wait = os.environ.get("AGP_PY_WAIT", os.environ.get("AGP_WAIT", ""))
        self.spin_s = spin_seconds(wait)
        # The command is built in a struct of this process's own (its epoch and token set
        # once, the stamps it does not set zero) and copied into each loaned sample whole.
        self._command = MotorCommand()
        self._command.epoch, self._command.token = epoch, token
        self._command_timing = self._command.timing
        self._command_stamps = self._command.timing.stamps_ns
        self._command_at = ctypes.addressof(self._command)
        self._command_size = ctypes.sizeof(MotorCommand)
        # The package's own loan and assume_init check the payload type (a fixed-size
        # struct here) through `typing` on every call: straight to the bindings' methods
        # when this version of iceoryx2 has them.
        self._loan = getattr(self.commands, "__loan_uninit", self.commands.loan_uninit)
        self._assume_init = getattr(iox2.SampleMutUninit, "__assume_init", iox2.SampleMutUninit.assume_init)
        self._wait(after_step=-1)

    # -- samples -------------------------------------------------------------------------------

    def _hold_frame(self, s) -> None:
        if self._frame_s is not None:
            self._frame_s.delete()
        self._frame_s = s
        self.frame = IrFrame.from_address(s.payload_ptr)

    def _hold_estimate(self, s) -> None:
        if self._est_s is not None:
            self._est_s.delete()
        self._est_s = s
        self.estimate = ObjectEstimate.from_address(s.payload_ptr)

    def close(self) -> None:
        """Hands every held sample back."""
        for s in (self._frame_s, self._est_s):
            if s is not None:
                s.delete()
        self._frame_s = self._est_s = None
        self.frame, self.estimate = IrFrame(), ObjectEstimate()

    def _drain(self) -> None:
        """Takes the estimates, then the frames, that arrived: the newest of each held, every
        other sample handed back at once. A frame of another physics run (its trace base
        changed) is a restarted physics."""
        est = self._est_s
        newest = self.estimate.timing.stamps_ns[FRAME_PUBLISHED] if est is not None else 0
        while (s := self.estimates.receive()) is not None:
            e = ObjectEstimate.from_address(s.payload_ptr)
            start, stamp = e.estimator_start_ns, e.timing.stamps_ns[FRAME_PUBLISHED]
            del e
            if start < self._estimator_start:
                s.delete()  # left in the queue by an estimator that died
                continue
            self._estimator_start = start
            if stamp > newest:
                newest = stamp
                self._hold_estimate(s)
            else:
                s.delete()
        while (s := self.frames.receive()) is not None:
            f = IrFrame.from_address(s.payload_ptr)
            base, step, reset = (f.timing.trace_id - f.step) & U64, f.step, f.reset_seq
            del f
            if self._run_base is not None and base != self._run_base:
                self._run_base = base
                self.restarted = True
                self._hold_frame(s)
            elif (
                self._frame_s is None
                or step > self.frame.step
                or self.restarted
                or (step == self.frame.step and reset != self.frame.reset_seq)  # a reset's frame
            ):
                self._run_base = base
                self._hold_frame(s)
            else:
                s.delete()

    def _took_in(self, e: ObjectEstimate) -> bool:
        by_clock = e.timing.stamps_ns[ESTIMATOR_RECEIVED] >= self.sent_ns
        if e.event_session == self.epoch + 1:
            return by_clock and e.event_seq >= self.seq
        return by_clock

    def _paired(self, after_step: int) -> bool:
        if self._frame_s is None or self._est_s is None:
            return False
        f, e = self.frame, self.estimate
        return (
            (f.step > after_step or self.restarted)
            and e.timing.stamps_ns[FRAME_PUBLISHED] == f.timing.stamps_ns[FRAME_PUBLISHED]
            and self._took_in(e)
        )

    def wait_reset(self, seq: int) -> None:
        """Until the frame of reset `seq` (physics publishes the same step again, the world
        as the reset put it) and its estimate are in."""
        self._wait(-1, reset_seq=seq)

    def _wait(self, after_step: int, reset_seq: int | None = None) -> None:
        """Until `_paired` (and, with `reset_seq`, the frame is of that reset): polls for up to `spin_s` (`AGP_WAIT`'s spin, as the Rust
        processes' default `spin-then-block:200`), then blocks on the estimates' event."""
        deadline = time.monotonic() + self.timeout_s
        wait = iox2.Duration.from_millis(20)
        spin_until = time.perf_counter() + self.spin_s
        while True:
            self._drain()
            if self._paired(after_step) and (reset_seq is None or self.frame.reset_seq == reset_seq):
                self.received_ns = time.monotonic_ns()
                return
            if self.spin_s > 0.0 and time.perf_counter() < spin_until:
                os.sched_yield()  # polls with yields, as the Rust waits do
                continue
            if _stop:
                raise Shutdown()
            if time.monotonic() > deadline:
                raise PipelineError(
                    f"no frame after step {after_step} with its estimate within {self.timeout_s:.0f} s: "
                    "are agp-physics and agp-estimator running on this instance?"
                )
            try:
                self.estimates_ev.timed_wait(wait)
            except Exception:  # ListenerWaitError.InterruptSignal: a signal came (SIGTERM)
                pass

    # -- acting --------------------------------------------------------------------------------

    def send(self, left_mps: float, right_mps: float) -> None:
        """Publishes the command answering the latest frame (no wait)."""
        f, e = self.frame, self.estimate
        c, stamps = self._command, self._command_stamps
        c.step, c.left_mps, c.right_mps = f.step, left_mps, right_mps
        # The frame's trace and stamps, the estimator's and this planner's, for `agp profile`.
        ft, es = f.timing, e.timing.stamps_ns
        self._command_timing.trace_id = ft.trace_id
        stamps[FRAME_PUBLISHED] = ft.stamps_ns[FRAME_PUBLISHED]
        stamps[ESTIMATOR_RECEIVED] = es[ESTIMATOR_RECEIVED]
        stamps[ESTIMATE_PUBLISHED] = es[ESTIMATE_PUBLISHED]
        stamps[PLANNER_RECEIVED] = self.received_ns
        stamps[COMMAND_PUBLISHED] = time.monotonic_ns()
        del ft, es
        u = self._loan()
        ctypes.memmove(u.payload_ptr, self._command_at, self._command_size)
        self._assume_init(u).send()
        self.physics_inbox.notify()
        self.steps += 1

    def step(self, left_mps: float, right_mps: float, steps: int = 1) -> None:
        """Sends wheel speeds (m/s) for the latest frame; returns once the next is in (with
        `steps` > 1, the frame `steps` later: physics started with `--hold-steps steps`
        holds each command that long). Raises `PhysicsRestarted` when the frame that came is
        a restarted physics's (it is then the latest, answered by the next step)."""
        self.send(left_mps, right_mps)
        self._wait(self.frame.step + steps - 1)
        if self.restarted:
            self.restarted = False
            raise PhysicsRestarted()

    def idle(self, period_s: float) -> None:
        """One step with the wheels stopped (between goals), paced `period_s` on the wall
        clock."""
        self.step(0.0, 0.0)
        if period_s > 0:
            time.sleep(period_s)

    def tell(self, kind: int, flag: int = 0, contact=(0.0, 0.0), alpha_deg: float = 0.0, scale: float = 1.0) -> None:
        """Tells the estimator an event about the latest frame (before the command answering it)."""
        f = self.frame
        u = self.events.loan_uninit()
        ev = LearnEvent.from_address(u.payload_ptr)
        ctypes.memset(ctypes.addressof(ev), 0, ctypes.sizeof(LearnEvent))
        self.seq += 1
        ev.seq, ev.session, ev.kind, ev.flag = self.seq, self.epoch + 1, kind, flag
        ev.step, ev.ir_sample, ev.ir_raw, ev.odometry = f.step, f.ir_sample, f.ir_raw, f.odometry
        ev.contact[0], ev.contact[1] = contact
        ev.alpha_deg, ev.scale = alpha_deg, scale
        del ev
        u.assume_init().send()
        self.estimator_wake.notify()
        self.sent_ns = time.monotonic_ns()

    # -- a hot swap ----------------------------------------------------------------------------

    def take_over(self, control: Control) -> None:
        """For a planner started by a hot swap (epoch > 0): tells the supervisor it is ready,
        waits until its epoch is the active one, takes the latest frame, answers it with the
        wheels stopped and reports the handover once that command was applied (as the Rust
        planner's `SwapIn`)."""
        ready_ns = time.monotonic_ns()
        control.ready(self.epoch)
        deadline = time.monotonic() + self.timeout_s
        while True:
            active = None
            while (s := self.epochs.receive()) is not None:
                active = ActiveEpoch.from_address(s.payload_ptr).epoch
                s.delete()
            if active == self.epoch:
                break
            if _stop:
                raise Shutdown()
            if time.monotonic() > deadline:
                raise PipelineError(f"epoch {self.epoch} did not become active within {self.timeout_s:.0f} s")
            time.sleep(50e-6)
        # The latest frame: the one physics waits to get this planner's command for.
        while (s := self.frames.receive()) is not None:
            f = IrFrame.from_address(s.payload_ptr)
            newer = f.step >= self.frame.step
            del f
            if newer:
                self._hold_frame(s)
            else:
                s.delete()
        self.received_ns = time.monotonic_ns()
        try:
            self.step(0.0, 0.0)
        except PhysicsRestarted:
            pass
        applied = self.frame.timing.stamps_ns[COMMAND_APPLIED]
        control.driving(self.epoch, applied - ready_ns)


def latest_goal(subscriber, latest: Goal) -> Goal:
    """The newest goal on the latched `agp/goal` topic (or `latest` if none came)."""
    while (s := subscriber.receive()) is not None:
        ctypes.memmove(ctypes.addressof(latest), s.payload_ptr, ctypes.sizeof(Goal))
        s.delete()
    return latest
