"""Gymnasium environments over agp's pipeline: `agp/Place-v0` and `agp/Trajectory-v0`,
registered when `agp` is imported (with gymnasium installed)."""

from .pipeline_env import (
    HOLD_STEPS,
    MM_PER_DEG,
    AgpEnv,
    PlaceEnv,
    TrajectoryEnv,
    action_of,
    push_of,
    wheels_of,
)

__all__ = [
    "AgpEnv",
    "PlaceEnv",
    "TrajectoryEnv",
    "HOLD_STEPS",
    "MM_PER_DEG",
    "action_of",
    "push_of",
    "wheels_of",
    "register",
]


def register() -> None:
    """Registers `agp/Place-v0` and `agp/Trajectory-v0` with gymnasium (idempotent)."""
    import gymnasium

    for name, entry in (("agp/Place-v0", "agp.envs:PlaceEnv"), ("agp/Trajectory-v0", "agp.envs:TrajectoryEnv")):
        if name not in gymnasium.registry:
            gymnasium.register(id=name, entry_point=entry, nondeterministic=False)
