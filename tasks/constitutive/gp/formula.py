"""A genetic-programming law as one formula, its arithmetic simplified with SymPy.

The code of a law (:mod:`.codegen`) names every intermediate value and writes each coefficient
as the transform of a raw parameter (``torch.exp(self.log_modulus0)``). Its formula writes the
law as one expression with the fitted values in: ``F_corrected = 0.306*F +
0.612*U diag(exp(vol(eps))) Vh + ...``. SymPy expands and collects the sums, scalings and
blends, so that a plastic law's ``F + w (G - F)`` reads as its weights of F and of each
correction, and equal parts written twice add up. The other operations (a return onto a yield
surface, a frame built from principal values) are kept whole, as named functions of their
arguments; matrices do not commute. What the code clamps for safety (the exponent of a strain,
the strain's singular values) is left out: the formula says what the law does, the code how
it stays finite.
"""

from __future__ import annotations

import sympy
from sympy.printing.str import StrPrinter

from tasks.constitutive.gp import grammar
from tasks.constitutive.gp.genome import Expr, Genome, Param
from tasks.constitutive.gp.grammar import MATRIX, PRINCIPAL, SCALAR

#: Significant digits of the numbers in a formula.
DIGITS = 4
#: A term of a sum whose coefficient is this small beside the largest one is a rounding error
#: (the weights of F in a mixture, 1 - 0.2 - 0.5 - 0.3): it is left out.
NEGLIGIBLE = 1e-9
#: The terminals, as symbols (a matrix's symbol does not commute).
_TERMINALS = {
    (MATRIX, "F"): sympy.Symbol("F", commutative=False),
    (MATRIX, "I"): sympy.Symbol("I", commutative=False),
    (MATRIX, "R"): sympy.Symbol("R", commutative=False),
    (MATRIX, "b"): sympy.Symbol("b", commutative=False),
    (PRINCIPAL, "sigma"): sympy.Symbol("sigma"),
    (PRINCIPAL, "eps"): sympy.Symbol("eps"),
    (SCALAR, "J"): sympy.Symbol("J"),
    (SCALAR, "log_J"): sympy.log(sympy.Symbol("J")),
}
#: Operations kept whole: how each is written around its arguments' formulas.
_WHOLE = {
    "T": "({0})^T",
    "dev": "dev({0})",
    "vol": "vol({0})",
    "frame": "U diag({0}) Vh",
    "from_strain": "U diag(exp({0})) Vh",
    "spatial": "U diag({0}) U^T",
    "shrink": "shrink({0}, {1})",
    "cylinder": "cylinder_return({0}, {1})",
    "cone": "cone_return({0}, {1})",
    "shifted_cone": "shifted_cone_return({0}, {1}, {2})",
    "sum": "sum({0})",
    "norm": "norm({0})",
    "trace": "tr({0})",
}


def value(leaf: Param) -> sympy.Float:
    """The parameter's value (its transform of its raw value), as a SymPy number."""
    return sympy.Float(grammar.TRANSFORMS[leaf.transform].value(leaf.raw))


def _written(number: sympy.Float) -> sympy.Number:
    """``number`` to :data:`DIGITS` significant digits; a whole number below 10^DIGITS as an
    integer (a weight of 0.99999 is 1, and 1 * x is x)."""
    rounded = float(f"{float(number):.{DIGITS}g}")
    if abs(rounded) < 10**DIGITS and rounded.is_integer():
        return sympy.Integer(int(rounded))
    return number


def text(expression: sympy.Expr) -> str:
    """``expression`` expanded, with the terms of a sum dropped whose coefficients are
    rounding errors beside the largest (:data:`NEGLIGIBLE`), written with :data:`DIGITS`
    significant digits."""
    expression = sympy.expand(expression)
    if isinstance(expression, sympy.Add):
        sizes = [abs(term.as_coeff_Mul()[0]) for term in expression.args]
        largest = max(sizes)
        kept = zip(expression.args, sizes, strict=True)
        expression = sympy.Add(*(term for term, size in kept if size > NEGLIGIBLE * largest))
    written = {number: _written(number) for number in expression.atoms(sympy.Float)}
    return _Printer().doprint(expression.xreplace(written))


class _Printer(StrPrinter):
    """SymPy's text, its numbers written with :data:`DIGITS` significant digits."""

    def _print_Float(self, number: sympy.Float) -> str:
        return f"{float(number):.{DIGITS}g}"


def _whole(op: str, value_type: str, args: list[sympy.Expr]) -> sympy.Expr:
    """An operation kept whole, as a symbol named by what it does to its arguments."""
    name = _WHOLE[op].format(*(text(arg) for arg in args))
    return sympy.Symbol(name, commutative=value_type != MATRIX)


def expression(expr: Expr, value_type: str) -> sympy.Expr:
    """The SymPy expression of a genome's subtree ``expr`` of ``value_type``."""
    if isinstance(expr, Param):
        return value(expr)
    if not expr.children:
        return _TERMINALS[(value_type, expr.op)]
    op = grammar.OPS[value_type][expr.op]
    args = [expression(child, arg) for child, arg in zip(expr.children, op.args, strict=True)]
    name = expr.op
    if name == "add":
        return args[0] + args[1]
    if name == "sub":
        return args[0] - args[1]
    if name in ("scale", "smul", "mul", "const"):
        return sympy.Mul(*args)
    if name == "matmul":
        return args[0] * args[1]
    if name == "blend":
        weight, start, end = args
        return start + weight * (end - start)
    if name == "exp":
        return sympy.exp(args[0])
    if name == "pos":
        return sympy.Max(args[0], 0)
    if name == "neg":
        return sympy.Min(args[0], 0)
    return _whole(name, value_type, args)


def formula(genome: Genome) -> str:
    """The law of ``genome`` at its parameters' raw values, as one line: ``tau =
    sym(...)`` for an elastic law (the symmetric part of the sum of its terms), ``F_corrected
    = ...`` for a plastic one; sums, scalings and blends expanded and collected by SymPy."""
    terms = [value(term.coefficient) * expression(term.expr, MATRIX) for term in genome.terms]
    if genome.kind == "elastic":
        return f"tau = sym({text(sympy.Add(*terms))})"
    deformation = _TERMINALS[(MATRIX, "F")]
    corrected = deformation + sum(
        (value(term.coefficient) * (expression(term.expr, MATRIX) - deformation)
         for term in genome.terms),
        sympy.Integer(0),
    )  # fmt: skip
    return f"F_corrected = {text(corrected)}"
