#!/usr/bin/env python3
"""A push-level planner: the paper's Algorithm 5, its choice of push, on the affordance
gradient. agp's own skills (`agp-planner --skills`, started by `agp.run`) travel to each
push, push and circle the object to estimate it again; this script only chooses.

For each push it searches every aim point (a ray from the centroid every 3 deg) x learned
alpha x push length (50, 25, 12.5 mm) for the push whose predicted pose is nearest the goal:
distance + 1 mm per degree of turn left + the prediction's spread.

    agp up examples/python-planner/launch.toml          # the scenario's goal
    agp up examples/python-planner/launch-live.toml     # --serve: the goals `agp goal` queues
"""

import math
import sys

import agp

LENGTHS_MM = (50.0, 25.0, 12.5)  # the learned push, a half, a quarter
LENGTH_OFFSET = 0.23  # a push moves the object a little more than its length says
MIN_CONFIDENCE = 0.5
MM_PER_DEG = 1.0
SPREAD_LEVER_MM = 30.0  # the turn's spread (rad) weighs as a displacement at this lever


def symmetric_deg(a, order):
    """Orientation error `a` (deg) wrapped by the object's rotational symmetry (0: a disc)."""
    if order == 0:
        return 0.0
    period = 360.0 / order
    return (a + 0.5 * period) % period - 0.5 * period


def starts_on_circle(aim, alpha_deg, radius_mm):
    """Whether a push at `alpha_deg` through aim point `aim` (mm) can start on the circle of
    `radius_mm` round the centroid (as `approach_start` asks)."""
    length = math.hypot(*aim)
    return radius_mm > length > 0.0 and abs(radius_mm * math.sin(math.radians(alpha_deg)) / length) <= 1.0


class AffordancePlanner(agp.PushPlanner):
    def __init__(self):
        self.options = None  # (contact_deg, alpha_deg, prediction, aim_mm), made once

    def on_goal(self, goal):
        print(f"push_planner.py: goal {goal.id}: ({goal.x_mm:.0f}, {goal.y_mm:.0f}) mm, {goal.theta_deg:.0f} deg", flush=True)

    def predictions(self, ag, radius_mm):
        """Every push the gradient predicts with confidence: they depend on it alone."""
        if self.options is None:
            self.options = []
            for k in range(120):
                contact = 3.0 * k
                aim = ag.aim_point(contact)
                if aim is None:
                    continue
                aim_mm = (aim[0] * 1e3, aim[1] * 1e3)
                for alpha in ag.alphas_deg:
                    p = ag.prediction(contact, alpha)
                    if p is not None and p.confidence >= MIN_CONFIDENCE and starts_on_circle(aim_mm, alpha, radius_mm):
                        self.options.append((contact, alpha, p))
        return self.options

    def choose_push(self, obs):
        x, y, th = obs.object
        gx, gy, gth = obs.target
        order = obs.symmetry_order
        c, s = math.cos(math.radians(th)), math.sin(math.radians(th))
        best, best_cost = None, math.inf
        lengths = LENGTHS_MM[:1] if obs.full_only else LENGTHS_MM
        for contact, alpha, p in self.predictions(obs.ag, obs.request.start_radius_m * 1e3):
            for length in lengths:
                k = (length / LENGTHS_MM[0] + LENGTH_OFFSET) / (1.0 + LENGTH_OFFSET)
                nx = x + k * (c * p.dx_mm - s * p.dy_mm)
                ny = y + k * (s * p.dx_mm + c * p.dy_mm)
                turn_left = abs(symmetric_deg(th + k * p.dtheta_deg - gth, order))
                cost = math.hypot(nx - gx, ny - gy) + MM_PER_DEG * turn_left
                cost += k * (p.spread_mm + SPREAD_LEVER_MM * math.radians(p.rotation_spread_deg))
                if cost < best_cost:
                    best, best_cost = agp.Push(contact, alpha, length), cost
        return best


if __name__ == "__main__":
    sys.exit(agp.run(AffordancePlanner()))
