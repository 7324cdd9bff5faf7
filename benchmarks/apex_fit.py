"""Can the neighbourhood's shifted cone fit the cohesive sand once the plain cone is fitted?

On the ``observed-cohesive`` row's observation (``benchmarks/discovery.py``), fits the plain
Drucker-Prager form ``cone(eps, k)`` from the textbook slope of the observed sand (35 degrees,
nu = 0.3), then its first neighbour (:mod:`tasks.constitutive.gp.neighbourhood`: the cone with
its apex shifted, starting at 0) from the cone's fitted constants, each with the quick preset's
5 L-BFGS epochs, and prints both losses (the row's floor, the true law's loss, is 5.05e-6)::

    python benchmarks/apex_fit.py
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import discovery  # noqa: E402  (a sibling script)

from sga_agent.config import PRESETS  # noqa: E402
from sga_agent.options import parse_options  # noqa: E402
from sga_agent.registry import load_task  # noqa: E402
from sga_agent.task import EvaluationSettings, as_task, configured  # noqa: E402
from tasks.constitutive.gp.codegen import law_code, with_values  # noqa: E402
from tasks.constitutive.gp.genome import Genome, Node, Param, Term  # noqa: E402
from tasks.constitutive.gp.neighbourhood import neighbours  # noqa: E402

ROW = "observed-cohesive"
ANGLE, NU = 35.0, 0.3


def textbook_slope(angle: float, nu: float) -> float:
    """The cone's slope of Drucker-Prager sand at friction ``angle`` (degrees) with Poisson's
    ratio ``nu``: (3 lam + 2 mu) / (2 mu) sqrt(2/3) 2 sin(phi) / (3 - sin(phi))."""
    sin_phi = math.sin(math.radians(angle))
    stiffness = (1 + nu) / (1 - 2 * nu)  # (3 lam + 2 mu) / (2 mu)
    return stiffness * math.sqrt(2 / 3) * 2 * sin_phi / (3 - sin_phi)


def main() -> None:
    row = discovery.ROWS[ROW]
    files = discovery.observation_files(ROW, row)
    task = as_task(load_task(row.task))
    raw = dict(task.builtin_options) | row.options | files
    options = parse_options(task.options_type, raw, row.task)
    settings = EvaluationSettings(epochs=PRESETS["quick"]["epochs"], seed=0, options=options)
    task = configured(task, options)
    slope = Node("const", (Param("log", math.log(textbook_slope(ANGLE, NU))),))
    cone = Genome("plastic", (Term(Param("unit", 1.0), Node("from_strain", (
        Node("cone", (Node("eps"), slope)),))),))  # fmt: skip
    fitted = task.evaluate(task.capture(law_code(cone)), settings)
    shifted, _ = next(neighbours(with_values(cone, fitted.parameters)))
    moved = task.evaluate(task.capture(law_code(shifted)), settings)
    print(json.dumps({"cone": fitted.loss, "cone_parameters": fitted.parameters,
                      "shifted_cone": moved.loss, "shifted_parameters": moved.parameters}))


if __name__ == "__main__":
    main()
