"""How far a fit has come, told to whoever waits for it: an optional, informational hook.

A task's ``evaluate`` (and ``warm_up_fit``) may call :func:`report_progress` as its fit goes: a
stage starting ("compiling the law"), an epoch finished. In a fit worker each call becomes a
note that the evaluating process shows (``sga-agent evaluate``'s epochs, a search's progress
line); anywhere else, and for a task that never calls it, nothing happens. A note never
reaches an :class:`~sga_agent.task.Evaluation`, so it cannot change a score.

Standard library only (part of the protocol package :mod:`sga_agent.task`).
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable, Iterator
from contextvars import ContextVar
from dataclasses import dataclass
from typing import Any

#: Longest stage text a note keeps.
MAX_STAGE_CHARS = 80


@dataclass(frozen=True)
class FitProgress:
    """One progress note: the ``stage`` running ("warming up", "fitting"), and within it, when
    it counts epochs, the ``epoch`` just finished (1-based) of ``epochs`` and its ``loss``."""

    stage: str
    epoch: int | None = None
    epochs: int | None = None
    loss: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON data (a non-finite loss as its text: "inf", "nan"); None fields left out."""
        data: dict[str, Any] = {"stage": self.stage}
        if self.epoch is not None:
            data["epoch"] = self.epoch
        if self.epochs is not None:
            data["epochs"] = self.epochs
        if self.loss is not None:
            data["loss"] = self.loss if math.isfinite(self.loss) else str(self.loss)
        return data

    @classmethod
    def from_dict(cls, data: Any) -> FitProgress | None:
        """The note ``data`` holds, checked field by field (a printable stage of at most
        :data:`MAX_STAGE_CHARS`, counts that are non-negative integers, a loss that is a
        number); None when it is no note at all (no text stage). A malformed field is
        dropped, never raised."""
        if not isinstance(data, dict) or not isinstance(data.get("stage"), str):
            return None
        stage = "".join(ch if ch.isprintable() else " " for ch in data["stage"])
        counts = [_count(data.get(name)) for name in ("epoch", "epochs")]
        return cls(stage[:MAX_STAGE_CHARS].strip(), *counts, _number(data.get("loss")))


def _count(value: Any) -> int | None:
    ok = isinstance(value, int) and not isinstance(value, bool) and 0 <= value < 2**31
    return value if ok else None


def _number(value: Any) -> float | None:
    if isinstance(value, str) and value in ("inf", "-inf", "nan"):
        return float(value)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    return float(value)


_LISTENER: ContextVar[Callable[[FitProgress], None] | None] = ContextVar(
    "sga_fit_progress", default=None
)


def report_progress(
    stage: str, epoch: int | None = None, epochs: int | None = None, loss: float | None = None
) -> None:
    """Tell whoever waits for this fit that ``stage`` runs, and (counting epochs) that
    ``epoch`` of ``epochs`` has finished with ``loss``. Cheap, and a no-op where nobody
    listens; it never raises. Call it when a stage starts and after each epoch, not per
    simulation step."""
    listener = _LISTENER.get()
    if listener is None:
        return
    with contextlib.suppress(Exception):  # informational: a failure to tell is never the fit's
        listener(FitProgress(str(stage), epoch, epochs, None if loss is None else float(loss)))


@contextlib.contextmanager
def progress_to(listener: Callable[[FitProgress], None]) -> Iterator[None]:
    """Within this block, :func:`report_progress` hands its notes to ``listener`` (the fit
    worker sends them to its parent)."""
    token = _LISTENER.set(listener)
    try:
        yield
    finally:
        _LISTENER.reset(token)
