"""A third-party sga-agent task: find three hidden numbers.

A solution is a JSON list of numbers (``[1.0, 2.5, 3.0]``); its loss is the squared distance
to :data:`TARGET`. The task checks that format statically (``check_solution``), turns the text
into data in the sandbox (``capture``: here nothing needs to run) and scores the data without
trusting it (``evaluate``). It also offers an LLM-free proposer, so that
``sga-agent search --task numbers`` runs without a model. ``test_sga_numbers.py`` checks it
against the plugin contract.
"""

from __future__ import annotations

import json
import math
import random
from collections.abc import Sequence
from typing import Any

from sga_agent.task import (
    CodeRejected,
    Evaluation,
    EvaluationSettings,
    InvalidSolution,
    Parent,
    PromptParts,
    TaskBase,
)

TARGET = (1.0, 2.0, 3.0)


def parse_numbers(text: str) -> list[float]:
    """The finite numbers of the JSON list ``text``; ValueError (one sentence) otherwise."""
    try:
        values = json.loads(text)
    except json.JSONDecodeError:
        raise ValueError("the solution must be a JSON list of numbers, e.g. [1.0, 2.0]") from None
    finite = isinstance(values, list) and all(
        isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in values
    )
    if not finite or not values:
        raise ValueError("the solution must be a non-empty JSON list of finite numbers")
    return [float(v) for v in values]


class NumbersTask(TaskBase):
    """Find three numbers; the loss is the squared distance to a hidden target.

    ``TaskBase`` gives every optional hook its default; this task overrides two of them,
    ``check_solution`` and ``builtin_proposer``.
    """

    name = "numbers"
    description = "Find three hidden numbers (a third-party example task)."
    kind = "entity"  # a structure to find, not code with parameters to fit

    def seed_solution(self) -> str:
        return "[0, 0, 0]\n"

    def prompt_parts(self) -> PromptParts:
        return PromptParts(
            role="a careful guesser",
            context="Find three numbers; the loss is their squared distance to hidden ones.",
            template="[x, y, z]",
            requirements="Answer with a JSON list of three numbers in a code block.",
        )

    def check_solution(self, code: str) -> None:
        """Static check, before anything runs; the message is feedback for the model."""
        try:
            values = parse_numbers(code)
        except ValueError as error:
            raise CodeRejected(str(error)) from None
        if len(values) != len(TARGET):
            raise CodeRejected(f"give {len(TARGET)} numbers, not {len(values)}")

    def capture(self, solution: str) -> dict[str, Any]:
        """Untrusted side (the sandbox): the solution as inert JSON data."""
        try:
            return {"values": parse_numbers(solution)}
        except ValueError as error:
            raise InvalidSolution(str(error)) from None

    def evaluate(self, data: dict[str, Any], settings: EvaluationSettings) -> Evaluation:
        """Trusted side: check the captured data, never assume its shape, then score it."""
        values = data.get("values") if isinstance(data, dict) else None
        if not isinstance(values, list) or len(values) != len(TARGET):
            return Evaluation.invalid("the captured data is not three numbers")
        try:
            loss = sum((float(v) - t) ** 2 for v, t in zip(values, TARGET, strict=True))
        except (TypeError, ValueError):
            return Evaluation.invalid("the captured data is not three numbers")
        if not math.isfinite(loss):
            return Evaluation.invalid("the loss is not finite", status="unstable")
        return Evaluation(True, loss, f"squared distance {loss:g}")

    def builtin_proposer(self) -> Nudge:
        """The LLM-free proposer ``--model builtin`` (the default without a model) uses."""
        return Nudge()


class Nudge:
    """Moves a random parent's numbers by Gaussian steps, larger at a higher temperature."""

    name = "builtin:nudge"

    def propose_from(
        self, parents: Sequence[Parent], temperature: float, n: int, seed: int
    ) -> list[str]:
        rng = random.Random(seed)
        answers = []
        for _ in range(n):
            parent = parse_numbers(rng.choice(parents).code)
            child = [round(v + rng.gauss(0.0, temperature), 3) for v in parent]
            answers.append(f"```python\n{json.dumps(child)}\n```\n")
        return answers
