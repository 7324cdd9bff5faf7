"""The population of evaluated solutions and its top-K (pure, no I/O)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

#: Relative difference below which two losses are one number: the same law, written otherwise.
SAME_LOSS = 1e-9


@dataclass(frozen=True)
class Entry:
    """One evaluated candidate: its id, code, loss (inf when invalid), feedback and fitted
    parameter values."""

    candidate: str
    code: str
    loss: float
    feedback: str
    valid: bool
    order: int = 0  # insertion order: ties go to the earlier candidate
    parameters: dict[str, float] = field(default_factory=dict, compare=False)

    def key(self, parsimony: float = 0.0) -> tuple[float, int]:
        """Rank key: the loss (inf when not finite) times ``1 + parsimony`` per fitted
        parameter (see :attr:`~sga_agent.config.LoopConfig.parsimony`), then the order."""
        return (ranked_loss(self.loss, len(self.parameters), parsimony), self.order)

    def summary(self) -> dict[str, Any]:
        """JSON-ready id, loss (an infinite loss as the string "inf") and validity."""
        loss = self.loss if math.isfinite(self.loss) else str(self.loss)
        return {"candidate": self.candidate, "loss": loss, "valid": self.valid}


def ranked_loss(loss: float, parameters: int, parsimony: float) -> float:
    """The loss a solution with ``parameters`` fitted parameters ranks by: moved up by a share
    ``parsimony`` per parameter (a negative loss towards 0)."""
    if not math.isfinite(loss):
        return math.inf
    factor = (1.0 + parsimony) ** parameters
    return loss * factor if loss >= 0 else loss / factor


@dataclass
class SolutionHeap:
    """All evaluated solutions, ranked by loss (lower is better), a fitted parameter costing
    ``parsimony`` of it."""

    parsimony: float = 0.0
    entries: list[Entry] = field(default_factory=list)

    def push(
        self,
        candidate: str,
        code: str,
        loss: float,
        feedback: str,
        valid: bool,
        parameters: dict[str, float] | None = None,
    ) -> Entry:
        entry = Entry(
            candidate, code, loss, feedback, valid, len(self.entries), dict(parameters or {})
        )
        self.entries.append(entry)
        return entry

    def top(self, k: int) -> list[Entry]:
        """The k best entries, best first (valid ones before invalid ones)."""
        return sorted(self.entries, key=lambda entry: entry.key(self.parsimony))[:k]

    def distinct_top(self, k: int, form: Callable[[str], str]) -> list[Entry]:
        """The k best valid entries, best first, one per law: an entry whose code has the
        ``form`` of a better one (the same law with other constants), or whose loss equals a
        better one's, is passed over. Fewer than k when fewer distinct laws exist."""
        chosen: list[Entry] = []
        forms: set[str] = set()
        for entry in self.top(len(self.entries)):
            if not (entry.valid and math.isfinite(entry.loss)):
                continue
            key = form(entry.code)
            if key in forms or any(same_loss(entry.loss, other.loss) for other in chosen):
                continue
            forms.add(key)
            chosen.append(entry)
            if len(chosen) == k:
                break
        return chosen

    def best(self) -> Entry | None:
        ranked = self.top(1)
        return ranked[0] if ranked else None

    def __len__(self) -> int:
        return len(self.entries)


def same_loss(a: float, b: float) -> bool:
    """Whether ``a`` and ``b`` are one loss (within :data:`SAME_LOSS` of the larger)."""
    return abs(a - b) <= SAME_LOSS * max(abs(a), abs(b))
