"""A third party's task, as an outside package would write it: nothing here is known to sga_agent.

A solution is a JSON list of numbers (``[1.0, 2.5, 3.0]``), not a torch module; the loss is its
squared distance to :data:`TARGET`. ``check_solution`` checks that format statically,
``capture`` turns the text into data (the solution holds no code to run) and ``evaluate``
scores the data without trusting it.
"""

from __future__ import annotations

import json
import math
from typing import Any

from sga_agent.task import (
    CodeRejected,
    Evaluation,
    EvaluationSettings,
    InvalidSolution,
    PromptParts,
)

TARGET = (1.0, 2.0, 3.0)


def _numbers(text: str) -> list[float]:
    """The list of finite numbers ``text`` holds; ValueError (one sentence) if it holds none."""
    try:
        values = json.loads(text)
    except json.JSONDecodeError:
        raise ValueError("the solution must be a JSON list of numbers, e.g. [1.0, 2.0]") from None
    finite = all(
        isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
        for v in values
    ) if isinstance(values, list) else False  # fmt: skip
    if not finite or not values:
        raise ValueError("the solution must be a non-empty JSON list of finite numbers")
    return [float(v) for v in values]


class NumbersTask:
    """Find three numbers; the loss is the squared distance to a hidden target."""

    name = "numbers"
    description = "Find three hidden numbers (a third-party test task)."
    kind = "entity"

    def seed_solution(self) -> str:
        return "[0, 0, 0]\n"

    def prompt_parts(self) -> PromptParts:
        return PromptParts("a guesser", "find three numbers", "[x, y, z]", "a JSON list")

    def check_solution(self, code: str) -> None:
        try:
            values = _numbers(code)
        except ValueError as error:
            raise CodeRejected(str(error)) from None
        if len(values) != len(TARGET):
            raise CodeRejected(f"give {len(TARGET)} numbers, not {len(values)}")

    def capture(self, solution: str) -> dict[str, Any]:
        try:
            return {"values": _numbers(solution)}
        except ValueError as error:
            raise InvalidSolution(str(error)) from None

    def evaluate(self, data: dict[str, Any], settings: EvaluationSettings) -> Evaluation:
        values = data.get("values") if isinstance(data, dict) else None
        if not isinstance(values, list) or len(values) != len(TARGET):
            return Evaluation.invalid("the captured data is not three numbers")
        try:
            loss = sum((float(v) - t) ** 2 for v, t in zip(values, TARGET, strict=True))
        except (TypeError, ValueError):
            return Evaluation.invalid("the captured data is not three numbers")
        if not math.isfinite(loss):
            return Evaluation.invalid("the loss is not finite", status="unstable")
        return Evaluation(True, loss, f"squared distance {loss:g}", parameters={})
