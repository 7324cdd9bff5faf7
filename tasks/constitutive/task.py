"""The constitutive-law tasks as :class:`sga_agent.task.Task` objects.

Listing a task or building its prompt imports neither Taichi nor torch. ``capture`` runs the
law's code to record it as a graph (in the confined capture process); ``evaluate`` fits that
graph (in the trusted fit worker, which never runs the law's code).
"""

from __future__ import annotations

import copy
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from types import MappingProxyType
from typing import Any

from sga_agent.task import (
    Assessment,
    BuiltinProposer,
    CandidateRecord,
    Evaluation,
    EvaluationSettings,
    FormComparison,
    PromptParts,
    ReportView,
    Section,
    Simplified,
    TaskBase,
)
from tasks.constitutive import prompt_text, report
from tasks.constitutive.law_shape import check_law
from tasks.constitutive.options import ConstitutiveOptions
from tasks.constitutive.specs import SPECS, ConstitutiveSpec


class ConstitutiveTask(TaskBase):
    """Search a constitutive law that reproduces an observed MPM trajectory."""

    kind = "equation"
    options_type = ConstitutiveOptions
    #: The built-in genetic programming's runs fit constants by L-BFGS, as symbolic-regression
    #: tools fit theirs with quasi-Newton steps (with Adam's few small steps at a short budget, a
    #: child's constants barely move; ``--option optimizer=adam`` restores it).
    builtin_options = MappingProxyType({"optimizer": "lbfgs"})
    screens_cheaply = True  # fewer epochs on fewer segments (tasks/constitutive/fidelity.py)
    loss_label = report.LOSS_LABEL
    size_label = "operations of the captured law, those that only lay data out left out"
    #: Whether the report draws the observation beside the best law's free run.
    draws_motion = True
    #: Whether the scenes are in SI units, so that a modulus or a stress is in Pa.
    si_units = True
    #: What the capture server loads before it confines a capture (see law_capture).
    capture_modules = ("numpy", "torch", "torch.nn", "torch.nn.functional", "torch.linalg",
                       "tasks.constitutive.law_capture")  # fmt: skip

    #: What the run being assessed recorded at its start (:meth:`with_provenance`).
    recorded: Mapping[str, Any] | None = None

    def __init__(self, spec: ConstitutiveSpec) -> None:
        self.spec = spec
        self.name = spec.name
        self.description = spec.description

    def seed_solution(self) -> str:
        return self.spec.seed

    def prompt_parts(self) -> PromptParts:
        if self.spec.searched == "elastic":
            return PromptParts(
                role=prompt_text.ROLE,
                context=prompt_text.ELASTIC_CONTEXT,
                template=prompt_text.ELASTIC_TEMPLATE,
                requirements=prompt_text.ELASTIC_RULES,
            )
        return PromptParts(
            role=prompt_text.ROLE,
            context=prompt_text.PLASTIC_CONTEXT,
            template=prompt_text.PLASTIC_TEMPLATE,
            requirements=prompt_text.PLASTIC_RULES,
        )

    def warm_up_solutions(self) -> list[str]:
        """The seed and a law using every common operation, captured when a server starts."""
        from tasks.constitutive.law_capture import WARM_UP_LAW

        return [self.spec.seed, WARM_UP_LAW]

    def warm_up_fit(self, options: ConstitutiveOptions) -> Iterator[None]:
        """Ground truth and every kernel an evaluation launches, loaded in stages."""
        from tasks.constitutive.evaluation import warm_up

        return warm_up(self.spec, options)

    def check_solution(self, code: str) -> None:
        """One class Physics(nn.Module), defaulted __init__, forward(self, F) (nothing is run)."""
        check_law(code)

    def capture(self, solution: str) -> dict[str, Any]:
        """The law's graph (runs its code: capture process only)."""
        from tasks.constitutive.law_capture import capture_law

        return {"law": capture_law(solution)}

    def evaluate(self, data: dict[str, Any], settings: EvaluationSettings) -> Evaluation:
        from tasks.constitutive.evaluation import evaluate

        return evaluate(self.spec, data, settings)

    def solution_with_parameters(self, solution: str, parameters: dict[str, float]) -> str:
        """The law's code with its fitted constants as its parameters' defaults (parsed only),
        without the genetic programming's genome tag, which still holds the proposed ones."""
        from tasks.constitutive.fitted_code import with_fitted_values
        from tasks.constitutive.gp.codegen import GENOME_TAG

        lines = solution.splitlines(keepends=True)
        kept = []
        for index, line in enumerate(lines):
            tag_above = index > 0 and lines[index - 1].startswith(GENOME_TAG)
            if not line.startswith(GENOME_TAG) and not (tag_above and not line.strip()):
                kept.append(line)  # the tag goes with the blank line that sets it off
        return with_fitted_values("".join(kept), parameters)

    def parameter_units(self, solution: str, names: Sequence[str]) -> dict[str, str]:
        """Pa for a modulus or a stress (with :attr:`si_units`), an angle's unit as the law's
        code uses it (see :mod:`tasks.constitutive.units`)."""
        from tasks.constitutive.units import parameter_units

        return parameter_units(solution, names, si=self.si_units)

    def provenance(self, options: ConstitutiveOptions) -> dict[str, Any]:
        """The ground truth in words, with its values."""
        return {"truth": self.spec.truth_name}

    def with_provenance(self, recorded: Mapping[str, Any]) -> ConstitutiveTask:
        """A copy that assesses against the truth ``recorded`` at the run's start."""
        task = copy.copy(self)
        task.recorded = dict(recorded)
        return task

    def assess(
        self,
        artifacts: dict[str, Any] | None,
        parameters: dict[str, float],
        options: ConstitutiveOptions,
        simulate: bool,
    ) -> Assessment:
        """The ground truth's name and loss, the best law's derived values (``exp(log_E)``),
        its free runs on the training and the held-out scene and the verdict, from its captured
        graph (its code is not run)."""
        from tasks.constitutive.assessment import assess

        return assess(self.spec, artifacts, parameters, options, simulate, self.recorded)

    def compare_forms(
        self, candidates: Sequence[CandidateRecord], options: ConstitutiveOptions,
        folder: Path | None,
    ) -> FormComparison | None:
        """The distinct forms within 2x of the best loss (or of the true law's own, the float
        floor), simulated on four probe scenes (see :mod:`tasks.constitutive.forms`)."""
        from tasks.constitutive.forms import compare_task_forms

        return compare_task_forms(self.spec, candidates, options, folder)

    def formula(self, solution: str, parameters: dict[str, float]) -> str:
        """A genetic-programming law as one formula, its sums and blends collected by SymPy
        (:mod:`tasks.constitutive.gp.formula`); "" for a law a model wrote."""
        from tasks.constitutive.gp.codegen import genome_from_code, with_values
        from tasks.constitutive.gp.formula import formula

        genome = genome_from_code(solution, self.spec.searched)
        return "" if genome is None else formula(with_values(genome, parameters))

    def simplify(
        self, candidate: CandidateRecord, options: ConstitutiveOptions
    ) -> Simplified | None:
        """A genetic-programming law with the terms whose removal costs less than the noise
        dropped (see :mod:`tasks.constitutive.simplify`); a model's law is not simplified."""
        found = self._simplified(candidate, options)
        if found is not None:  # its code without the genome tag
            found.solution = self.solution_with_parameters(found.solution, {})
        return found

    def _simplified(self, candidate: CandidateRecord, options: Any) -> Simplified | None:
        """:meth:`simplify`'s law, each drop scored as this task scores a candidate."""
        from tasks.constitutive.assessment import simplified

        return simplified(self.spec, candidate, options)

    def solution_size(self, candidate: CandidateRecord) -> int | None:
        """The operations of the captured law that do more than lay data out."""
        from tasks.constitutive.law_graph import captured_graph, law_size

        return law_size(captured_graph(candidate.artifacts()))

    def describe_assessment(self, simulate: bool) -> str:
        return "assessing the best solution: the true law's loss (cached after the first time)" + (
            " and the free runs on the training and the held-out scene (the first run compiles "
            "Taichi's kernels and simulates the held-out ground truth: up to two minutes), then "
            "the forms that fit as well on four probe scenes"
            if simulate
            else ""
        )

    def screen_lines(self, findings: dict[str, Any]) -> list[str]:
        """The best law's free-run errors on the training and the held-out scene."""
        return report.free_run_screen_lines(findings)

    def summary_lines(self, view: ReportView) -> list[str]:
        """The best law's free-run errors in body sizes, training and held-out scene."""
        return report.free_run_line(view.assessment, view.simulate)

    def report_sections(self, view: ReportView) -> list[Section]:
        """The observation against the best law's free run (PNG and GIF)."""
        return [report.motion_section(view)] if self.draws_motion else []

    def builtin_proposer(self) -> BuiltinProposer:
        """Genetic programming over law code (no model needed)."""
        from tasks.constitutive.gp import GeneticProgrammingProposer

        return GeneticProgrammingProposer(self.spec.searched)


