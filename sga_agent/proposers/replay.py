"""Answers from a recorded run: ``sga-agent search --replay RUN_DIR`` asks no model."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from sga_agent.proposers.base import Proposal, ProposalRequest
from sga_agent.run_store import RunStore


class ReplayProposer:
    """Gives each candidate slot the answer the run in ``run_dir`` recorded for it.

    A slot the recorded run has no answer for gets none (nor do the slots after it in the same
    request, as a model's short answer would leave them); the search records them as missing
    and goes on.

    Raises
    ------
    sga_agent.run_store.RunStoreError
        ``run_dir`` is not a run folder.
    """

    def __init__(self, run_dir: Path) -> None:
        self.store = RunStore.open(Path(run_dir))
        self.answers: dict[str, dict[str, Any]] = self.store.recorded().proposals

    @property
    def name(self) -> str:
        return f"replay:{self.store.path}"

    def propose(self, request: ProposalRequest) -> list[Proposal]:
        proposals = []
        for candidate in request.candidates:
            if candidate not in self.answers:
                break
            proposals.append(Proposal.from_dict(self.answers[candidate]))
        return proposals
