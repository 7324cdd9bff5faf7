"""The units of what a law's parameters stand for, for people to read (the constitutive
tasks' :meth:`~sga_agent.task.TaskBase.parameter_units`).

The task's scenes are in SI units, so a modulus, a stress or a pressure is in Pa and a
viscosity in Pa s, whatever the law calls it (an observation file's units are its own: no unit
then). An angle's unit is the law's: degrees when its code converts degrees to radians
(``* math.pi / 180``, ``torch.deg2rad``, ``math.radians``), as the ground truth's friction angle
does, else radians (``torch.sin`` of it takes radians). Names that say nothing certain
(``mu``: a shear modulus or a friction coefficient) get no unit. The code is read, never run.
"""

from __future__ import annotations

import ast
import math
import re
from collections.abc import Sequence

from sga_agent.task import CodeRejected
from sga_agent.task.code import parse_python

#: Words of a natural name (``bulk_modulus``, ``yield_stress``) that make it a quantity in Pa.
PASCAL = frozenset({"modulus", "youngs", "stress", "pressure"})
#: Natural names that are a quantity in Pa by themselves (Young's modulus).
PASCAL_NAMES = frozenset({"E"})
#: Words of a natural name that make it a viscosity (Pa s).
VISCOSITY = frozenset({"viscosity"})
#: Words of a natural name that make it an angle.
ANGLE = frozenset({"angle"})
#: Functions that turn degrees into radians.
_TO_RADIANS = frozenset({"deg2rad", "radians"})


def parameter_units(solution: str, names: Sequence[str], si: bool = True) -> dict[str, str]:
    """The unit of each of ``names`` (natural names: ``friction_angle``) that its words make
    certain, in the law ``solution``; only an angle's when the scene's units are not ``si``
    (an observation file's own)."""
    units = {}
    for name in names:
        words = _words(name)
        if si and (name in PASCAL_NAMES or words & PASCAL):
            units[name] = "Pa"
        elif si and words & VISCOSITY:
            units[name] = "Pa s"
        elif words & ANGLE:
            units[name] = "deg" if converts_degrees(solution) else "rad"
    return units


def _words(name: str) -> set[str]:
    """``log_modulus0[2]``'s natural name ``modulus0[2]`` -> {"modulus"}."""
    return {word.rstrip("0123456789") for word in re.sub(r"\[.*?\]", "", name).lower().split("_")}


def converts_degrees(solution: str) -> bool:
    """Whether the law's code turns degrees into radians: a product or quotient with 180 or
    with pi/180 written out, or ``deg2rad``/``radians`` called (False for code that does not
    parse)."""
    try:
        tree = parse_python(solution)
    except CodeRejected:
        return False
    for node in ast.walk(tree):
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Mult | ast.Div):
            if any(_is_degree_constant(side) for side in (node.left, node.right)):
                return True
        elif isinstance(node, ast.Call):
            called = node.func
            name = called.attr if isinstance(called, ast.Attribute) else getattr(called, "id", "")
            if name in _TO_RADIANS:
                return True
    return False


def _is_degree_constant(node: ast.expr) -> bool:
    if not isinstance(node, ast.Constant) or isinstance(node.value, bool):
        return False
    if not isinstance(node.value, int | float):
        return False
    return node.value == 180 or math.isclose(node.value, math.pi / 180, rel_tol=1e-3)
