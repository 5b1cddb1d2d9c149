"""agp: your own planner for agp's pipeline, in Python.

- wheel level: subclass `Planner` (`on_goal`, `step(obs) -> Wheels | None`);
- push level: subclass `PushPlanner` (`on_goal`, `choose_push(obs) -> Push | None`);
- `run(planner)` runs either under `agp up`;
- `Gradient`: the affordance gradient as numpy arrays, `predict(contact_deg, alpha_deg)`.
"""

from .gradient import Gradient, Prediction
from .planner import Goal, Obs, Planner, Push, PushObs, PushPlanner, Wheels, run

__all__ = ["Gradient", "Goal", "Obs", "Planner", "Prediction", "Push", "PushObs", "PushPlanner", "Wheels", "run"]
