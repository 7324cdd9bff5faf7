"""The prompt of the ``observed`` task: the scene and the data from the observation file, the
known elastic law when the plastic part is searched; never the material behind the data."""

from __future__ import annotations

import numpy as np

from sga_agent.task import PromptParts
from tasks.constitutive import prompt_text
from tasks.observed.data import ObservedData
from tasks.observed.options import ObservedOptions

_ELASTIC_NAMES = {
    "stvk": "St. Venant-Kirchhoff on the Hencky strain",
    "neohookean": "neo-Hookean", "elastic": "neo-Hookean",
    "corotated": "fixed corotated", "linear": "linear (small-strain) elasticity",
}  # fmt: skip


def _vector(values: np.ndarray) -> str:
    return "(" + ", ".join(f"{value:.3g}" for value in values) + ")"


def scene_text(data: ObservedData) -> str:
    """The scene, the observed data and how a proposal is scored."""
    facts = data.describe()
    times = facts["times"]
    walls = facts["walls"]
    friction = f" with friction {walls.friction:g}" if walls.kind == "separate" else ""
    return (
        f"A body of {facts['particles']} material points (extent {_vector(facts['extent'])} m, "
        f"centre {_vector(facts['centre'])} m, density {facts['density']:g} kg/m^3) starts "
        f"in a cubic box of side {facts['domain']:g} m with a mean velocity of "
        f"{_vector(facts['velocity'])} m/s and an angular velocity of "
        f"{_vector(facts['spin'])} rad/s, under gravity {_vector(facts['gravity'])} m/s^2, "
        f"between {walls.kind} walls{friction} {walls.thickness} grid cells thick. A "
        f"differentiable material point method ({facts['grid']}^3 grid) simulates it for "
        f"{facts['steps']} steps of {facts['dt']:g} s ({facts['steps'] * facts['dt']:.4g} s). "
        f"The data: positions of {facts['observed']} of the {facts['particles']} points "
        f"at {facts['frames']} moments from t = {times[0]:.4g} s to {times[-1]:.4g} s "
        "(nothing else: no velocities, no deformation, no stresses). There is no teacher "
        "forcing: the simulation runs from the initial state to the end without being reset "
        "to observed states, so an error early in the motion carries on. A proposal is scored "
        "by the mean squared distance (m^2) between simulated and observed positions over the "
        "observed moments and points, after its continuous parameters have been fitted by "
        "gradient descent through the whole simulation."
    )


def prompt_parts(data: ObservedData, options: ObservedOptions) -> PromptParts:
    """Role, context, template and rules for the searched part of the law."""
    scene = scene_text(data)
    if options.searched == "elastic":
        return PromptParts(
            role=prompt_text.ROLE,
            context=scene + " Treat the material as purely elastic. Find the elastic "
            "constitutive law: the function mapping the deformation gradient F to the Kirchhoff "
            "stress tau = P F^T (P the first Piola-Kirchhoff stress), and its parameters.",
            template=prompt_text.ELASTIC_TEMPLATE,
            requirements=prompt_text.ELASTIC_RULES,
        )
    return PromptParts(
        role=prompt_text.ROLE,
        context=scene + f" The elastic response is known: {_ELASTIC_NAMES[options.elastic]} "
        f"with Young's modulus {options.E:g} Pa and Poisson's ratio {options.nu:g}. Find the "
        "plastic part: the return mapping from the trial deformation gradient F to the "
        "corrected deformation gradient, and its material parameters (the elastic law is then "
        "applied to the corrected F).",
        template=prompt_text.PLASTIC_TEMPLATE,
        requirements=prompt_text.PLASTIC_RULES,
    )
