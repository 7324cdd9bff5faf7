"""The constitutive-law tasks as :class:`sga_agent.task.Task` objects.

Listing a task or building its prompt imports neither Taichi nor torch; only ``evaluate``
does (inside the sandbox worker).
"""

from __future__ import annotations

from sga_agent.task import BuiltinProposer, Evaluation, EvaluationSettings, PromptParts
from tasks.constitutive import prompt_text
from tasks.constitutive.specs import SPECS, ConstitutiveSpec


class ConstitutiveTask:
    """Search a constitutive law that reproduces an observed MPM trajectory."""

    kind = "equation"

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

    def evaluate(self, solution: str, settings: EvaluationSettings) -> Evaluation:
        from tasks.constitutive.evaluation import evaluate

        return evaluate(self.spec, solution, settings)

    def builtin_proposer(self) -> BuiltinProposer:
        """Genetic programming over law code (no model needed)."""
        from tasks.constitutive.gp import GeneticProgrammingProposer

        return GeneticProgrammingProposer(self.spec.searched)


class ElasticTask(ConstitutiveTask):
    """(a) Non-linear elasticity from a linear seed."""

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
