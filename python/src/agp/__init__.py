"""agp: your own planner for agp's pipeline, in Python.

- wheel level: subclass `Planner` (`on_goal`, `step(obs) -> Wheels | None`);
- push level: subclass `PushPlanner` (`on_goal`, `choose_push(obs) -> Push | None`);
- `run(planner)` runs either under `agp up`;
- `Gradient`: the affordance gradient as numpy arrays, `predict(contact_deg, alpha_deg)`;
- with gymnasium installed, `import agp` registers `agp/Place-v0` and `agp/Trajectory-v0`
  (`agp.envs`; policies in `agp.policies`).
"""

from .gradient import Gradient, Prediction
from .planner import Goal, Obs, Planner, Push, PushObs, PushPlanner, Wheels, run

__all__ = ["Gradient", "Goal", "Obs", "Planner", "Prediction", "Push", "PushObs", "PushPlanner", "Wheels", "run"]

try:  # the Gymnasium environments, when gymnasium is installed (`pip install ./python[gym]`)
    import gymnasium as _gymnasium  # noqa: F401
except ImportError:  # pragma: no cover
    pass
else:
    from .envs import register as _register

    _register()
