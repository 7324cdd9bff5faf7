"""Proposers: who writes the candidate solutions the search evaluates.

:mod:`~sga_agent.proposers.base` holds the contract (:class:`Proposer`, :class:`ProposalRequest`,
:class:`Proposal`); :mod:`~sga_agent.proposers.litellm_backbone` asks any model litellm can
reach, :mod:`~sga_agent.proposers.builtin` a task's LLM-free proposer, and
:mod:`~sga_agent.proposers.replay` answers from a recorded run.
"""

from sga_agent.proposers.base import (
    Proposal,
    ProposalRequest,
    Proposer,
    ProposerError,
)
from sga_agent.proposers.builtin import BuiltinAdapter
from sga_agent.proposers.litellm_backbone import (
    BackboneSettings,
    BackboneSettingsError,
    LiteLLMProposer,
)
from sga_agent.proposers.replay import ReplayProposer

__all__ = [
    "BackboneSettings",
    "BackboneSettingsError",
    "BuiltinAdapter",
    "LiteLLMProposer",
    "Proposal",
    "ProposalRequest",
    "Proposer",
    "ProposerError",
    "ReplayProposer",
]
