"""The record of a law simulated on its own (no teacher forcing), for summaries and reports.

Light (no torch, no Taichi): the report side reads it without loading the simulator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any


@dataclass
class FreeRun:
    """A solution simulated from the initial state without teacher forcing, against the
    observation: the root-mean-square position error at the last step and averaged over the
    steps, in units of the body's size (``body_size``, m); infinite when the simulation blew up
    (``unstable`` says where). ``frames`` are steps at which ``positions`` and ``observed``
    ((frames, N, 3) arrays, for pictures; not part of :meth:`to_dict`) were kept. ``scene``
    names where it ran ("training scene", "held-out scene")."""

    final_error: float
    mean_error: float
    body_size: float
    steps: int
    frames: list[int] = field(default_factory=list)
    positions: Any = None
    observed: Any = None
    unstable: str = ""
    scene: str = "training scene"

    def to_dict(self) -> dict[str, Any]:
        """The numbers, JSON-ready (an infinite error as the string "inf")."""
        return {
            "final_error": _encode(self.final_error), "mean_error": _encode(self.mean_error),
            "body_size": self.body_size, "steps": self.steps, "unstable": self.unstable,
            "scene": self.scene,
        }  # fmt: skip


def _encode(value: float) -> float | str:
    return value if math.isfinite(value) else str(value)
