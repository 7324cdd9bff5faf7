"""System identification: material parameters from observed motion, with taichi_mpm alone."""

from taichi_mpm.sysid.fit import FitError, FitResult, FitSettings, fit
from taichi_mpm.sysid.identify import Identification, identify
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
    "FitSettings",
    "Identification",
    "Observation",
    "ObservationError",
    "fit",
    "identify",
    "load_observation",
    "observation_from_times",
    "save_observation",
]
