"""Unconstrained coordinates for material parameters.

The optimizer works on u in R^n; each parameter maps u to a physical value that always
stays in its range: E = exp(u) (log E), nu = 0.49 sigmoid(u), the yield stress exp(u),
the friction angle 90 sigmoid(u) degrees, cohesion and mixture weights softplus(u).
A step in u is a relative change of E or of the yield stress, which makes one learning
rate fit parameters of very different magnitudes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Transform:
    """value = forward(u); derivative(u) = d value / d u; inverse(value) = u."""

    name: str
    low: float
    high: float

    def forward(self, u: float) -> float:
        if self.name == "log":
            return float(np.exp(u))
        if self.name == "sigmoid":
            return float(self.low + (self.high - self.low) / (1.0 + np.exp(-u)))
        return float(np.logaddexp(0.0, u))  # softplus

    def derivative(self, u: float) -> float:
        if self.name == "log":
            return float(np.exp(u))
        if self.name == "sigmoid":
            s = 1.0 / (1.0 + np.exp(-u))
            return float((self.high - self.low) * s * (1.0 - s))
        return float(1.0 / (1.0 + np.exp(-u)))

    def contains(self, value: float) -> bool:
        """Whether value lies strictly inside the range (where inverse exists)."""
        return self.low < value < self.high

    def inverse(self, value: float) -> float:
        if not self.contains(value):
            raise ValueError(f"{value} is outside ({self.low}, {self.high})")
        if self.name == "log":
            return float(np.log(value))
        if self.name == "sigmoid":
            t = (value - self.low) / (self.high - self.low)
            return float(np.log(t / (1.0 - t)))
        return float(value + np.log(-np.expm1(-value)))  # inverse softplus


TRANSFORMS = {
    "E": Transform("log", 0.0, np.inf),
    "nu": Transform("sigmoid", 0.0, 0.49),
    "yield_stress": Transform("log", 0.0, np.inf),
    "friction_angle": Transform("sigmoid", 0.0, 90.0),
    "cohesion": Transform("softplus", 0.0, np.inf),
    "weight_identity": Transform("softplus", 0.0, np.inf),
    "weight_von_mises": Transform("softplus", 0.0, np.inf),
    "weight_sand": Transform("softplus", 0.0, np.inf),
    "weight_fluid": Transform("softplus", 0.0, np.inf),
}


def to_unconstrained(values: dict[str, float]) -> np.ndarray:
    return np.array([TRANSFORMS[name].inverse(value) for name, value in values.items()])


def to_values(names: list[str], u: np.ndarray) -> dict[str, float]:
    return {name: TRANSFORMS[name].forward(x) for name, x in zip(names, u, strict=True)}


def chain(names: list[str], u: np.ndarray, value_grads: dict[str, float]) -> np.ndarray:
    """dL/du from dL/dvalue."""
    return np.array(
        [
            value_grads[name] * TRANSFORMS[name].derivative(x)
            for name, x in zip(names, u, strict=True)
        ]
    )
