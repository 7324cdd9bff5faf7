"""What the search asks of a proposer, and what it gets back.

A proposer turns chat messages into candidate responses. The search asks it for ``n`` samples
at one temperature per call (the exploit batch at T_l, the explore batch at T_h) and stores
every :class:`Proposal` in the run folder, so a proposal must round-trip through JSON.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable


@dataclass(frozen=True)
class Proposal:
    """One sampled response and what it cost.

    Parameters
    ----------
    text : str
        The raw response text.
    model : str
        The model that wrote it (for litellm, the model string, e.g. "openai/gpt-4o").
    temperature : float
        The sampling temperature it was asked at.
    prompt_tokens, completion_tokens : int
        Tokens billed for it. When one request returned several choices, the request's tokens
        are shared among them so that sums over proposals equal what was billed.
    cost_usd : float
        Its share of the request's price in US dollars (0 when the price is unknown).
    cost_note : str
        Why the cost may be wrong, e.g. the model is not in litellm's price map; empty if priced.
    seconds : float
        Wall time of the request that produced it, retries included.
    """

    text: str
    model: str
    temperature: float
    prompt_tokens: int = 0
    completion_tokens: int = 0
    cost_usd: float = 0.0
    cost_note: str = ""
    seconds: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Proposal:
        return cls(**data)


class ProposerError(RuntimeError):
    """The model could not be asked (after retries); the message names the cause and the fix.

    ``transient`` is True when a later request may well succeed (rate limits, timeouts, server
    errors that outlasted the retries); otherwise (no key, a refused key, an unknown model,
    nothing listening at the address) asking again is pointless and the search stops.
    Messages never contain API keys: proposers redact them before raising.
    """

    def __init__(self, message: str, transient: bool = False) -> None:
        super().__init__(message)
        self.transient = transient


@runtime_checkable
class Proposer(Protocol):
    """Anything that samples responses to chat messages.

    ``propose`` returns up to ``n`` proposals: all of them, or fewer when some requests failed
    but at least one succeeded (the failures are logged). It raises :class:`ProposerError` only
    when none succeeded, and returns an empty list for ``n == 0``.
    """

    @property
    def name(self) -> str:
        """Identifies the proposer in the run config, e.g. "litellm:openai/gpt-4o"."""
        ...

    def propose(
        self, messages: list[dict[str, str]], temperature: float, n: int
    ) -> list[Proposal]: ...


def describe_proposer(proposer: Proposer) -> dict[str, Any]:
    """The proposer's settings for the run config (no secrets): its ``describe()`` if it has one."""
    describe = getattr(proposer, "describe", None)
    return describe() if callable(describe) else {"name": proposer.name}
