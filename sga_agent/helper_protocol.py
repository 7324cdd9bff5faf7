"""What the two helper processes of the sandbox share: their answer channel and error texts.

The capture server (:mod:`.capture_server`) and the fit worker (:mod:`.fit_worker`) each read
one JSON request per line of standard input and write one JSON answer per line on the
original standard output; whatever else prints goes to standard error.
"""

from __future__ import annotations

import json
import os
import traceback
from typing import IO, Any

from sga_agent.isolation import die_with_parent

#: Characters of an error message kept in a one-line reason.
MAX_MESSAGE_CHARS = 300


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
