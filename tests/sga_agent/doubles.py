"""Test doubles for the sandbox and the CLI: tasks that import nothing heavy.

:class:`ExecTask` executes the candidate's text (as a real task would run a proposed law) and
reports the names it defines (``loss``, ``parameters``, ``feedback`` and ``report``, any JSON
value), plus the worker's environment and working directory, so that the tests can see what the
sandbox did.
"""

from __future__ import annotations

import os
from dataclasses import asdict
from typing import Any

from sga_agent.task import Evaluation, EvaluationSettings, PromptParts


class ExecTask:
    """Runs the solution; ``loss`` and ``parameters`` are read from the names it defines."""

    name = "exec-double"
    description = "Executes the candidate and reports what it defined (a test double)."
    kind = "equation"

    def seed_solution(self) -> str:
        return "loss = 1.0\nparameters = {'E': 2.0}\n"

    def prompt_parts(self) -> PromptParts:
        return PromptParts(role="tester", context="", template="", requirements="")

    def capture(self, solution: str) -> dict[str, Any]:
        namespace: dict = {}
        exec(solution, namespace)
        return {
            "loss": float(namespace.get("loss", 0.0)),
            "feedback": str(namespace.get("feedback", "ran")),
            "parameters": dict(namespace.get("parameters", {})),
            "report": namespace.get("report"),
            "environ": dict(os.environ),
            "uid": os.getuid(),
            "pid": os.getpid(),
        }

    def evaluate(self, data: dict[str, Any], settings: EvaluationSettings) -> Evaluation:
        return Evaluation(
            valid=True,
            loss=data["loss"],
            feedback=data["feedback"],
            parameters=data["parameters"],
            extras={
                "environ": data["environ"],
                "uid": data["uid"],
                "pid": data["pid"],
                "settings": asdict(settings),
                "report": data["report"],
            },
        )


def not_a_task() -> object:
    """A factory returning something that is not a Task."""
    return object()


def broken_task() -> ExecTask:
    """A factory that fails, as a plugin with a bug would."""
    raise RuntimeError("this plugin is broken")
