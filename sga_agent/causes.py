"""Why a candidate failed, in one short line that groups alike failures.

A failed candidate's :class:`~sga_agent.task.Evaluation` carries a ``status`` ("invalid",
"error", "unstable", "timeout", "out_of_memory", "crashed") and a ``reason`` (one or a few
lines naming the cause, the line and the fix). :func:`cause_of` reduces them to a cause: the
status and the reason's first line, with line numbers and numbers dropped, so that the prompt's
failure section, the end screen and the report count the same cause once however many
candidates hit it. A candidate that repeated an earlier one has the cause :data:`REPEATED`.
"""

from __future__ import annotations

import re
from collections import Counter
from collections.abc import Iterable, Mapping
from typing import Any

#: The cause of an answer that repeated an earlier law (same code, or same form).
REPEATED = "repeated an earlier law"
#: Longest cause, in characters.
MAX_CAUSE_CHARS = 110
_LINE_PREFIX = re.compile(r"^line \d+: ")
_NUMBER = re.compile(r"(?<![\w.])[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?(?![\w.])", re.I)
_REJECTED = "the code was rejected before it ran: "


def cause_of(evaluation: Mapping[str, Any]) -> str:
    """The cause of a failed evaluation (a dict as ``Evaluation.to_dict`` or ``evaluation.json``
    holds it); "" for a valid one that repeats nothing."""
    extras = evaluation.get("extras") or {}
    if extras.get("duplicate_of") or extras.get("same_form_as"):
        return REPEATED
    if evaluation.get("valid"):
        return ""
    status = str(evaluation.get("status") or "invalid")
    reason = str(evaluation.get("reason") or evaluation.get("feedback") or "").strip()
    first = reason.removeprefix(_REJECTED).splitlines()[0] if reason else "no reason given"
    first = _LINE_PREFIX.sub("", first.strip())
    first = _NUMBER.sub("N", first)
    first = re.split(r"(?<=[.;])\s", first, maxsplit=1)[0].rstrip(" .;")
    label = "rejected" if reason.startswith(_REJECTED) else status.replace("_", " ")
    text = f"{label}: {first}"
    return text if len(text) <= MAX_CAUSE_CHARS else text[: MAX_CAUSE_CHARS - 1] + "…"


def top_causes(evaluations: Iterable[Mapping[str, Any]], count: int = 3) -> list[tuple[str, int]]:
    """The ``count`` most frequent causes among ``evaluations`` (most frequent first; ties in
    order of first appearance), valid ones left out."""
    counted = Counter(cause for cause in map(cause_of, evaluations) if cause)
    return counted.most_common(count)
