"""Whether the data determine a solution's form: the record of :meth:`TaskBase.compare_forms`.

A search can end with several distinct forms that fit the observation equally well. A task
that can simulate its solutions elsewhere runs each of them on probe scenes it defines (never
its held-out scene) and measures how far their predictions spread. Where they disagree, the
observation did not determine the law, and the probe that separates them best is the
experiment that would; where they agree, the forms differ in writing, not in what they predict.

Standard library only, as the rest of the protocol package.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

#: A distinct form fits "equally" when its loss is at most this many times the larger of the
#: best loss and the task's noise floor: its misfit is then no larger than what is left at
#: the best, the noise (for a noisy observation) or the precision (for an exact one).
NOISE_BAND = 2.0


@dataclass(frozen=True)
class Probe:
    """A scene the task can simulate a solution in: a short ``name`` for sentences ("a
    stronger impact"), ``text`` that lets a user set the same experiment up (shape, size,
    initial velocity, duration) and the ``file`` it was written to ("" when none was)."""

    name: str
    text: str
    file: str = ""


@dataclass
class FormComparison:
    """What :meth:`TaskBase.compare_forms` found.

    Parameters
    ----------
    forms : list of str
        The candidates of the distinct forms that fit within the noise of the best, best
        first (only the best's when no other does).
    losses : list of float
        Their losses.
    band : float
        The loss below which a form counted as fitting equally.
    next_ratio : float, optional
        The next distinct form's loss over the best's, when only the best fits.
    spreads : dict of str to float
        By probe name: the largest distance between two forms' simulated motions at any step,
        RMS over particles, in body sizes (inf where some but not all of them were unstable).
    threshold : float
        The spread above which the forms disagree.
    probe : Probe, optional
        The probe with the largest spread, when they disagree.
    """

    forms: list[str]
    losses: list[float]
    band: float
    next_ratio: float | None = None
    spreads: dict[str, float] = field(default_factory=dict)
    threshold: float = 0.05
    probe: Probe | None = None

    @property
    def determined(self) -> bool:
        """Whether the data single out the form, or the forms that fit agree on every probe."""
        return all(spread <= self.threshold for spread in self.spreads.values())

    @property
    def largest_spread(self) -> float:
        return max(self.spreads.values(), default=0.0)

    @property
    def sentence(self) -> str:
        """The finding in one sentence, for the end screen and the report."""
        count = len(self.forms)
        if count < 2:
            ratio = f"{self.next_ratio:.3g}x" if self.next_ratio is not None else "far above"
            return (f"the observation singles out the best form: the next distinct form's loss "
                    f"is {ratio} the best's")  # fmt: skip
        fitting = (f"{count} distinct forms fit it within the noise (losses "
                   f"{self.losses[0]:.3g} to {self.losses[-1]:.3g}, at most {self.band:.3g})")
        if self.determined:
            names = ", ".join(self.spreads)
            return (f"the observation determines the motion: {fitting} and agree on "
                    f"{len(self.spreads)} probe scenes ({names}) to within "
                    f"{_percent(self.largest_spread)} of the body size")  # fmt: skip
        probe = self.probe
        if probe is None:  # spreads disagree but no probe was named: only from a bad record
            return f"the observation does not determine the law: {fitting}"
        differ = (f"one of them is unstable under {probe.name}"
                  if math.isinf(self.spreads[probe.name])
                  else f"their motions differ by up to {_percent(self.spreads[probe.name])} of "
                       f"the body size under {probe.name}")  # fmt: skip
        where = f" (scene file {probe.file})" if probe.file else ""
        return (f"the observation does not determine the law: {fitting}, and {differ}; "
                f"observing {probe.text}{where} would separate them")  # fmt: skip

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (an infinite spread as the string "inf")."""
        return {
            "determined": self.determined, "sentence": self.sentence, "forms": self.forms,
            "losses": self.losses, "band": self.band, "next_ratio": self.next_ratio,
            "spreads": {name: _encode(value) for name, value in self.spreads.items()},
            "threshold": self.threshold,
            "probe": None if self.probe is None else vars(self.probe),
        }  # fmt: skip


def within_noise(losses: Sequence[float], floor: float | None = None) -> float:
    """The loss below which a distinct form fits as well as the best (the first of
    ``losses``): :data:`NOISE_BAND` times the larger of the best and ``floor``."""
    best = losses[0] if losses else math.inf
    return NOISE_BAND * max(best, floor or 0.0)


def compared(
    forms: Sequence[str],
    losses: Sequence[float],
    band: float,
    spreads: Mapping[str, float],
    probes: Mapping[str, Probe],
    threshold: float,
) -> FormComparison:
    """The comparison of the distinct ``forms`` (best first, with their ``losses``; those
    within ``band`` were simulated on ``probes``, giving ``spreads``)."""
    fitting = [(form, loss) for form, loss in zip(forms, losses, strict=True) if loss <= band]
    next_ratio = None
    if len(fitting) < 2 and len(losses) > 1 and losses[0] > 0:
        next_ratio = losses[1] / losses[0]
    usable = {name: value for name, value in spreads.items() if not math.isnan(value)}
    separating = max(usable, key=usable.__getitem__, default=None)
    probe = probes[separating] if separating and usable[separating] > threshold else None
    return FormComparison([form for form, _ in fitting], [loss for _, loss in fitting], band,
                          next_ratio, dict(usable), threshold, probe)  # fmt: skip


def _percent(fraction: float) -> str:
    return f"{100 * fraction:.2g} %" if fraction >= 1e-4 else "less than 0.01 %"


def _encode(value: float) -> float | str:
    return value if math.isfinite(value) else str(value)
