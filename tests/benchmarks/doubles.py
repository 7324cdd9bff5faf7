"""Cheap tasks for the benchmark-grid tests: a law's loss is its distance to a target number.

The code of a solution is a ``Physics`` law returning ``F * value``; the task's capture reads
``value`` from the text (nothing is run, nothing heavy is imported) and its evaluation scores
that number, so a sandboxed evaluation takes a fraction of a second. The built-in proposer
scales the best parent's value by random factors drawn from the seed, so different seeds give
different (reproducible) results.
"""

from __future__ import annotations

import math
import random
import re
from collections.abc import Sequence
from typing import Any

from sga_agent.task import Evaluation, EvaluationSettings, InvalidSolution, Parent, PromptParts

LAW = """import torch
import torch.nn as nn


class Physics(nn.Module):
    def forward(self, F: torch.Tensor) -> torch.Tensor:
        return F * {value!r}
"""
VALUE = re.compile(r"return F \* ([-\d.e+]+)")


def value_of(code: str) -> float:
    found = VALUE.search(code)
    if found is None:
        raise InvalidSolution("the law does not return F * <number>")
    return float(found.group(1))


class Nudge:
    """Built-in proposer: the best parent's value times factors in [0.2, 1.2)."""

    name = "builtin:nudge"

    def propose_from(
        self, parents: Sequence[Parent], temperature: float, n: int, seed: int
    ) -> list[str]:
        rng = random.Random(seed)
        best = value_of(parents[-1].code)  # best last
        values = [round(best * rng.uniform(0.2, 1.2), 6) for _ in range(n)]
        return [f"```python\n{LAW.format(value=value)}```" for value in values]


class NumberTask:
    """Find ``value`` close to ``target``; the loss is the distance."""

    name = "number"
    target = 1.0
    description = "Find the number; the loss is the distance to it (a test double)."
    kind = "equation"

    def seed_solution(self) -> str:
        return LAW.format(value=100.0)

    def prompt_parts(self) -> PromptParts:
        return PromptParts("a tester", "find the number", LAW, "one law")

    def builtin_proposer(self) -> Nudge:
        return Nudge()

    def capture(self, solution: str) -> dict[str, Any]:
        return {"value": value_of(solution)}

    def evaluate(self, data: dict[str, Any], settings: EvaluationSettings) -> Evaluation:
        value = data.get("value") if isinstance(data, dict) else None
        if not isinstance(value, float) or not math.isfinite(value):
            return Evaluation.invalid("the captured value is not a finite number")
        loss = abs(value - self.target)
        return Evaluation(True, loss, f"off by {loss}", parameters={})


class NumberTaskA(NumberTask):
    name = "number-a"
    target = 1.0


class NumberTaskB(NumberTask):
    name = "number-b"
    target = 3.0
