"""The options of the constitutive-law tasks (``--option KEY=VALUE``); plain data."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal


@dataclass(frozen=True)
class ConstitutiveOptions:
    """``steps``: steps of the scene (a shorter one for quick checks; default the task's 1000).
    ``optimizer``: the inner optimizer (default the task's: Adam, L-BFGS for ``imaginary``).
    ``precision``: Taichi's floating-point type (default: the running Taichi's, else float32);
    it must match a Taichi already running in the process."""

    steps: int | None = None
    optimizer: Literal["adam", "lbfgs"] | None = None
    precision: Literal["float32", "float64"] | None = None

    def __post_init__(self) -> None:
        if self.steps is not None and self.steps < 1:
            raise ValueError(f"option 'steps' must be at least 1, got {self.steps}")
