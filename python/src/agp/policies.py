"""Policies for `agp/Place-v0` and `agp/Trajectory-v0` at the push level.

- `AffordancePolicy(env)`: the baseline, the paper's Algorithm 5's choice on the AG
  (`env.unwrapped.ag`): of every aim point (a ray from the centroid every 3 deg) x learned
  alpha x push length (50, 25, 12.5 mm), the push whose predicted pose is nearest the goal
  (distance + 1 mm per degree of turn left + the prediction's spread), as
  examples/python-planner/push_planner.py chooses.
- `RandomPolicy(env)`: a push drawn at random from the action space (seeded).

Each is called with the observation (and optionally the step's info) and returns an action
of the environment's action space.
"""

from __future__ import annotations

import math

import numpy as np

from .envs.pipeline_env import action_of, _wrap_deg
from .planner import Push

LENGTHS_MM = (50.0, 25.0, 12.5)  # the learned push, a half, a quarter
LENGTH_OFFSET = 0.23  # a push moves the object a little more than its length says
MIN_CONFIDENCE = 0.5
MM_PER_DEG = 1.0
SPREAD_LEVER_MM = 30.0  # the turn's spread (rad) weighs as a displacement at this lever


def _starts_on_circle(aim, alpha_deg: float, radius_mm: float) -> bool:
    length = math.hypot(*aim)
    return radius_mm > length > 0.0 and abs(radius_mm * math.sin(math.radians(alpha_deg)) / length) <= 1.0


class RandomPolicy:
    """A random push (or wheel speeds): the action space's own sampling, seeded."""

    def __init__(self, env, seed: int | None = None):
        self.space = env.action_space
        self.space.seed(seed)

    def __call__(self, obs, info=None) -> np.ndarray:
        return self.space.sample()


class AffordancePolicy:
    """The AG's best push toward the observation's goal (push level only)."""

    def __init__(self, env):
        self.env = env.unwrapped
        if self.env.control != "push":
            raise ValueError("AffordancePolicy chooses pushes: make the environment with control='push'")
        self.options = None

    def _predictions(self):
        """Every push the gradient predicts with confidence (they depend on it alone)."""
        if self.options is None:
            ag, radius = self.env.ag, self.env.start_radius_mm
            self.options = []
            for k in range(120):
                contact = 3.0 * k
                aim = ag.aim_point(contact)
                if aim is None:
                    continue
                aim_mm = (aim[0] * 1e3, aim[1] * 1e3)
                for alpha in ag.alphas_deg:
                    p = ag.prediction(contact, alpha)
                    if p is not None and p.confidence >= MIN_CONFIDENCE and _starts_on_circle(aim_mm, alpha, radius):
                        self.options.append((contact, alpha, p))
        return self.options

    def choose(self, obs) -> Push:
        """The push, in the object's frame: the goal is `obs["goal"]` (object frame)."""
        gx, gy, gth = (float(v) for v in obs["goal"])
        order = self.env.symmetry_order if self.env.symmetry_order is not None else 1
        turn = self.env.task == "place"
        best, best_cost = None, math.inf
        lengths = LENGTHS_MM[:1] if getattr(self.env, "full_only", False) else LENGTHS_MM
        for contact, alpha, p in self._predictions():
            for length in lengths:
                k = (length / LENGTHS_MM[0] + LENGTH_OFFSET) / (1.0 + LENGTH_OFFSET)
                cost = math.hypot(k * p.dx_mm - gx, k * p.dy_mm - gy)
                if turn:
                    cost += MM_PER_DEG * abs(_wrap_deg(k * p.dtheta_deg - gth, order))
                cost += k * (p.spread_mm + SPREAD_LEVER_MM * math.radians(p.rotation_spread_deg))
                if cost < best_cost:
                    best, best_cost = Push(contact, alpha, length), cost
        if best is None:
            raise RuntimeError("the AG predicts no push with confidence")
        return best

    def __call__(self, obs, info=None) -> np.ndarray:
        return action_of(self.choose(obs))
