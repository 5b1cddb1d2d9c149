#!/usr/bin/env python3
"""A wheel-level planner: every physics frame, wheel speeds from the estimator's estimate.

It nudges the object: it drives straight at what is ahead until the front gap closes to
3 mm, pushes for `PUSH_S` seconds, backs off, and says the goal is done. A planner of your
own replaces `step` (the estimate of the frame, the IR frame and the simulated time are in
`obs`, read in place from shared memory).

    agp up examples/python-planner/launch-wheels.toml

`AGP_BENCH_STEPS=N` (the benchmark, tools/python-bench.sh) instead alternates the wheels
for N frames and then says done.
"""

import os
import sys

import agp

APPROACH_MM_S, PUSH_MM_S, BACKOFF_MM_S = 80.0, 100.0, 80.0
CONTACT_GAP_MM = 3.0
PUSH_S, BACKOFF_S, GIVE_UP_S = 0.5, 0.15, 10.0


class Nudge(agp.Planner):
    def on_goal(self, goal):
        self.phase, self.since = "approach", None

    def step(self, obs):
        if self.since is None:
            self.since = obs.t
        elapsed = obs.t - self.since
        if self.phase == "approach":
            gap = obs.front_gap_mm
            if (gap is not None and gap <= CONTACT_GAP_MM) or elapsed > GIVE_UP_S:
                self.phase, self.since = "push", obs.t
            return agp.Wheels(APPROACH_MM_S, APPROACH_MM_S)
        if self.phase == "push":
            if elapsed >= PUSH_S:
                self.phase, self.since = "back off", obs.t
            return agp.Wheels(PUSH_MM_S, PUSH_MM_S)
        if elapsed >= BACKOFF_S:
            return None  # done: agp.run reports the goal's end
        return agp.Wheels(-BACKOFF_MM_S, -BACKOFF_MM_S)


class Bench(agp.Planner):
    """The benchmark's planner: N frames answered, the wheels alternating."""

    def __init__(self, steps):
        self.steps = steps

    def on_goal(self, goal):
        self.left = self.steps

    def step(self, obs):
        self.left -= 1
        if self.left < 0:
            return None
        return agp.Wheels(20.0, -20.0) if self.left & 1 else agp.Wheels(-20.0, 20.0)


if __name__ == "__main__":
    bench = int(os.environ.get("AGP_BENCH_STEPS", "0"))
    sys.exit(agp.run(Bench(bench) if bench else Nudge()))
