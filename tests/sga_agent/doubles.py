"""Test doubles for the sandbox and the CLI: tasks that import nothing heavy.

:class:`ExecTask` executes the candidate's text (as a real task would run a proposed law) and
reports the names it defines (``loss``, ``parameters``, ``feedback`` and ``report``, any JSON
value), plus the worker's environment and working directory, so that the tests can see what the
sandbox did.
"""

from __future__ import annotations

import os
from dataclasses import asdict

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

    def evaluate(self, solution: str, settings: EvaluationSettings) -> Evaluation:
        namespace: dict = {}
        exec(solution, namespace)
        return Evaluation(
            valid=True,
            loss=float(namespace.get("loss", 0.0)),
            feedback=str(namespace.get("feedback", "ran")),
            parameters=dict(namespace.get("parameters", {})),
            extras={
                "environ": dict(os.environ),
                "cwd": os.getcwd(),
                "settings": asdict(settings),
                "report": namespace.get("report"),
            },
        )


def not_a_task() -> object:
    """A factory returning something that is not a Task."""
    return object()


def broken_task() -> ExecTask:
    """A factory that fails, as a plugin with a bug would."""
    raise RuntimeError("this plugin is broken")
