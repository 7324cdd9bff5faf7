"""The winning law simplified: terms whose removal costs less than the noise dropped, scored on
the captured graph (physics: a term a millionth of the stiffness changes no motion; dropping a
term that carries the stiffness does)."""

from __future__ import annotations

from dataclasses import replace

import pytest

from tasks.constitutive.gp.codegen import law_code
from tasks.constitutive.gp.enumeration import elastic_pairs
from tasks.constitutive.gp.genome import Genome, Param
from tasks.constitutive.simplify import coefficient_names, simplify

PAIR = elastic_pairs()[0]
#: The pair and a third term (the second pair's first), their moduli e^11 and e^10 Pa, the
#: third's e^-3 Pa.
THREE = Genome("elastic", (
    replace(PAIR.terms[0], coefficient=Param("log", 11.0)),
    replace(PAIR.terms[1], coefficient=Param("log", 10.0)),
    replace(elastic_pairs()[1].terms[0], coefficient=Param("log", -3.0)),
))  # fmt: skip


def test_a_term_whose_removal_stays_within_the_noise_is_dropped_and_the_others_kept():
    names = coefficient_names(THREE)
    assert names == ["log_modulus0", "log_modulus1", "log_modulus2"]
    fitted = {"log_modulus0": 11.5, "log_modulus1": 10.2, "log_modulus2": -3.0}
    scored = []

    def loss_of(parameters):  # the third term costs 1.5x to drop, the others 100x
        scored.append(parameters)
        return 1e-8 * (1.5 if parameters["log_modulus2"] == -50.0 else 1.0) * (
            100 if min(parameters["log_modulus0"], parameters["log_modulus1"]) == -50.0 else 1)

    found = simplify(law_code(THREE), "elastic", fitted, loss_of)
    assert found is not None and found.dropped == ["the term scaled by log_modulus2"]
    assert (found.base_loss, found.loss, found.band) == pytest.approx((1e-8, 1.5e-8, 2e-8))
    assert len(scored) == 4  # the loss at the fitted values, then one drop per term
    assert found.solution.count("log_modulus") > 0 and "log_modulus2" not in found.solution
    assert "log_modulus0: float = 11.5" in found.solution  # its fitted values written in
    assert found.sentence == ("1 of its parts costs less than the noise and is dropped (the term "
                              "scaled by log_modulus2): the loss goes from 1e-08 to 1.5e-08, "
                              "2e-08 at most")  # fmt: skip


def test_a_law_without_a_genome_or_without_a_term_to_spare_is_not_simplified():
    never = lambda parameters: pytest.fail("nothing is scored")  # noqa: E731
    model_law = "import torch\nclass Physics(torch.nn.Module):\n    pass\n"
    assert simplify(model_law, "elastic", {}, never) is None
    pair = Genome("elastic", THREE.terms[:2])
    assert simplify(law_code(pair), "elastic", {}, never) is None  # shear and volume: kept
    assert simplify(law_code(THREE), "plastic", {}, never) is None  # another kind's genome


@pytest.mark.slow
def test_a_term_a_millionth_of_the_stiffness_is_dropped_on_the_real_task():
    """On the elastic task (200 steps), each drop scored by the real teacher-forced loss of
    the captured graph: the e^-3 Pa term goes, both terms that carry the stiffness stay. The
    pair is Hencky's law, 2 mu eps + 3 lam mean(eps) I, at the Lame constants of the task's
    neo-Hookean truth (E = 4.42e5 Pa, nu = 0.245: 2 mu = 3.55e5 Pa, 3 lam = 5.12e5 Pa), which
    it matches at small strains: its loss is near the noise, so a drop that matters shows."""
    from sga_agent.registry import load_task
    from tasks.constitutive.options import ConstitutiveOptions
    from tests.tasks.constitutive.test_forms import Recorded

    task = load_task("elastic")
    code = law_code(THREE)
    fitted = {"log_modulus0": 12.78, "log_modulus1": 13.15, "log_modulus2": -3.0}
    candidate = Recorded("a", 1.0, task.capture(code), fitted, code=code)
    found = task.simplify(candidate, ConstitutiveOptions(steps=200))
    assert found is not None and found.dropped == ["the term scaled by log_modulus2"]
    assert found.loss <= found.band and found.loss == pytest.approx(found.base_loss, rel=1e-3)
    assert "# genome:" not in found.solution and "log_modulus2" not in found.solution
    compile(found.solution, "<simplified>", "exec")
