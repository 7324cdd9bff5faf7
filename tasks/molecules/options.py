"""The options of the molecule tasks (``--option KEY=VALUE``); plain data."""

from __future__ import annotations

import math
from dataclasses import dataclass

from tasks.molecules.constants import DEFAULT_STRAIN_WEIGHT


@dataclass(frozen=True)
class MoleculeOptions:
    """``strain_weight``: conformer-loss weight per kcal/mol of strain."""

    strain_weight: float = DEFAULT_STRAIN_WEIGHT

    def __post_init__(self) -> None:
        if not (math.isfinite(self.strain_weight) and self.strain_weight >= 0):
            raise ValueError(
                f"option 'strain_weight' must be a finite number >= 0, got {self.strain_weight}"
            )
