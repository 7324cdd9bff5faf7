"""A task's built-in (LLM-free) proposer as a :class:`~sga_agent.proposers.base.Proposer`."""

from __future__ import annotations

import inspect

from sga_agent.proposers.base import Proposal, ProposalRequest
from sga_agent.task import BuiltinProposer


class BuiltinAdapter:
    """Answers a request with ``builtin.propose_from`` (the parents, never the prompt).

    Parameters
    ----------
    builtin : BuiltinProposer
        What a task's ``builtin_proposer()`` returned, e.g. the constitutive tasks' genetic
        programming ("builtin:gp").
    """

    def __init__(self, builtin: BuiltinProposer) -> None:
        self.builtin = builtin
        self.reads_tried = _takes(builtin, "tried")
        self.reads_opening = _takes(builtin, "opening")

    @property
    def name(self) -> str:
        return self.builtin.name

    def propose(self, request: ProposalRequest) -> list[Proposal]:
        extra: dict[str, object] = {"tried": list(request.tried)} if self.reads_tried else {}
        if self.reads_opening:
            extra["opening"] = request.opening
        texts = self.builtin.propose_from(
            list(request.parents), request.temperature, request.n, request.seed, **extra
        )
        return [Proposal(text, self.name, request.temperature) for text in texts[: request.n]]


def _takes(builtin: BuiltinProposer, keyword: str) -> bool:
    """Whether ``builtin.propose_from`` takes ``keyword``: the run's earlier answers
    (``tried=``), whether the batch is the search's opening (``opening=``)."""
    try:
        return keyword in inspect.signature(builtin.propose_from).parameters
    except (TypeError, ValueError):
        return False
