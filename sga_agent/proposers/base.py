"""What the search asks of a proposer, and what it gets back.

Every proposer (a model through litellm, a task's built-in LLM-free proposer, the answers of a
recorded run) implements :class:`Proposer`: given a :class:`ProposalRequest` (the candidate
slots to fill, the top-K parents, the temperature, a seed, and the chat messages, built only
when a proposer reads them) it returns the answers. The search asks once per batch (the
exploit batch at T_l, the explore batch at T_h) and stores every :class:`Proposal` in the run
folder, so a proposal must round-trip through JSON.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

from sga_agent.task import Parent

Messages = list[dict[str, str]]


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
    finish_reason : str
        Why the model stopped, as the provider said: "stop", "length" (cut off at the token
        limit), "content_filter", ...; empty when unknown.
    reasoning : str
        The provider's reasoning for it, when it sends one apart from the answer
        (``reasoning_content`` of DeepSeek-R1, vLLM's reasoning parsers, ...).
    truncated_before : int
        Answers to the same slot that were cut off at the token limit and asked again with
        more room; their tokens and cost are included here.
    """

    text: str
    model: str
    temperature: float
    prompt_tokens: int = 0
    completion_tokens: int = 0
    cost_usd: float = 0.0
    cost_note: str = ""
    seconds: float = 0.0
    finish_reason: str = ""
    reasoning: str = ""
    truncated_before: int = 0

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Proposal:
        """The proposal ``to_dict`` wrote; keys it does not know (a record's own, such as the
        parents the search adds) are left out."""
        names = {f.name for f in dataclasses.fields(cls)}
        return cls(**{key: value for key, value in data.items() if key in names})


@dataclass
class ProposalRequest:
    """One batch the search asks for.

    Parameters
    ----------
    candidates : sequence of str
        The ids of the slots to fill, in order ("03-exploit-00", ...); ``n`` is their number.
    temperature : float
        The batch's temperature: low to exploit the parents, high to explore.
    seed : int
        Seed for a proposer's randomness (the same request gives the same answers).
    parents : sequence of Parent
        The top-K solutions shown, worst first, best last.
    prompt : messages, or a callable returning them
        The chat messages for a model; a callable is called on the first :meth:`messages`
        only, so proposers that never read the prompt never pay for it.
    tried : sequence of str
        The answer texts of every earlier proposal of this run, oldest first (a resumed run
        rebuilds them from its store): what a proposer without memory needs to try something
        new rather than a parent's forgotten sibling.
    opening : bool
        The batch is the search's wide first look (``LoopConfig.opening``): a proposer with a
        list of likely solutions answers with it (a model is asked as in any explore batch).
    """

    candidates: Sequence[str]
    temperature: float
    seed: int = 0
    parents: Sequence[Parent] = ()
    prompt: Messages | Callable[[], Messages] = field(default_factory=list)
    tried: Sequence[str] = ()
    opening: bool = False
    _built: Messages | None = field(default=None, init=False, repr=False)

    @property
    def n(self) -> int:
        return len(self.candidates)

    def messages(self) -> Messages:
        """The chat messages, built on the first call."""
        if self._built is None:
            self._built = self.prompt() if callable(self.prompt) else list(self.prompt)
        return self._built

    @property
    def built_messages(self) -> Messages | None:
        """The messages if a proposer asked for them, else None (nothing to record)."""
        return self._built


class ProposerError(RuntimeError):
    """The model could not be asked (after retries); the message names the cause and the fix.

    The search stops on it, resumable, with every finished evaluation kept. ``transient`` is
    True when a later request may well succeed (rate limits, timeouts, server errors that
    outlasted the retries: a resume once the provider answers again); otherwise (no key, a
    refused key, an unknown model, nothing listening at the address) the setting must change
    first. Messages never contain API keys: proposers redact them before raising.
    """

    def __init__(self, message: str, transient: bool = False) -> None:
        super().__init__(message)
        self.transient = transient


@runtime_checkable
class Proposer(Protocol):
    """Anything that answers a :class:`ProposalRequest`.

    ``propose`` returns up to ``request.n`` proposals, for the request's candidates in order:
    all of them, or fewer (for the first ones) when some failed or, for a recorded run, were
    never recorded. It raises :class:`ProposerError` when the model could not be asked at all,
    which stops the search, and returns an empty list for ``n == 0``.
    """

    @property
    def name(self) -> str:
        """Identifies the proposer in the run config, e.g. "litellm:openai/gpt-4o"."""
        ...

    def propose(self, request: ProposalRequest) -> list[Proposal]: ...
