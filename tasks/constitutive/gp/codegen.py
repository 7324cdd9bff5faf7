"""Genome to law code, and back: the code carries its genome as a one-line comment.

The generated module follows the task's template: ``Physics(nn.Module)`` with one
``nn.Parameter`` per parameter leaf (named for its transform, its default the leaf's raw value)
and ``forward(self, F)`` in straight-line code, one variable per operation with its shape in a
comment. Shared quantities (the SVD, the Hencky strain, J) are computed once at the top, and
identical parameter-free subtrees once.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import replace

from tasks.constitutive.gp import grammar
from tasks.constitutive.gp.genome import (
    Expr,
    Genome,
    GenomeError,
    Param,
    from_json,
    params,
    to_json,
    with_param,
)
from tasks.constitutive.gp.grammar import MATRIX, SHAPES

GENOME_TAG = "# genome: "
_GENOME_LINE = re.compile("^" + re.escape(GENOME_TAG) + r"(.+)$", re.M)
_RESULT = {
    "elastic": "Kirchhoff stress tau = P F^T from the deformation gradient",
    "plastic": "Corrected deformation gradient from the trial deformation gradient",
}


class _Forward:
    """Collects the parameters and the lines of ``forward`` while walking a genome."""

    def __init__(self) -> None:
        self.params: list[tuple[str, Param, str]] = []  # name, leaf, meaning
        self.lines: list[str] = []
        self.needs: set[str] = set()
        self.helpers: set[str] = set()
        self.names: dict[tuple[Expr, str], str] = {}

    def param(self, leaf: Param, role: str = "k", meaning: str = "") -> str:
        transform = grammar.TRANSFORMS[leaf.transform]
        name = f"{transform.prefix}{role}{len(self.params)}"
        self.params.append((name, leaf, meaning or transform.meaning))
        return transform.template.format(name)

    def value(self, expr: Expr, value_type: str) -> str:
        """Code of ``expr``'s value: a parameter, a shared quantity or a new variable."""
        if isinstance(expr, Param):
            return self.param(expr)
        key = (expr, value_type)
        if key in self.names:
            return self.names[key]
        op = grammar.OPS[value_type][expr.op]
        self.needs.update(op.needs)
        self.helpers.update(op.helpers)
        if op.terminal:
            return op.template
        args = [self.value(child, arg) for child, arg in zip(expr.children, op.args, strict=True)]
        name = f"{value_type.lower()}{len(self.lines)}"
        self.lines.append(f"{name} = {op.template.format(*args)}  # {SHAPES[value_type]}")
        if not _has_param(expr):
            self.names[key] = name
        return name

    def prelude(self) -> list[str]:
        """Lines of the shared quantities needed, their own needs included, in a fixed order."""
        needed = set(self.needs)
        for name in reversed(grammar.PRELUDE):
            if name in needed:
                needed.update(grammar.PRELUDE[name][1])
        return [line for name, (line, _) in grammar.PRELUDE.items() if name in needed]

    def helper_functions(self) -> list[str]:
        """Source lines of the helper functions the operations call, in definition order."""
        used = [name for name in grammar.HELPERS if name in self.helpers]
        lines = []
        for name in used:
            lines += ["", "", *grammar.HELPERS[name].strip().split("\n")]
        return lines


_COEFFICIENT_MEANINGS = {
    "log": "natural log of a modulus in Pa",
    "sigmoid": "logit of the weight of a correction",
    "unit": "weight of a correction, at most 1 (1: it replaces F)",
}


def _has_param(expr: Expr) -> bool:
    return isinstance(expr, Param) or any(_has_param(child) for child in expr.children)


def _walk(genome: Genome) -> tuple[_Forward, list[tuple[str, str]]]:
    """The body of ``forward`` and each term's (coefficient, value) code."""
    body = _Forward()
    coefficients = []
    for term in genome.terms:
        meaning = _COEFFICIENT_MEANINGS[term.coefficient.transform]
        coefficient = body.param(term.coefficient, grammar.TERM_NAME[genome.kind], meaning)
        coefficients.append((coefficient, body.value(term.expr, MATRIX)))
    return body, coefficients


def parameter_names(genome: Genome) -> list[str]:
    """Names of the law's parameters, in the order of :func:`genome.params`."""
    return [name for name, _, _ in _walk(genome)[0].params]


def with_values(genome: Genome, values: Mapping[str, float]) -> Genome:
    """``genome`` with the raw values of the parameters named in ``values`` replaced (the fitted
    values of an evaluated law, say); names it does not have and non-finite values are ignored."""
    for (index, path, param), name in zip(params(genome), parameter_names(genome), strict=True):
        value = values.get(name)
        if value is None or not math.isfinite(value):
            continue
        genome = with_param(genome, index, path, replace(param, raw=round(float(value), 4)))
    return genome


def law_code(genome: Genome) -> str:
    """Python source of the ``Physics`` module of ``genome``, the genome in a comment."""
    body, coefficients = _walk(genome)
    if genome.kind == "elastic":
        total = " + ".join(f"{c} * {value}" for c, value in coefficients)
        result = [
            f"stress = {total}  # (B, 3, 3)",
            "return 0.5 * (stress + stress.transpose(-2, -1))  # Kirchhoff stress (B, 3, 3)",
        ]
    elif coefficients:
        total = " + ".join(f"{c} * ({value} - F)" for c, value in coefficients)
        result = [f"return F + {total}  # (B, 3, 3)"]
    else:
        result = ["return F  # no plastic correction (B, 3, 3)"]
    forward = [*body.prelude(), *body.lines, *result]
    return "\n".join(
        [
            "import torch",
            "import torch.nn as nn",
            "",
            GENOME_TAG + to_json(genome),
            *body.helper_functions(),
            "",
            "",
            "class Physics(nn.Module):",
            *_init(body.params),
            "",
            "    def forward(self, F: torch.Tensor) -> torch.Tensor:",
            f'        """{_RESULT[genome.kind]}, (B, 3, 3)."""',
            *("        " + line for line in forward),
            "",
        ]
    )


def _init(params: list[tuple[str, Param, str]]) -> list[str]:
    if not params:
        signature = ["    def __init__(self):"]
    else:
        arguments = [f"        {name}: float = {leaf.raw!r}," for name, leaf, _ in params]
        signature = ["    def __init__(", "        self,", *arguments, "    ):"]
    docs = [f"            {name} (float): {meaning}." for name, _, meaning in params]
    doc = [
        '        """A law found by genetic programming over typed tensor blocks.',
        *(["", "        Args:", *docs] if docs else []),
        '        """',
    ]
    assignments = [
        f"        self.{name} = nn.Parameter(torch.tensor({name}))" for name, _, _ in params
    ]
    return [*signature, *doc, "        super().__init__()", *assignments]


def genome_from_code(code: str, kind: str) -> Genome | None:
    """The genome in ``code``'s genome comment; None when there is none, it is malformed or it
    is of another kind (the seed law, code written by a model)."""
    match = _GENOME_LINE.search(code)
    if match is None:
        return None
    try:
        genome = from_json(match.group(1))
    except GenomeError:
        return None
    return genome if genome.kind == kind else None
