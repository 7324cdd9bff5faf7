"""The inner optimization: Adam on atomic positions towards a target property value.

Per step, GFN1-xTB gives the smooth HOMO/LUMO (hence the normalized property ``p``) and the total
energy ``E`` of the current positions; the objective minimized is

    (p - target)^2 + strain_weight * E   (E in kcal/mol)

whose energy term is the xTB force pulling the structure back towards a minimum, so the target is
not reached by tearing the molecule apart. After the loop every step is scored with the same
losses reported to the search:

* property loss  = (p - target)^2  (squared distance in QM9 standard deviations),
* conformer loss = strain_weight * strain, with strain = E - min(E over the run) in kcal/mol
  (the energy above the lowest-energy geometry met, starting point included),
* total          = property loss + conformer loss,

and the best step (lowest total) is the result. Measuring strain from the run's own minimum makes
it non-negative and independent of how far from an xTB minimum the start was.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import torch

from sga_agent.task import report_progress
from tasks.molecules.calibration import PROPERTIES, normalized_property
from tasks.molecules.constants import (
    DEFAULT_LEARNING_RATE,
    DEFAULT_STEPS,
    DEFAULT_STRAIN_WEIGHT,
)
from tasks.molecules.geometry import Structure
from tasks.molecules.xtb import (
    BOHR_PER_ANGSTROM,
    DTYPE,
    HARTREE_IN_KCAL_MOL,
    GFN1Model,
    XtbError,
    XtbPoint,
)


@dataclass(frozen=True)
class Objective:
    """What the inner loop aims for: a normalized property value and the strain price."""

    prop: str
    target: float
    strain_weight: float = DEFAULT_STRAIN_WEIGHT

    def __post_init__(self) -> None:
        if self.prop not in PROPERTIES:
            raise ValueError(f"unknown property {self.prop!r}; expected one of {PROPERTIES}")
        if not self.strain_weight >= 0:
            raise ValueError("strain_weight must be non-negative")

    def normalized(self, point: XtbPoint) -> torch.Tensor:
        """The normalized (QM9-scale) value of the objective's property at ``point``."""
        gfn1 = {"homo": point.homo, "lumo": point.lumo, "gap": point.gap}[self.prop]
        return normalized_property(self.prop, gfn1)


@dataclass
class StepRecord:
    """One evaluated geometry of the run (values as floats; energies in Hartree)."""

    positions: np.ndarray
    property: float
    homo: float
    lumo: float
    energy: float


@dataclass
class Trajectory:
    """All evaluated geometries of a run, step 0 being the starting structure."""

    objective: Objective
    records: list[StepRecord] = field(default_factory=list)
    stopped: str = ""
    steps_requested: int = 0

    @property
    def strain(self) -> np.ndarray:
        """Strain (kcal/mol) of each step: energy above the run's lowest energy."""
        energy = np.array([r.energy for r in self.records])
        return (energy - energy.min()) * HARTREE_IN_KCAL_MOL

    @property
    def property_loss(self) -> np.ndarray:
        """Squared distance of the normalized property to the target, per step."""
        values = np.array([r.property for r in self.records])
        return (values - self.objective.target) ** 2

    @property
    def conformer_loss(self) -> np.ndarray:
        """Strain weight times strain, per step."""
        return self.objective.strain_weight * self.strain

    @property
    def total_loss(self) -> np.ndarray:
        """Property loss plus conformer loss, per step."""
        return self.property_loss + self.conformer_loss

    @property
    def best(self) -> int:
        """Index of the step with the lowest total loss."""
        return int(np.argmin(self.total_loss))


def run_inner_loop(
    structure: Structure,
    objective: Objective,
    steps: int = DEFAULT_STEPS,
    learning_rate: float = DEFAULT_LEARNING_RATE,
    model: GFN1Model | None = None,
) -> Trajectory:
    """Optimize all atomic positions (hydrogens included) with Adam for ``steps`` steps.

    The starting structure is evaluated first (step 0), then each Adam step's new geometry, so a
    run has ``steps + 1`` records unless xTB fails part-way (``Trajectory.stopped`` then says
    why and the records so far are kept).

    Raises
    ------
    XtbError
        xTB fails on the starting structure.
    """
    model = model or GFN1Model(structure.numbers.tolist())
    positions = torch.tensor(structure.positions, dtype=DTYPE, requires_grad=True)
    optimizer = torch.optim.Adam([positions], lr=learning_rate)
    trajectory = Trajectory(objective=objective, steps_requested=steps)
    for step in range(steps + 1):
        last = step == steps
        try:
            with torch.set_grad_enabled(not last):
                point = model(positions * BOHR_PER_ANGSTROM)
                value = objective.normalized(point)
        except XtbError as error:
            if step == 0:
                raise
            trajectory.stopped = f"xTB failed at step {step} ({error}); the run stopped there"
            break
        trajectory.records.append(
            StepRecord(
                positions=positions.detach().numpy().copy(),
                property=float(value.detach()),
                homo=float(point.homo.detach()),
                lumo=float(point.lumo.detach()),
                energy=float(point.energy.detach()),
            )
        )
        report_progress("optimizing the geometry", step + 1, steps + 1)
        if last:
            break
        loss = (value - objective.target) ** 2
        loss = loss + objective.strain_weight * HARTREE_IN_KCAL_MOL * point.energy
        optimizer.zero_grad()
        loss.backward()
        if positions.grad is None or not torch.isfinite(positions.grad).all():
            trajectory.stopped = f"non-finite gradient at step {step}; the run stopped there"
            break
        optimizer.step()
    if not all(math.isfinite(r.property) for r in trajectory.records):  # pragma: no cover
        raise XtbError("non-finite property value")
    return trajectory
