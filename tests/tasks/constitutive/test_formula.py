"""A genetic-programming law as one formula: its sums, scalings and blends collected by SymPy,
its other blocks kept whole, its fitted values in."""

from __future__ import annotations

import math
import random
from pathlib import Path

import pytest
import sympy

from sga_agent.registry import load_task
from tasks.constitutive.gp.codegen import law_code, parameter_names
from tasks.constitutive.gp.formula import expression, formula
from tasks.constitutive.gp.genome import Genome, Node, Param, Term, random_genome
from tasks.constitutive.gp.grammar import MATRIX, OPS, PARAM, PRINCIPAL, SCALAR, WEIGHT

EPS = Node("eps")
CONE = Node("from_strain", (Node("cone", (EPS, Node("const", (Param("log", math.log(0.3)),)))),))
VOLUME = Node("from_strain", (Node("vol", (EPS,)),))


def logit(weight: float) -> Param:
    return Param("sigmoid", math.log(weight / (1 - weight)))


def test_a_plastic_law_reads_as_the_weights_of_f_and_of_each_correction():
    """F + 0.6 (G1 - F) + 0.1 (G2 - F) is 0.3 F + 0.6 G1 + 0.1 G2."""
    law = Genome("plastic", (Term(logit(0.6), VOLUME), Term(logit(0.1), CONE)))
    assert formula(law) == (
        "F_corrected = 0.3*F + 0.1*U diag(exp(cone_return(eps, 0.3))) Vh"
        " + 0.6*U diag(exp(vol(eps))) Vh"
    )


def test_a_weight_of_one_and_a_cancelled_f_are_written_away():
    """A correction that replaces F is the correction alone; a mixture whose weights sum to 1
    keeps no F, however the floating point rounds 1 - 0.5 - 0.3 - 0.2."""
    assert formula(Genome("plastic", (Term(Param("unit", 1.2), CONE),))) == (
        "F_corrected = U diag(exp(cone_return(eps, 0.3))) Vh"
    )
    mixture = Genome("plastic", (Term(logit(0.5), VOLUME), Term(logit(0.3), CONE),
                                 Term(logit(0.2), Node("I"))))  # fmt: skip
    written = formula(mixture)
    assert "*F" not in written and "F +" not in written, written
    assert "0.2*I" in written and "0.5*U" in written


def test_an_elastic_law_adds_equal_parts_and_keeps_the_order_of_products():
    """Two terms of b add their moduli; F b and b F are different matrices."""
    twice = Genome("elastic", (Term(Param("log", math.log(2e5)), Node("b")),
                               Term(Param("log", math.log(3e5)), Node("b"))))  # fmt: skip
    assert formula(twice) == "tau = sym(5e+05*b)"
    left = Node("matmul", (Node("F"), Node("b")))
    right = Node("matmul", (Node("b"), Node("F")))
    assert expression(left, MATRIX) != expression(right, MATRIX)
    both = Genome("elastic", (Term(Param("log", 0.0), left), Term(Param("log", 0.0), right)))
    assert formula(both) == "tau = sym(F*b + b*F)"


def test_a_blend_and_a_sum_of_the_same_block_collect():
    """blend(w, F, F) is F, whatever w: the arithmetic is SymPy's, not a string's."""
    same = Node("blend", (Param("sigmoid", 0.3), Node("F"), Node("F")))
    assert expression(same, MATRIX) == sympy.Symbol("F", commutative=False)
    doubled = Node("add", (Node("b"), Node("scale", (Param("linear", -1.0), Node("b")))))
    assert expression(doubled, MATRIX) == 0


LEAVES = {MATRIX: Node("F"), PRINCIPAL: EPS, SCALAR: Node("J"),
          PARAM: Param("linear", 0.5), WEIGHT: Param("sigmoid", 0.0)}  # fmt: skip


@pytest.mark.parametrize(
    ("value_type", "name"), [(t, name) for t, ops in OPS.items() for name in ops]
)
def test_every_operation_of_the_grammar_is_written(value_type, name):
    op = OPS[value_type][name]
    node = Node(name, tuple(LEAVES[arg] for arg in op.args))
    assert isinstance(expression(node, value_type), sympy.Basic)


@pytest.mark.parametrize("kind", ["elastic", "plastic"])
def test_every_random_law_of_the_grammar_has_a_formula_of_one_line(kind):
    rng = random.Random(3)
    for _ in range(200):
        written = formula(random_genome(rng, kind))
        assert "\n" not in written and written.startswith(("tau = sym(", "F_corrected = "))


def test_the_task_writes_a_formula_with_the_fitted_values_and_none_for_a_model_s_law():
    task = load_task("granular")
    law = Genome("plastic", (Term(Param("unit", 0.5), CONE),))
    code = law_code(law)
    weight, slope = parameter_names(law)
    fitted = task.formula(code, {weight: 1.0, slope: math.log(0.5)})
    assert fitted == "F_corrected = U diag(exp(cone_return(eps, 0.5))) Vh"
    example = Path(__file__).resolve().parents[3] / "examples" / "laws" / "drucker_prager.py"
    assert task.formula(example.read_text(), {}) == ""
