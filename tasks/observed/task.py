"""``observed``: discover the constitutive law of an object from your own observation of it.

The observation is a ``taichi_mpm.sysid`` file (scene, initial state, positions of some or all
particles at some frames), named by ``--option observation=PATH.npz``; ``--option
searched=plastic`` (with the known elastic law: ``elastic=FAMILY``, ``E``, ``nu``) or
``searched=elastic`` says which part of the law is searched. Laws are proposed, captured and
checked exactly as in the constitutive tasks; the fit runs without teacher forcing.
``--option validation=PATH.npz``, a second observation of the same material in another scene,
is the held-out scene of the report's free run.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from sga_agent.task import (
    Assessment,
    BuiltinProposer,
    CandidateRecord,
    Evaluation,
    EvaluationSettings,
    FormComparison,
    PromptParts,
    Simplified,
)
from tasks.constitutive import prompt_text
from tasks.constitutive.task import ConstitutiveTask
from tasks.observed.options import ObservedOptions


class ObservedTask(ConstitutiveTask):
    """Search the law behind an observation file; set up for it by :meth:`with_options`.

    Shares the constitutive tasks' solution checks, capture and fitted-code display; the seed,
    prompt and proposer follow ``searched``, the evaluation the observation.
    """

    options_type = ObservedOptions
    loss_label = "loss"  # the observation's units are the file's
    si_units = False  # so a modulus's unit is not known
    screens_cheaply = False  # its fit runs whole at any fidelity

    def __init__(self, options: ObservedOptions | None = None) -> None:
        self.options = options
        self.name = "observed"
        self.description = ("a constitutive law (elastic or plastic part) discovered from your "
                            "own observation file (taichi_mpm.sysid format)")  # fmt: skip

    def with_options(self, options: ObservedOptions) -> ObservedTask:
        return ObservedTask(options)

    def configured_options(self) -> ObservedOptions:
        """The options this task was set up with; a ``ValueError`` if none were given."""
        if self.options is None:
            raise ValueError("task 'observed' needs its options: --option observation=PATH.npz "
                             "--option searched=plastic|elastic")  # fmt: skip
        return self.options

    @property
    def searched(self) -> str:
        return self.configured_options().searched

    def seed_solution(self) -> str:
        """The linear elastic law, or no plasticity (the constitutive tasks' seeds)."""
        if self.searched == "elastic":
            return prompt_text.ELASTIC_SEED
        return prompt_text.PLASTIC_SEED

    def prompt_parts(self) -> PromptParts:
        from tasks.observed.data import ObservedData
        from tasks.observed.prompt import prompt_parts

        options = self.configured_options()
        return prompt_parts(ObservedData.load(options.observation, options.frames), options)

    def warm_up_solutions(self) -> list[str]:
        """Both seeds and a law using every common operation (the capture knows no options)."""
        from tasks.constitutive.law_capture import WARM_UP_LAW

        return [prompt_text.ELASTIC_SEED, prompt_text.PLASTIC_SEED, WARM_UP_LAW]

    def warm_up_fit(self, options: ObservedOptions) -> Iterator[None]:
        from tasks.observed.evaluation import warm_up

        return warm_up(options)

    def evaluate(self, data: dict[str, Any], settings: EvaluationSettings) -> Evaluation:
        from tasks.observed.evaluation import evaluate

        return evaluate(data, settings)

    def assess(
        self,
        artifacts: dict[str, Any] | None,
        parameters: dict[str, float],
        options: ObservedOptions,
        simulate: bool,
    ) -> Assessment:
        """The hidden truth beside the observation (if written there; the one recorded when the
        run started) and its loss, the best law's readable values, its free runs against the
        observed particles and the validation file's, and the verdict."""
        from tasks.observed.evaluation import assess

        return assess(artifacts, parameters, options, simulate, self.recorded)

    def compare_forms(
        self, candidates: Sequence[CandidateRecord], options: ObservedOptions,
        folder: Path | None,
    ) -> FormComparison | None:
        """The distinct forms within 2x of the best loss (the observation's noise, as the best
        fit estimates it), simulated on the observed body's four probe scenes."""
        from tasks.observed.evaluation import compare_forms

        return compare_forms(candidates, options, folder)

    def _simplified(
        self, candidate: CandidateRecord, options: ObservedOptions
    ) -> Simplified | None:
        """Each drop scored as the fit scores a law (a free rollout, no teacher forcing)."""
        from tasks.observed.evaluation import simplified

        return simplified(candidate, options)

    def describe_assessment(self, simulate: bool) -> str:
        return "assessing the best solution: the hidden truth's loss" + (
            " and the free runs on the observation and the validation file (if given), then "
            "the forms that fit as well on four probe scenes"
            if simulate
            else ""
        )

    def provenance(self, options: ObservedOptions) -> dict[str, Any]:
        """The observation's (and validation's) path and sha256, the hidden truth beside it."""
        from tasks.observed.data import provenance

        return provenance(options.observation, options.validation)

    def builtin_proposer(self) -> BuiltinProposer:
        """Genetic programming over law code, seeded by the searched part's seed law."""
        from tasks.constitutive.gp import GeneticProgrammingProposer

        return GeneticProgrammingProposer(self.searched)
