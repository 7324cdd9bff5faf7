"""Fitted parameters in natural units, for people to read.

A parameter is often fitted as the logarithm of what it stands for (a modulus of 1e6 Pa as
``log_youngs_modulus`` = 13.8, so that the fit takes steps of order one). The rule is the name:
a parameter ``log_X`` stands for ``X = exp(value)``. The task names the unit of ``X`` where it
knows it (:meth:`sga_agent.task.TaskBase.parameter_units`: the friction angle in degrees when
the law converts it from degrees, a modulus in Pa); ``X`` is shown without one otherwise.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from sga_agent.task import Task, as_task

#: A parameter named with this prefix is the natural logarithm of what it stands for.
LOG_PREFIX = "log_"
_LARGEST_LOG = math.log(1e300)  # exp of more is not worth showing (or overflows)


@dataclass(frozen=True)
class NaturalValue:
    """What a fitted parameter stands for: ``name`` (``friction_angle``), its value, its unit."""

    parameter: str
    name: str
    value: float
    unit: str = ""

    def __str__(self) -> str:
        """``friction angle 25 deg``."""
        text = f"{self.name.replace('_', ' ')} {self.value:.4g}"
        return f"{text} {self.unit}" if self.unit else text


def natural_name(parameter: str) -> str | None:
    """The name of what ``parameter`` stands for (``log_E`` -> ``E``); None when it is not
    named as a logarithm."""
    name = parameter.removeprefix(LOG_PREFIX)
    return name if name != parameter and name else None


def natural_values(
    parameters: Mapping[str, float], units: Mapping[str, str] | None = None
) -> dict[str, NaturalValue]:
    """By parameter, what each one named ``log_X`` stands for: ``X = exp(value)`` with its unit
    from ``units`` (by natural name). Parameters named otherwise, and values whose exp is not a
    finite number, are left out."""
    units = units or {}
    found = {}
    for parameter, value in parameters.items():
        name = natural_name(parameter)
        if name is None or not math.isfinite(value) or value > _LARGEST_LOG:
            continue
        found[parameter] = NaturalValue(parameter, name, math.exp(value), units.get(name, ""))
    return found


def natural_values_of(
    task: Task | None, solution: str, parameters: Mapping[str, float]
) -> dict[str, NaturalValue]:
    """:func:`natural_values` with the units ``task`` gives for ``solution`` (none without a
    task, or when its hook fails: a unit is a courtesy, never a reason to fail)."""
    names = [name for name in map(natural_name, parameters) if name is not None]
    if not names:
        return {}
    units: Mapping[str, str] = {}
    if task is not None:
        try:
            given = as_task(task).parameter_units(solution, names)
            units = {name: unit for name, unit in given.items() if isinstance(unit, str)}
        except Exception:  # a plugin's hook may fail in any way; the values stand without units
            units = {}
    return natural_values(parameters, units)
