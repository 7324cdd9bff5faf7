"""Proposers: who writes the candidate solutions the search evaluates.

:mod:`~sga_agent.proposers.base` holds the contract (:class:`Proposer`, :class:`Proposal`);
:mod:`~sga_agent.proposers.litellm_backbone` asks any model litellm can reach.
"""

from sga_agent.proposers.base import Proposal, Proposer, ProposerError, describe_proposer
from sga_agent.proposers.litellm_backbone import (
    BackboneSettings,
    BackboneSettingsError,
    LiteLLMProposer,
)

__all__ = [
    "BackboneSettings",
    "BackboneSettingsError",
    "LiteLLMProposer",
    "Proposal",
    "Proposer",
    "ProposerError",
    "describe_proposer",
]