class ElasticTask(ConstitutiveTask):
    """(a) Non-linear elasticity from a linear seed."""

    #: An elastic pair's screen starts both moduli at one stiffness; one epoch on one segment
    #: (0.1) ranked the neo-Hookean pair twentieth of 40 and the default search ended 17x
    #: above the fitted truth, one epoch on two segments ranks well enough (3x).
    opening_screen = 0.2
    #: Its pairs' screens cost twice the plastic forms'; the first 20 hold the pairs its default
    #: search fits best (the second, and neo-Hookean's, the eighth). With 40 the default command
    #: took 188.6 s at seed 1, with 20 122.3 s, the same best (``discovery.py --budget none``).
    opening_answers = 20

    def __init__(self) -> None:
        super().__init__(SPECS["elastic"])


class PlasticineTask(ConstitutiveTask):
    """(b) von Mises plasticity."""

    def __init__(self) -> None:
        super().__init__(SPECS["plasticine"])


class GranularTask(ConstitutiveTask):
    """(c) Drucker-Prager sand."""

    def __init__(self) -> None:
        super().__init__(SPECS["granular"])


class FluidTask(ConstitutiveTask):
    """(d) Weakly compressible fluid."""

    def __init__(self) -> None:
        super().__init__(SPECS["fluid"])


class ImaginaryTask(ConstitutiveTask):
    """A mixture: 0.5 von Mises + 0.3 sand + 0.2 fluid."""

    def __init__(self) -> None:
        super().__init__(SPECS["imaginary"])
