"""The four molecule-design tasks of the paper (e)-(h) as :class:`sga_agent.task.Task` plugins."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from sga_agent.task import (
    Block,
    BuiltinProposer,
    CandidateRecord,
    Evaluation,
    EvaluationSettings,
    PromptParts,
    ReportView,
    Section,
    TaskBase,
    TaskKind,
)
from tasks.molecules import prompt_text, report
from tasks.molecules.calibration import PROPERTY_LABELS
from tasks.molecules.constants import DEFAULT_STEPS, DEFAULT_STRAIN_WEIGHT
from tasks.molecules.options import MoleculeOptions
from tasks.molecules.solution import check_solution

SEED_SOLUTION = """\
# Paracetamol (N-(4-hydroxyphenyl)acetamide): an amide-substituted phenol.
SMILES: str = "CC(=O)Nc1ccc(O)cc1"  # 11 heavy atoms: C C O N C C C C O C C

coordinates: list[list[float]] = [  # (11, 3) heavy-atom positions in Angstrom, SMILES order
    [4.002, 0.387, -0.208],  # 0 C (methyl)
    [2.543, 0.746, -0.350],  # 1 C (carbonyl)
    [2.209, 1.840, -0.792],  # 2 O
    [1.710, -0.265, 0.092],  # 3 N
    [0.300, -0.271, 0.111],  # 4 C (aromatic, N-bound)
    [-0.492, 0.785, -0.346],  # 5 C
    [-1.888, 0.702, -0.295],  # 6 C
    [-2.491, -0.442, 0.214],  # 7 C (aromatic, O-bound)
    [-3.846, -0.563, 0.282],  # 8 O (hydroxyl)
    [-1.721, -1.502, 0.672],  # 9 C
    [-0.327, -1.417, 0.620],  # 10 C
]
"""


class MoleculeTask(TaskBase):
    """Design a molecule whose normalized HOMO, LUMO or gap hits a target value.

    Parameters
    ----------
    name : str
        Registry name of the task.
    prop : str
        ``"homo"``, ``"lumo"`` or ``"gap"``.
    target : float
        Target of the property in QM9 standard deviations from the QM9 mean.
    """

    kind: TaskKind = "entity"
    options_type = MoleculeOptions
    loss_label = report.LOSS_LABEL

    def __init__(self, name: str, prop: str, target: float) -> None:
        if prop not in PROPERTY_LABELS:
            raise ValueError(f"unknown property {prop!r}")
        self.name = name
        self.prop = prop
        self.target = float(target)
        self.description = (
            f"Molecule design: normalized {PROPERTY_LABELS[prop]} = {self.target:g} "
            "(QM9 scale, GFN1-xTB calibrated)"
        )

    def seed_solution(self) -> str:
        """A valid starting molecule (paracetamol) in the task's code format."""
        return SEED_SOLUTION

    def prompt_parts(self) -> PromptParts:
        """Role, context, code skeleton and rules for this target."""
        return PromptParts(
            role=prompt_text.ROLE,
            context=prompt_text.context(
                self.prop, self.target, DEFAULT_STEPS, DEFAULT_STRAIN_WEIGHT
            ),
            template=prompt_text.TEMPLATE,
            requirements=prompt_text.REQUIREMENTS,
        )

    def check_solution(self, code: str) -> None:
        """Only literal assignments, among them SMILES and coordinates (nothing is run)."""
        check_solution(code)

    def capture(self, solution: str) -> dict[str, Any]:
        """The solution's text: it is data already (read with ``ast``, never executed)."""
        return {"solution": solution}

    def evaluate(self, data: dict[str, Any], settings: EvaluationSettings) -> Evaluation:
        """Score the captured solution (see :func:`.evaluation.evaluate_solution`)."""
        from tasks.molecules.evaluation import evaluate_solution

        solution = data.get("solution") if isinstance(data, dict) else None
        if not isinstance(solution, str):
            return Evaluation.invalid("the captured solution is not text", status="error")
        return evaluate_solution(solution, self.prop, self.target, settings)

    def builtin_proposer(self) -> BuiltinProposer:
        """The LLM-free graph-GA proposer ("builtin:ga"), falling back on this task's seed."""
        from tasks.molecules.ga import GraphGAProposer

        return GraphGAProposer(self.seed_solution())

    def solution_key(self, candidate: CandidateRecord) -> str | None:
        """The molecule's SMILES, as evaluated."""
        smiles = candidate.extras.get("smiles")
        return f"smiles:{smiles}" if smiles else None

    def top_facts(self, candidates: Sequence[CandidateRecord]) -> list[dict[str, Any]]:
        """Each top molecule's property on the QM9 scale and its distance to the target."""
        return report.top_facts(candidates)

    def screen_lines(self, findings: dict[str, Any]) -> list[str]:
        """The best molecule's SMILES and its property (normalized, in Hartree and eV)."""
        return report.screen_lines(findings)

    def summary_blocks(self, view: ReportView) -> list[Block]:
        """The table of the top molecules."""
        return report.summary_blocks(view)

    def report_sections(self, view: ReportView) -> list[Section]:
        """2D depictions of the top molecules."""
        return [report.pictures_section(view)]

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r})"


class HomoTask(MoleculeTask):
    """(e) normalized HOMO = 0."""

    def __init__(self) -> None:
        super().__init__("homo", "homo", 0.0)


class LumoTask(MoleculeTask):
    """(f) normalized LUMO = 0."""

    def __init__(self) -> None:
        super().__init__("lumo", "lumo", 0.0)


class GapTask(MoleculeTask):
    """(g) normalized HOMO-LUMO gap = 0."""

    def __init__(self) -> None:
        super().__init__("gap", "gap", 0.0)


class GapLowTask(MoleculeTask):
    """(h) normalized HOMO-LUMO gap = -2."""

    def __init__(self) -> None:
        super().__init__("gap-low", "gap", -2.0)
