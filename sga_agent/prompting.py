"""Assembling the prompt of one proposal from the templates in ``prompts/``.

The order follows the paper's data workflow (appendix "Data Workflow"): the system prompt
first, then the earlier solutions (the top-K, worst first so that the best one sits right before
the request), then the format requirements last. Concretely, :func:`build_messages` returns

1. a system message: ``system_<kind>.md`` with the task's role;
2. a user message made of
   a. ``context.md``: the task context,
   b. ``history.md`` followed by one ``iteration.md`` per shown solution, "Iteration 1" the
      worst (highest loss; unscored ones first) and "Iteration K" the best,
   c. ``failures.md``, when the last iteration had failures: what went wrong, one line per
      cause (:mod:`sga_agent.failures` writes it),
   d. ``format_<kind>.md``: the task's rules and code template, then the three sections the
      answer must have ("### Analysis" with "#### Iteration N" per shown iteration,
      "### Step-by-Step Plan", "### Code").

With a token budget, the shown solutions' feedback is shortened, the worst solution's first,
until the prompt fits (:func:`fit_to_budget`); every section stays.

Templates use :class:`string.Template` placeholders (``${name}``); every placeholder must be
filled, so a misspelt name fails loudly rather than leaking into a prompt.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cache
from string import Template
from typing import get_args

from sga_agent.resources import prompts_dir
from sga_agent.task import PromptParts, TaskKind

KINDS: tuple[str, ...] = get_args(TaskKind)


@dataclass(frozen=True)
class Shown:
    """One earlier solution shown to the model.

    Parameters
    ----------
    code : str
        The solution's code.
    feedback : str
        What its evaluation reported.
    loss : float
        Its loss; ``inf`` or ``nan`` for a solution that could not be scored.
    """

    code: str
    feedback: str
    loss: float


@cache
def _template(name: str) -> Template:
    return Template(prompts_dir().joinpath(name).read_text(encoding="utf-8"))


def render(name: str, **values: object) -> str:
    """Fill the template ``prompts/<name>`` with ``values`` (all placeholders required)."""
    return _template(name).substitute(values).strip()


def worst_first(history: Sequence[Shown]) -> list[Shown]:
    """``history`` from the highest loss to the lowest; unscored (inf, nan) solutions first.

    The sort is stable: solutions with equal losses keep the caller's order.
    """

    def badness(shown: Shown) -> float:
        return math.inf if math.isnan(shown.loss) else shown.loss

    return sorted(history, key=badness, reverse=True)


def build_messages(
    kind: str, parts: PromptParts, history: Sequence[Shown], failures: str = ""
) -> list[dict[str, str]]:
    """The chat messages asking for one new solution.

    Parameters
    ----------
    kind : str
        The task kind, ``"equation"`` or ``"entity"``; picks the system and format templates.
    parts : PromptParts
        The task's role, context, code template and requirements.
    history : sequence of Shown
        The earlier solutions to show (the top-K), in any order; they are shown worst first.
    failures : str
        What went wrong in the last iteration (empty: no such section).

    Returns
    -------
    list of dict
        ``[{"role": "system", "content": ...}, {"role": "user", "content": ...}]``.
    """
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    blocks = [render("context.md", context=parts.context.strip())]
    ordered = worst_first(history)
    if ordered:
        blocks.append(render("history.md", last=len(ordered)))
        blocks += [
            render(
                "iteration.md",
                index=index,
                code=shown.code.strip(),
                feedback=shown.feedback.strip() or "(no feedback)",
            )
            for index, shown in enumerate(ordered, start=1)
        ]
    if failures.strip():
        blocks.append(render("failures.md", failures=failures.strip()))
    blocks.append(
        render(
            f"format_{kind}.md",
            requirements=parts.requirements.strip(),
            template=parts.template.strip(),
        )
    )
    return [
        {"role": "system", "content": render(f"system_{kind}.md", role=parts.role.strip())},
        {"role": "user", "content": "\n\n".join(blocks) + "\n"},
    ]


#: Lines of feedback a shown solution keeps at each step of shortening, longest first.
FEEDBACK_LINES = (40, 24, 14, 8, 4, 2)


def fit_to_budget(
    kind: str,
    parts: PromptParts,
    history: Sequence[Shown],
    failures: str,
    budget: int | None,
    count: Callable[[list[dict[str, str]]], int],
) -> tuple[list[dict[str, str]], int]:
    """The messages of :func:`build_messages` within ``budget`` tokens (``count`` counts a
    prompt's), and their count.

    Each step shortens one more shown solution's feedback to the next length of
    :data:`FEEDBACK_LINES`, the worst solution first, keeping its first lines and saying how
    many were left out; every section stays. A prompt that still does not fit at the shortest
    is returned as it is (its task text and code alone exceed the budget).
    """
    original = worst_first(history)
    ordered = list(original)
    messages = build_messages(kind, parts, ordered, failures)
    tokens = count(messages)
    if budget is None or tokens <= budget:
        return messages, tokens
    for lines in FEEDBACK_LINES:
        for index, shown in enumerate(original):
            ordered[index] = dataclasses.replace(shown, feedback=shortened(shown.feedback, lines))
            messages = build_messages(kind, parts, ordered, failures)
            tokens = count(messages)
            if tokens <= budget:
                return messages, tokens
    return messages, tokens


def shortened(feedback: str, lines: int) -> str:
    """``feedback`` cut to its first ``lines`` lines, saying how many were left out."""
    kept = feedback.strip().splitlines()
    if len(kept) <= lines:
        return feedback
    left = len(kept) - lines
    return "\n".join([*kept[:lines], f"({left} more lines of this feedback left out)"])


def count_tokens(model: str) -> Callable[[list[dict[str, str]]], int]:
    """A counter of a prompt's tokens for ``model``, with litellm's counter (its tokenizer
    for the model where it knows one, else a GPT tokenizer)."""
    from sga_agent.proposers.litellm_backbone import import_litellm

    litellm = import_litellm()

    def count(messages: list[dict[str, str]]) -> int:
        return int(litellm.token_counter(model=model, messages=messages))

    return count
