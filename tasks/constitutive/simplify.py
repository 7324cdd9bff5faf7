"""The winning law with the terms the data do not need dropped.

A law written by the built-in genetic programming is a sum of terms, each scaled by its own
coefficient (``Genome``). A term whose coefficient, set to zero, leaves the loss within the
noise of the best (:func:`sga_agent.task.within_noise`) is a term the observation does not
ask for: the sand's law found with an extra cylinder, an elastic law with a third term at 1 %
of the stiffness. Terms are tried one at a time, the others kept at their fitted values, each
drop kept while the loss stays within the noise; nothing is refitted, so what is dropped is
dropped at no cost the data can see. The simplified law is printed from its genome (text
only), as code and as a formula; its losses come from the captured graph of the winner, never
from running code. A law a model wrote has no genome: it is not simplified.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import replace

from sga_agent.task import Simplified, within_noise
from tasks.constitutive.gp.codegen import genome_from_code, law_code, parameter_names, with_values
from tasks.constitutive.gp.formula import formula
from tasks.constitutive.gp.genome import Genome, params

#: A raw coefficient that makes its term vanish, by the coefficient's transform: exp(-50) and
#: sigmoid(-50) are 2e-22 (0 in float32 against any modulus or weight), a unit weight 0.
ZERO = {"log": -50.0, "sigmoid": -50.0, "unit": 0.0}
#: The fewest terms a law keeps: an elastic law needs a stress, a plastic one may return F.
LEAST_TERMS = {"elastic": 1, "plastic": 0}
#: The fewest terms of a law that is simplified at all. Fewer are the parts every law of its
#: kind has (an elastic law's shear and volume parts, as mu (b - I) + lam log(J) I; a plastic
#: law's one return): trying them would cost a scored rollout each (seconds) for nothing.
SIMPLIFIED_FROM = {"elastic": 3, "plastic": 2}


def coefficient_names(genome: Genome) -> list[str]:
    """The name of each term's coefficient, in the order of the terms."""
    names = parameter_names(genome)
    return [name for (_, path, _), name in zip(params(genome), names, strict=True) if path is None]


def simplify(
    code: str,
    kind: str,
    parameters: Mapping[str, float],
    loss_of: Callable[[dict[str, float]], float],
    floor: float | None = None,
) -> Simplified | None:
    """The law of ``code`` (a genetic-programming law of ``kind``; None for any other) at its
    fitted ``parameters`` with each term dropped whose removal keeps ``loss_of(parameters)``
    within the noise of its loss there (``floor``: the task's own floor); None when no term
    can go or the law has fewer than :data:`SIMPLIFIED_FROM` terms. Its code is written from
    the genome, the genome in its comment (the task's ``solution_with_parameters`` takes it
    out)."""
    genome = genome_from_code(code, kind)
    if genome is None or len(genome.terms) < SIMPLIFIED_FROM[kind]:
        return None
    base = loss_of(dict(parameters))
    band = within_noise([base], floor)
    current, loss, dropped = dict(parameters), base, []
    for index, name in enumerate(coefficient_names(genome)):
        if len(genome.terms) - len(dropped) <= LEAST_TERMS[kind]:
            break
        transform = genome.terms[index].coefficient.transform
        trial = current | {name: ZERO[transform]}
        trial_loss = loss_of(trial)
        if trial_loss <= band:
            current, loss = trial, trial_loss
            dropped.append(index)
    if not dropped:
        return None
    names = coefficient_names(genome)
    kept = tuple(term for index, term in enumerate(with_values(genome, parameters).terms)
                 if index not in dropped)  # fmt: skip
    simpler = replace(genome, terms=kept)
    return Simplified(law_code(simpler), [f"the term scaled by {names[i]}" for i in dropped],
                      loss, base, band, formula(simpler))  # fmt: skip
