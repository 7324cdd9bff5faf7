"""The prompt's section on what went wrong in the last iteration.

Every answer of the last iteration that was not scored (no code, rejected by the checks,
failed in the sandbox, unstable, ...) or that repeated a law already tried is told to the model
in the next prompt, so that it does not make the same mistake twice. Alike failures are told
once (:func:`sga_agent.causes.cause_of` groups them), with the answers they hit, the full reason
(cause, line and fix) and a few lines of the first one's code; slips that were fixed before the
code ran are listed in one line. The section is bounded: at most :data:`MAX_CAUSES` causes, each
reason at most :data:`MAX_REASON_CHARS` characters, each excerpt at most :data:`EXCERPT_LINES`
lines.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from sga_agent.causes import REPEATED, cause_of
from sga_agent.heap import same_loss

MAX_CAUSES = 6
MAX_REASON_CHARS = 420
EXCERPT_LINES = 6
_LINE = re.compile(r"\bline (\d+)\b")


@dataclass(frozen=True)
class Outcome:
    """One answer of the last iteration: its id, code (or text when it had none), evaluation
    (as ``Evaluation.to_dict`` gives it) and the slips fixed on reading it."""

    candidate: str
    code: str
    evaluation: Mapping[str, object]
    fixes: Sequence[str] = field(default_factory=tuple)


def failures_text(outcomes: Sequence[Outcome], earlier_losses: Mapping[str, float]) -> str:
    """The section's body for the last iteration's ``outcomes``; ``earlier_losses`` maps the
    scored candidates to their losses (to tell a repeat the loss of the law it repeated, and
    find a scored answer that reached exactly the loss of one before it). Empty when nothing
    went wrong."""
    grouped: dict[str, list[Outcome]] = {}
    repeats: list[str] = []
    for outcome in outcomes:
        repeat = _repeat(outcome, earlier_losses)
        if repeat:
            repeats.append(repeat)
            continue
        cause = cause_of(outcome.evaluation)
        if cause:
            grouped.setdefault(cause, []).append(outcome)
    lines = [_told(group) for group in list(grouped.values())[:MAX_CAUSES]]
    if len(grouped) > MAX_CAUSES:
        rest = sum(len(group) for group in list(grouped.values())[MAX_CAUSES:])
        lines.append(f"- ({len(grouped) - MAX_CAUSES} more causes, {rest} answers, not listed)")
    if repeats:
        lines.append(
            f"- {REPEATED[0].upper()}{REPEATED[1:]}: "
            + "; ".join(repeats)
            + ". Propose a different form: its fit cannot change the form, only its constants."
        )
    slips = sorted({fix for outcome in outcomes for fix in outcome.fixes})
    if slips:
        lines.append(
            "- Slips fixed before the code ran (avoid them): "
            + "; ".join(_shorter(slip, 160) for slip in slips[:4])
            + "."
        )
    return "\n".join(lines)


def _repeat(outcome: Outcome, earlier_losses: Mapping[str, float]) -> str:
    """How ``outcome`` repeated an earlier law, or ""."""
    extras = outcome.evaluation.get("extras") or {}
    assert isinstance(extras, Mapping)
    for key, how in (("duplicate_of", "the same code as"), ("same_form_as", "the same law as")):
        first = extras.get(key)
        if first:
            loss = earlier_losses.get(str(first))
            known = f", loss {loss:.3g}" if loss is not None and math.isfinite(loss) else ""
            return f"{outcome.candidate} is {how} {first}{known}"
    loss = _loss(outcome.evaluation)
    if outcome.evaluation.get("valid") and math.isfinite(loss):
        for candidate, earlier in earlier_losses.items():
            if (
                math.isfinite(earlier)
                and same_loss(loss, earlier)
                and candidate < outcome.candidate
            ):
                return (
                    f"{outcome.candidate} reached exactly the loss of {candidate} ({loss:.6g}): "
                    "the same law written another way"
                )
    return ""


def _told(group: list[Outcome]) -> str:
    """One cause: the answers it hit, the first one's reason and code excerpt."""
    first = group[0]
    status = str(first.evaluation.get("status") or "invalid")
    reason = str(first.evaluation.get("reason") or first.evaluation.get("feedback") or "")
    names = ", ".join(outcome.candidate for outcome in group)
    text = f"- {names} ({status}): {_shorter(' '.join(reason.split()), MAX_REASON_CHARS)}"
    excerpt = _excerpt(first.code, reason)
    if excerpt:
        text += "\n  Its code there:\n" + "\n".join(f"      {line}" for line in excerpt)
    return text


def _excerpt(code: str, reason: str) -> list[str]:
    """A few lines of ``code``: around the line the reason names, else its first lines of
    substance (imports and blank lines skipped); each line numbered."""
    lines = code.splitlines()
    if not lines:
        return []
    match = _LINE.search(reason)
    if match and 1 <= int(match.group(1)) <= len(lines):
        at = int(match.group(1)) - 1
        start = max(0, at - EXCERPT_LINES // 2)
    else:
        skipped = ("import ", "from ", "#")
        start = next(
            (
                i
                for i, line in enumerate(lines)
                if line.strip() and not line.lstrip().startswith(skipped)
            ),
            0,
        )
    chosen = range(start, min(len(lines), start + EXCERPT_LINES))
    return [f"{i + 1:>3} | {_shorter(lines[i].rstrip(), 110)}" for i in chosen]


def _loss(evaluation: Mapping[str, object]) -> float:
    try:
        return float(evaluation.get("loss", math.inf))  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return math.inf


def _shorter(text: str, limit: int) -> str:
    return text if len(text) <= limit else text[: limit - 1] + "…"
