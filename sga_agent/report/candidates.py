"""The report's table of every candidate: where it came from, how it ended, what its answer
planned, with the answer's analysis, plan and reasoning folded into its row."""

from __future__ import annotations

import math
import os
import re
from pathlib import Path

from sga_agent.report.data import Candidate, Run
from sga_agent.report.render import Fold, FoldedTable, Section, Text

HEADER = ["candidate", "iteration", "temperature", "status", "cause", "loss", "fitted", "plan",
          "parents"]  # fmt: skip
#: The column a multi-fidelity search's table adds after the loss: the screen and its promotion.
SCREEN_COLUMN = "screen"
#: The answer's texts folded into each row: its :class:`~.data.Answer` field and its file in the
#: candidate's folder.
TEXTS = (("analysis", "analysis.md"), ("plan", "plan.md"), ("reasoning", "reasoning.md"))
#: Fitted values shown in a row; more are cut with "…".
SHOWN_VALUES = 4
#: Longest first line of a plan shown in a row, in characters.
PLAN_CHARS = 100
_MARKUP = re.compile(r"^\s*(?:#+\s*|[-*+]\s+|\d+[.)]\s+)*")
_STARTS_ITEM = re.compile(r"^\s*(?:#+\s|[-*+]\s|\d+[.)]\s)")  # a heading or a list item
_PLAN_TITLES = {"plan", "step-by-step plan"}


def number(value: object) -> str:
    """A fitted value in a few characters: ``1.2e5``, ``0.31``, ``-3``."""
    if not isinstance(value, int | float):
        return str(value)
    text = f"{value:.3g}"
    return re.sub(r"e([-+])0*(\d)", lambda m: "e" + m[1].replace("+", "") + m[2], text)


def fitted(parameters: dict[str, float]) -> str:
    """``name=value`` pairs, the first :data:`SHOWN_VALUES` of them."""
    pairs = [f"{name}={number(value)}" for name, value in parameters.items()]
    return ", ".join(pairs[:SHOWN_VALUES]) + (", …" if len(pairs) > SHOWN_VALUES else "")


def first_line(plan: str) -> str:
    """The plan's first heading, item or paragraph that says something (its wrapped lines
    joined, its Markdown markers dropped), cut at a word to :data:`PLAN_CHARS` characters."""
    words: list[str] = []
    for line in plan.splitlines():
        if words and (not line.strip() or _STARTS_ITEM.match(line)):
            break
        text = _MARKUP.sub("", line).replace("**", "").replace("`", "").strip()
        if words or text.rstrip(":").lower() not in _PLAN_TITLES:
            words += text.split()
        if words and line.lstrip().startswith("#"):
            break  # a heading is a line of its own
    text = " ".join(words)
    if len(text) <= PLAN_CHARS:
        return text
    cut = text[: PLAN_CHARS - 1]
    return (cut.rsplit(" ", 1)[0] if " " in cut else cut) + "…"


def status(candidate: Candidate) -> str:
    """The status, marked when it is a screen's, and how the answer ended when not plainly."""
    text = f"{candidate.status} (screen)" if candidate.screen_only else candidate.status
    reason = candidate.answer.finish_reason if candidate.answer else ""
    return text if reason in ("", "stop") else f"{text}, finish: {reason}"


def cause(candidate: Candidate) -> str:
    """Why it failed; a repeat names the candidate it repeats."""
    earlier = candidate.extras.get("duplicate_of") or candidate.extras.get("same_form_as")
    return f"{candidate.cause} ({earlier})" if candidate.cause and earlier else candidate.cause


def screen(candidate: Candidate) -> str:
    """Its screen's loss and outcome and whether it was promoted to a full fit:
    ``"0.031 ok, promoted"``, ``"unstable, not promoted"``; "" when it was not screened."""
    if candidate.screen is None:
        return ""
    loss = candidate.screen.loss
    text = f"{loss:.4g} " if math.isfinite(loss) else ""
    promoted = "promoted" if candidate.promoted else "not promoted"
    return f"{text}{candidate.screen.status}, {promoted}"


def header(screens: bool) -> list[str]:
    """The table's columns: :data:`HEADER`, with :data:`SCREEN_COLUMN` after the loss when the
    run has ``screens``."""
    at = HEADER.index("loss") + 1
    return [*HEADER[:at], SCREEN_COLUMN, *HEADER[at:]] if screens else HEADER


def row(candidate: Candidate, screens: bool = False) -> list[str]:
    """The candidate's cells, in :func:`header`'s order."""
    answer = candidate.answer
    temperature = answer.temperature if answer else None
    cells = [
        candidate.id,
        str(candidate.iteration),
        f"{temperature:g}" if temperature is not None else "",
        status(candidate),
        cause(candidate),
        f"{candidate.loss:.4g}" if math.isfinite(candidate.loss) else "-",
        fitted(candidate.parameters),
        first_line(answer.plan) if answer else "",
        ", ".join(answer.parents) if answer else "",
    ]
    if screens:
        cells.insert(HEADER.index("loss") + 1, screen(candidate))
    return cells


def folds(candidate: Candidate, report: Path) -> list[Fold]:
    """The answer's texts that were recorded, and the fixes its code needed before it ran."""
    found = []
    if candidate.answer is not None and candidate.folder is not None:
        for name, file in TEXTS:
            text = getattr(candidate.answer, name)
            if text.strip():
                found.append(Fold(name, text, os.path.relpath(candidate.folder / file, report)))
    read_as = candidate.extras.get("read_as") or []
    if read_as:
        found.append(Fold("read as", "\n".join(f"- {fix}" for fix in read_as)))
    return found


def candidates_section(run: Run, report: Path) -> Section:
    """One row per candidate (screens never fitted fully too), in the order they were made;
    ``report`` is the report's folder, which the Markdown's links start from."""
    every = run.every_candidate()
    screens = bool(run.screens())
    rows = [row(c, screens) for c in every]
    table = FoldedTable(header(screens), rows, [folds(c, report) for c in every])
    note = ("Every candidate, in the order it was made: the temperature it was sampled at, how "
            "it ended and why, the constants fitted, the first line of its plan and the "
            "candidates its prompt showed (worst first).")  # fmt: skip
    if screens:
        note += (" The screen column gives the loss and outcome of its screen (a short fit, "
                 "compared only with other screens) and whether that promoted it to a full fit; "
                 "a candidate never fitted fully shows its screen's status and loss.")  # fmt: skip
    return Section("Candidates", [Text(note), table])
