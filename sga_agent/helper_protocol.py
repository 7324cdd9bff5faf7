"""What the two helper processes of the sandbox share: their answer channel and error texts,
and the form evaluation settings take to reach a fit worker.

The capture server (:mod:`.capture_server`) and the fit worker (:mod:`.fit_worker`) each read
one JSON request per line of standard input and write one JSON answer per line on the
original standard output; whatever else prints goes to standard error. Before an answer a fit
worker may write progress notes, lines ``{"progress": {"stage": ..., "epoch": ..., "epochs":
..., "loss": ...}}`` (:class:`~sga_agent.task.FitProgress`): a line with the key
:data:`NOTE` is never an answer; the reader shows it if it is well-formed and drops it
otherwise, so a note can only inform, never change a result.
"""

from __future__ import annotations

import json
import os
import traceback
from dataclasses import dataclass
from typing import IO, Any

from sga_agent.isolation import die_with_parent
from sga_agent.options import options_json
from sga_agent.task import EvaluationSettings, FitProgress

#: Characters of an error message kept in a one-line reason.
MAX_MESSAGE_CHARS = 600
#: The key of a progress note's line (see the module docstring).
NOTE = "progress"


@dataclass(frozen=True)
class FitSettings:
    """:class:`~sga_agent.task.EvaluationSettings` on their way to a fit worker: the task
    options as their JSON text, the one serialisation of them (a fit worker is started for one
    task and options, on its command line, and builds the options object back once), and the
    rest, which each request carries."""

    epochs: int | None
    learning_rate: float | None
    seed: int
    options: str
    fidelity: float = 1.0

    @classmethod
    def of(cls, settings: EvaluationSettings) -> FitSettings:
        """``settings`` ready to send; ``TypeError`` if their options cannot be (not a
        dataclass, or holding a value JSON cannot write). No options: the task's defaults."""
        options = "{}" if settings.options is None else options_json(settings.options)
        return cls(settings.epochs, settings.learning_rate, settings.seed, options,
                   settings.fidelity)  # fmt: skip

    def request(self) -> dict[str, Any]:
        """The settings each request carries: all but the options."""
        return {"epochs": self.epochs, "learning_rate": self.learning_rate, "seed": self.seed,
                "fidelity": self.fidelity}  # fmt: skip


def start_helper() -> IO[str]:
    """Tie this process's life to its parent's; the stream answers go to.

    Standard output is moved aside for the answers and replaced by standard error, so that
    prints of a task or a library never corrupt an answer.
    """
    die_with_parent()  # a helper never outlives the evaluator that started it
    answers = os.fdopen(os.dup(1), "w", encoding="utf-8")
    os.dup2(2, 1)
    return answers


def answer(answers: IO[str], reply: dict[str, Any]) -> None:
    """Write one answer line and flush it."""
    answers.write(json.dumps(reply) + "\n")
    answers.flush()


def note_of(reply: dict[str, Any]) -> FitProgress | None:
    """The progress note a line read from a helper holds, checked (None: malformed, dropped);
    call it only for a line that is a note (``NOTE in reply``)."""
    return FitProgress.from_dict(reply.get(NOTE))


def first_line(text: str) -> str:
    """The first line of ``text``, at most :data:`MAX_MESSAGE_CHARS` long."""
    lines = text.strip().splitlines()
    return lines[0][:MAX_MESSAGE_CHARS] if lines else ""


def describe(error: BaseException, tail_chars: int) -> tuple[str, str]:
    """``"Type: first line"`` of ``error``, and the last whole lines of its traceback."""
    traceback.clear_frames(error.__traceback__)  # free memory before formatting
    message = first_line(str(error))
    described = f"{type(error).__name__}: {message}" if message else type(error).__name__
    formatted = "".join(traceback.format_exception(error))
    if len(formatted) > tail_chars:  # keep whole lines from the end
        formatted = formatted[-tail_chars:].partition("\n")[2]
    return described, formatted
