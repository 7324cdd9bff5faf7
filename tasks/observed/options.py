"""The options of the ``observed`` task (``--option KEY=VALUE``): the observation file, what is
searched and the known elastic law; plain data, checked when the options are parsed."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

if TYPE_CHECKING:
    from taichi_mpm.sysid.observation import Observation

#: taichi_mpm's elastic laws by their system-identification family names.
ElasticFamily = Literal["stvk", "neohookean", "elastic", "corotated", "linear"]


@dataclass(frozen=True)
class ObservedOptions:
    """``observation``: the ``.npz`` file (format of :mod:`taichi_mpm.sysid.observation`), made
    absolute; it is read and checked here, so a bad file is a usage error before anything runs.
    ``searched``: ``elastic`` (F to Kirchhoff stress) or ``plastic`` (the return mapping, the
    elastic law then known: family ``elastic`` with Young's modulus ``E`` (Pa) and Poisson's
    ratio ``nu``). ``frames``: fit only the first this many observed frames after t = 0
    (default all). ``segment``: the most steps per checkpointed segment of the backward pass;
    ``graph_memory_mb``: what the gradient may hold at once (a segment's autograd graph and
    the state at each segment's start, in MiB): segments are shortened to fit it, measured on
    each law, and a law that cannot fit it is reported with the options to change.
    ``optimizer`` and ``precision`` as in the constitutive tasks. ``validation``: a second
    observation (``.npz``) of the same material in another scene, never fitted: the best law's
    free run there is its held-out error; checked here too (readable, not the observation
    itself, the same density, and the same hidden truth where both files have one)."""

    observation: str | None = None
    searched: Literal["elastic", "plastic"] | None = None
    elastic: ElasticFamily = "stvk"
    E: float | None = None
    nu: float | None = None
    frames: int | None = None
    segment: int = 50
    graph_memory_mb: float = 1000.0
    optimizer: Literal["adam", "lbfgs"] | None = None
    precision: Literal["float32", "float64"] | None = None
    validation: str | None = None

    def __post_init__(self) -> None:
        from tasks.observed.data import read_observation

        if self.observation is None:
            raise ValueError("option 'observation' is required: the .npz file of the observed "
                             "motion (see taichi_mpm.sysid.save_observation)")  # fmt: skip
        if self.searched is None:
            raise ValueError("option 'searched' is required: elastic or plastic")
        path = Path(self.observation).expanduser().resolve()
        object.__setattr__(self, "observation", str(path))
        try:
            observation = read_observation(path)
        except ValueError as error:  # the sysid loader's ObservationError
            raise ValueError(f"option 'observation': {error}") from None
        available = int((observation.frame_steps > 0).sum())
        if self.frames is not None and not 2 <= self.frames <= available:
            raise ValueError(f"option 'frames' must lie in [2, {available}] (the observed "
                             f"frames after t = 0), got {self.frames}")  # fmt: skip
        if self.segment < 1:
            raise ValueError(f"option 'segment' must be at least 1, got {self.segment}")
        if not self.graph_memory_mb > 0:
            raise ValueError("option 'graph_memory_mb' must be a positive number of MiB, got "
                             f"{self.graph_memory_mb}")  # fmt: skip
        self._check_elastic()
        if self.validation is not None:
            object.__setattr__(self, "validation", self._checked_validation(observation))

    def _checked_validation(self, observation: Observation) -> str:
        """The validation file's absolute path, once it is checked against ``observation``."""
        from tasks.observed.data import read_observation, read_truth

        path = Path(self.validation).expanduser().resolve()
        if str(path) == self.observation:
            raise ValueError("option 'validation' names the observation itself: give a second "
                             "observation of the same material in another scene")  # fmt: skip
        try:
            validation = read_observation(path)
        except ValueError as error:  # the sysid loader's ObservationError
            raise ValueError(f"option 'validation': {error}") from None
        if not (validation.frame_steps > 0).any():
            raise ValueError(f"option 'validation': {path} has no frame after t = 0 to compare "
                             "a free run with")  # fmt: skip
        if validation.scene.density != observation.scene.density:
            raise ValueError(
                f"option 'validation': {path} has density {validation.scene.density:g} kg/m^3, "
                f"the observation {observation.scene.density:g}: a validation file must observe "
                "the same material"
            )
        truths = read_truth(self.observation), read_truth(path)
        if None not in truths and truths[0] != truths[1]:
            raise ValueError(
                f"option 'validation': the hidden truth beside {path.name} ({truths[1]}) is not "
                f"the observation's ({truths[0]}): a validation file must observe the same "
                "material"
            )
        return str(path)

    def _check_elastic(self) -> None:
        given = [name for name in ("E", "nu") if getattr(self, name) is not None]
        if self.searched == "elastic":
            if given:
                raise ValueError(f"option(s) {', '.join(given)} describe the known elastic law: "
                                 "give them only with searched=plastic")  # fmt: skip
            return
        if len(given) < 2:
            raise ValueError("searched=plastic needs the known elastic law: options E (Young's "
                             "modulus, Pa) and nu (Poisson's ratio), and elastic=FAMILY "
                             "(default stvk)")  # fmt: skip
        from taichi_mpm.sysid.families import material_family

        material_family(self.elastic, E=self.E, nu=self.nu)  # MaterialError for bad values
