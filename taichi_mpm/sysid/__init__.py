"""System identification: material parameters from observed motion, with taichi_mpm alone."""

from taichi_mpm.sysid.fit import FitError, FitResult, fit
from taichi_mpm.sysid.observation import (
    Observation,
    ObservationError,
    load_observation,
    observation_from_times,
    save_observation,
)

__all__ = [
    "FitError",
    "FitResult",
    "Observation",
    "ObservationError",
    "fit",
    "load_observation",
    "observation_from_times",
    "save_observation",
]
