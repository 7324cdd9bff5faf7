"""A per-particle law as a scalar program, compiled into one Taichi kernel forward and one reverse.

A constitutive law maps each particle's 3x3 matrix on its own. Written in torch, every step runs
a few dozen batched operations (and autograd their reverse), each a pass over all particles'
tensors with its own dispatch. Here the law is first written out once as a *program* of scalar
operations on one particle's nine inputs and the law's parameters (:class:`Program`, built by
ordinary arithmetic on :class:`Scalar` values, e.g. element by element of NumPy object arrays),
then run as one Taichi launch over all particles forward and one in reverse:

* the reverse is derived from the program (reverse-mode differentiation, with torch's
  conventions at the edges: ``clamp`` passes the gradient at its bounds, ``abs`` has
  gradient 0 at 0, an SVD's is :mod:`bridges.linalg`'s clamped one) and recomputes the
  forward values it needs, so only the law's input and its SVDs' values are kept between the
  two;
* parameter gradients are written per particle and summed by torch (no atomics).

Every operation is defined once, in :data:`OPERATIONS` (in the manner of PyTorch's
``derivatives.yaml``): its arity, its value on constants, its local derivative, its Taichi
code and the ATen overloads it translates; adding an operation is adding one entry.

:class:`CompiledLaw` holds the two kernels and :func:`apply_law` runs them as a differentiable
torch operation. Which laws can be written as a program is the caller's business
(:mod:`tasks.constitutive.law_kernel` translates a captured law graph).
"""

from __future__ import annotations

import math
import numbers
import warnings
import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import taichi as ti
import torch

from bridges import linalg
from bridges.step import torch_dtype
from taichi_mpm import _compat
from taichi_mpm.kernels.jacobi_svd import jacobi_svd

#: Most nodes a program may have (forward and reverse): Taichi's compile time grows with it.
MAX_NODES = 20_000


class ProgramTooLarge(ValueError):
    """The program outgrew :data:`MAX_NODES`."""


def _constant_almost_everywhere(args: list, out: Any, g: Any) -> list:
    """The derivative of a comparison or a sign: no gradient flows through it."""
    return []


@dataclass(frozen=True)
class Operation:
    """One operation of a :class:`Program`: everything the compiler knows of it.

    Attributes
    ----------
    arity : int
        Number of arguments.
    fold : callable or None
        Its value when the arguments at ``fold_on`` are constants (given as floats; any other
        argument as it is), as Python computes it (IEEE double); a math error gives NaN.
        None: never computed on constants.
    emit : callable
        Its value inside a kernel being compiled, from its arguments' values (Taichi
        expressions, or floats for constants).
    derivative : callable
        ``derivative(args, out, g)``: ``(argument position, g * d out / d argument)`` pairs, by
        torch's backward formulas (``out`` the node itself, ``g`` its adjoint, a local of None
        passing nothing); none for an operation constant almost everywhere.
    aten : tuple of str
        ATen overloads that are this operation applied element-wise to their broadcast
        tensors (:mod:`tasks.constitutive.law_kernel` translates a law graph's by this).
    constants : tuple of int
        Argument positions that only a constant may take.
    fold_on : tuple of int or None
        The positions whose arguments being constants is enough to fold; None: all.
    outputs : int
        Values it makes: more than one are read by ``part`` nodes, and ``derivative`` then
        gets the list of their adjoints (None where none flows) as ``g``.
    local : bool
        Whether its Taichi value is kept in a kernel-local variable (not when ``emit``
        returns variables already made).
    """

    arity: int
    fold: Callable[..., Any] | None
    emit: Callable[..., Any]
    derivative: Callable[[list, Any, Any], list] = _constant_almost_everywhere
    aten: tuple[str, ...] = ()
    constants: tuple[int, ...] = ()
    fold_on: tuple[int, ...] | None = None
    outputs: int = 1
    local: bool = True


class Program:
    """Scalar operations on ``inputs`` input values and ``parameters`` parameter values.

    Nodes are numbered in the order they are made (a topological order); equal operations on
    equal arguments are made once, and operations on constants only are folded. A node is
    ``(name, args)``: an input or a parameter (``args`` its index), or an operation of
    :data:`OPERATIONS` (``args`` the indices of argument nodes, ``("c", value)`` for constants).
    """

    def __init__(self, inputs: int, parameters: int) -> None:
        self.nodes: list[tuple[str, tuple]] = []
        self._known: dict[tuple[str, tuple], Scalar] = {}
        self.inputs = [self._leaf("input", k) for k in range(inputs)]
        self.parameters = [self._leaf("param", k) for k in range(parameters)]

    def _leaf(self, kind: str, index: int) -> Scalar:
        self.nodes.append((kind, (index,)))
        return Scalar(self, len(self.nodes) - 1)

    def op(self, name: str, *args: Scalar | float) -> Scalar | float:
        """The node ``name(*args)`` (made once), or its value if it folds on constants."""
        operation = OPERATIONS.get(name)
        if operation is None or operation.arity != len(args):
            arity = None if operation is None else operation.arity
            raise ValueError(f"{name} takes {arity} arguments, got {len(args)}")
        for position in operation.constants:
            if isinstance(args[position], Scalar):
                raise NotImplementedError(f"{name} with a computed argument {position}")
        plain = tuple(a.index if isinstance(a, Scalar) else ("c", float(a)) for a in args)
        on = range(len(args)) if operation.fold_on is None else operation.fold_on
        if all(isinstance(plain[k], tuple) for k in on):
            return _fold(operation, args)
        key = (name, plain)
        known = self._known.get(key)
        if known is None:
            if len(self.nodes) >= MAX_NODES:
                raise ProgramTooLarge(f"the law needs more than {MAX_NODES} scalar operations")
            self.nodes.append(key)
            known = self._known[key] = Scalar(self, len(self.nodes) - 1)
        return known

    def gradients(self, outputs: Sequence[Scalar | float], seeds: Sequence[Scalar | float],
                  wrt: Sequence[Scalar]) -> list[Scalar | float]:  # fmt: skip
        """d(sum of seeds[k] * outputs[k]) / d(wrt[j]), as more nodes of this program."""
        adjoint: dict[int, Scalar | float] = {}
        for output, seed in zip(outputs, seeds, strict=True):
            if isinstance(output, Scalar):
                adjoint[output.index] = _plus(adjoint.get(output.index), seed)
        parts: dict[int, list] = {}  # a node of several values: the adjoints of its values
        leaves = len(self.inputs) + len(self.parameters)  # the first nodes; their adjoints stay
        for index in range(len(self.nodes) - 1, leaves - 1, -1):
            name, args = self.nodes[index]
            operation = OPERATIONS[name]
            g = adjoint.pop(index, None) if operation.outputs == 1 else parts.pop(index, None)
            if g is None:
                continue
            if name == "part":  # the adjoint of one value of the node it reads
                whole = args[0]
                size = OPERATIONS[self.nodes[whole][0]].outputs
                parts.setdefault(whole, [None] * size)[int(args[1][1])] = g
                continue
            values = [self._value(a) for a in args]
            for position, local in operation.derivative(values, Scalar(self, index), g):
                argument = values[position]
                if isinstance(argument, Scalar) and local is not None:
                    adjoint[argument.index] = _plus(adjoint.get(argument.index), local)
        return [adjoint.get(w.index, 0.0) for w in wrt]

    def _value(self, plain: int | tuple) -> Scalar | float:
        return plain[1] if isinstance(plain, tuple) else Scalar(self, plain)


def _plus(total: Scalar | float | None, term: Scalar | float) -> Scalar | float:
    return term if total is None else total + term


def _fold(operation: Operation, args: Sequence) -> Any:
    """``operation``'s value on ``args`` (those it folds on are constants)."""
    if operation.fold is None:
        raise NotImplementedError("an operation of constants that is not folded (an SVD)")
    try:
        return operation.fold(*[a if isinstance(a, Scalar) else float(a) for a in args])
    except (ValueError, ZeroDivisionError, OverflowError):
        return math.nan


class Scalar:
    """One value of a :class:`Program`; arithmetic on it adds nodes."""

    __slots__ = ("program", "index")
    __hash__ = object.__hash__

    def __init__(self, program: Program, index: int) -> None:
        self.program, self.index = program, index

    def _op(self, name: str, *args):
        return self.program.op(name, *args)

    def __add__(self, other):
        if not isinstance(other, _OPERANDS):
            return NotImplemented
        return self if _is(other, 0.0) else self._op("add", self, other)

    def __radd__(self, other):
        if not isinstance(other, _OPERANDS):
            return NotImplemented
        return self if _is(other, 0.0) else self._op("add", other, self)

    def __sub__(self, other):
        if not isinstance(other, _OPERANDS):
            return NotImplemented
        return self if _is(other, 0.0) else self._op("sub", self, other)

    def __rsub__(self, other):
        if not isinstance(other, _OPERANDS):
            return NotImplemented
        return self._op("neg", self) if _is(other, 0.0) else self._op("sub", other, self)

    def __mul__(self, other):
        if not isinstance(other, _OPERANDS):
            return NotImplemented
        return self if _is(other, 1.0) else self._op("mul", self, other)

    def __rmul__(self, other):
        if not isinstance(other, _OPERANDS):
            return NotImplemented
        return self if _is(other, 1.0) else self._op("mul", other, self)

    def __truediv__(self, other):
        if not isinstance(other, _OPERANDS):
            return NotImplemented
        return self if _is(other, 1.0) else self._op("div", self, other)

    def __rtruediv__(self, other):
        if not isinstance(other, _OPERANDS):
            return NotImplemented
        return self._op("div", other, self)

    def __neg__(self):
        return self._op("neg", self)

    def __pos__(self):
        return self

    def __pow__(self, other):
        if isinstance(other, Scalar):
            raise NotImplementedError("a power with a computed exponent")
        return self if other == 1 else self._op("powc", self, other)

    def __abs__(self):
        return self._op("abs", self)

    def __lt__(self, other):
        if not isinstance(other, _OPERANDS):
            return NotImplemented
        return self._op("lt", self, other)

    def __le__(self, other):
        if not isinstance(other, _OPERANDS):
            return NotImplemented
        return self._op("le", self, other)

    def __gt__(self, other):
        if not isinstance(other, _OPERANDS):
            return NotImplemented
        return self._op("gt", self, other)

    def __ge__(self, other):
        if not isinstance(other, _OPERANDS):
            return NotImplemented
        return self._op("ge", self, other)

    def __eq__(self, other):  # type: ignore[override]
        if not isinstance(other, _OPERANDS):
            return NotImplemented
        return self._op("eq", self, other)

    def __ne__(self, other):  # type: ignore[override]
        if not isinstance(other, _OPERANDS):
            return NotImplemented
        return self._op("ne", self, other)

    def __bool__(self):
        raise TypeError("a scalar of a law program has no truth value while it is written")


_OPERANDS = (Scalar, numbers.Real)


def _is(value, constant: float) -> bool:
    return not isinstance(value, Scalar) and float(value) == constant


def apply(name: str, *args: Scalar | float) -> Scalar | float:
    """``name(*args)`` on scalars or constants (``name`` from :data:`OPERATIONS`)."""
    for arg in args:
        if isinstance(arg, Scalar):
            return arg.program.op(name, *args)
    return _fold(OPERATIONS[name], args)


def select(condition, if_true, if_false):
    """``if_true`` where ``condition`` holds (non-zero), else ``if_false``."""
    return apply("select", condition, if_true, if_false)


def svd(entries: Sequence[Scalar | float], tolerance: float) -> list[Scalar | float]:
    """The SVD ``A = U diag(S) Vh`` of the 3x3 matrix with row-major ``entries``, as torch's
    ``linalg.svd`` gives it (S >= 0 descending): U's 9 entries, S's 3, Vh's 9. Computed by
    :func:`taichi_mpm.kernels.jacobi_svd.jacobi_svd`; its reverse is the clamped one of
    :mod:`bridges.linalg` with ``tolerance`` (square root of the machine epsilon)."""
    program = next((e.program for e in entries if isinstance(e, Scalar)), None)
    if program is None:
        raise NotImplementedError("the SVD of a constant matrix")
    node = program.op("svd", *entries, tolerance)
    return [program.op("part", node, k) for k in range(SVD_VALUES)]


#: Values of an SVD node: U (9, row-major), S (3), Vh (9).
SVD_VALUES = 21


def _product(x, y):
    """x * y, exactly 0 where either is the constant 0 (a gradient that does not flow)."""
    return 0.0 if _is(x, 0.0) or _is(y, 0.0) else x * y


def _matmul(A: list[list], B: list[list]) -> list[list]:
    rows = []
    for i in range(3):
        row = []
        for j in range(3):
            total: Scalar | float = 0.0
            for k in range(3):
                total = total + _product(A[i][k], B[k][j])
            row.append(total)
        rows.append(row)
    return rows


def _clamp_magnitude(x, tol):
    up = select(apply("gt", x, tol), x, tol)
    down = select(apply("lt", x, -tol), x, -tol)
    return select(apply("ge", x, 0.0), up, down)


def _svd_derivative(args: list, out: Scalar, grads: list) -> list:
    """The local derivatives of an SVD node (``args``: its 9 entries, then the tolerance)."""
    values = [apply("part", out, k) for k in range(SVD_VALUES)]
    adjoint = _svd_adjoint(values, grads, args[9])
    return [(k, None if _is(local, 0.0) else local) for k, local in enumerate(adjoint)]


def _svd_adjoint(parts: list, grads: list, tolerance: float) -> list:
    """dL/dA (row-major) of an SVD from its values and the adjoints of them (None: none)."""
    g = [0.0 if x is None else x for x in grads]
    U = [parts[3 * i : 3 * i + 3] for i in range(3)]
    S = parts[9:12]
    Vh = [parts[12 + 3 * i : 15 + 3 * i] for i in range(3)]
    gU = [g[3 * i : 3 * i + 3] for i in range(3)]
    gS = g[9:12]
    gVh = [g[12 + 3 * i : 15 + 3 * i] for i in range(3)]
    a = _matmul([list(col) for col in zip(*U, strict=True)], gU)
    b = _matmul(Vh, [list(col) for col in zip(*gVh, strict=True)])
    largest: Scalar | float = 1.0
    for value in S:
        magnitude = apply("abs", value)
        largest = select(apply("gt", magnitude, largest), magnitude, largest)
    tol = tolerance * largest
    inner = [[0.0] * 3 for _ in range(3)]
    for i in range(3):
        for j in range(3):
            if i == j:
                inner[i][j] = gS[i]
                continue
            skew_a, skew_b = a[i][j] - a[j][i], b[i][j] - b[j][i]
            total, difference = skew_a + skew_b, skew_a - skew_b
            if _is(total, 0.0) and _is(difference, 0.0):
                continue
            gap = _clamp_magnitude(S[j] - S[i], tol)
            span = _clamp_magnitude(S[j] + S[i], tol)
            inner[i][j] = 0.5 * (total / gap + difference / span)
    return [x for row in _matmul(_matmul(U, inner), Vh) for x in row]


def _emit_svd(entries: Sequence) -> list:
    """U (9), S (3), Vh (9) of the 3x3 matrix ``entries``, torch's convention (S >= 0)."""
    u, s, v = jacobi_svd(ti.Matrix([entries[0:3], entries[3:6], entries[6:9]]))

    def at(matrix, *index):  # what ``matrix[index]`` is in a kernel's own code
        return _compat.element(matrix, *index)

    flip = at(s, 2) < 0  # jacobi_svd's U is a rotation: torch's makes S[2] >= 0 instead
    values = []
    for i in range(3):
        values += [at(u, i, 0), at(u, i, 1), ti.select(flip, -at(u, i, 2), at(u, i, 2))]
    values += [at(s, 0), at(s, 1), ti.abs(at(s, 2))]
    values += [at(v, j, i) for i in range(3) for j in range(3)]
    return [_compat.local(x) for x in values]


# ------------------------------------------------------------------------------ operations


def _sign(x: float) -> float:
    return 1.0 if x > 0 else -1.0 if x < 0 else 0.0


def _div(a: float, b: float) -> float:
    if b == 0:
        return math.nan if a == 0 or a != a else math.copysign(math.inf, a) * math.copysign(1, b)
    return a / b


def _power(a, exponent: float):
    """``a ** exponent`` for a constant exponent: small whole powers as products."""
    if exponent == 2:
        return a * a
    if exponent == 3:
        return a * a * a
    if exponent == 0.5:
        return ti.sqrt(a)
    if exponent == -1:
        return 1.0 / a
    return ti.pow(a, exponent)


def _unary(name: str, fold, emit, derivative=None) -> Operation:
    """An operation of one argument, ATen's ``name`` (its ``default`` overload)."""
    return Operation(1, fold, emit, derivative or _constant_almost_everywhere,
                     aten=(f"aten.{name}.default",))  # fmt: skip


def _comparison(name: str, compare: Callable[[Any, Any], Any]) -> Operation:
    """1.0 where ``compare`` holds, else 0.0: ATen's ``name`` (its Scalar and Tensor forms)."""
    return Operation(2, lambda a, b: float(compare(a, b)),
                     lambda a, b: ti.select(compare(a, b), 1.0, 0.0),
                     aten=(f"aten.{name}.Scalar", f"aten.{name}.Tensor"))  # fmt: skip


#: Every operation of a program, by name: ``Operation(arity, fold, emit, derivative, ...)``. In
#: a derivative, ``x`` is the list of the arguments, ``out`` the result and ``g`` its adjoint.
OPERATIONS: dict[str, Operation] = {
    "add": Operation(2, lambda a, b: a + b, lambda a, b: a + b,
                     lambda x, out, g: [(0, g), (1, g)],
                     aten=("aten.add.Tensor", "aten.add.Scalar")),
    "sub": Operation(2, lambda a, b: a - b, lambda a, b: a - b,
                     lambda x, out, g: [(0, g), (1, -g)],
                     aten=("aten.sub.Tensor", "aten.sub.Scalar")),
    "mul": Operation(2, lambda a, b: a * b, lambda a, b: a * b,
                     lambda x, out, g: [(0, g * x[1]), (1, g * x[0])],
                     aten=("aten.mul.Tensor", "aten.mul.Scalar")),
    "div": Operation(2, _div, lambda a, b: a / b,
                     lambda x, out, g: [(0, g / x[1]), (1, -g * x[0] / (x[1] * x[1]))],
                     aten=("aten.div.Tensor", "aten.div.Scalar", "aten.div.Tensor_mode")),
    # a power with a constant exponent
    "powc": Operation(2, math.pow, _power,
                      lambda x, out, g: [(0, 0.0 if x[1] == 0
                                          else g * (x[1] * x[0] ** (x[1] - 1)))],
                      aten=("aten.pow.Tensor_Scalar",), constants=(1,)),
    "neg": _unary("neg", lambda a: -a, lambda a: -a, lambda x, out, g: [(0, -g)]),
    "exp": _unary("exp", math.exp, ti.exp, lambda x, out, g: [(0, g * out)]),
    "log": _unary("log", lambda a: -math.inf if a == 0 else math.log(a), ti.log,
                  lambda x, out, g: [(0, g / x[0])]),
    "sqrt": _unary("sqrt", math.sqrt, ti.sqrt, lambda x, out, g: [(0, g / (2.0 * out))]),
    "sin": _unary("sin", math.sin, ti.sin, lambda x, out, g: [(0, g * apply("cos", x[0]))]),
    "cos": _unary("cos", math.cos, ti.cos, lambda x, out, g: [(0, -g * apply("sin", x[0]))]),
    "tanh": _unary("tanh", math.tanh, ti.tanh, lambda x, out, g: [(0, g * (1.0 - out * out))]),
    # torch's: the gradient of abs at 0 is 0
    "abs": _unary("abs", abs, ti.abs, lambda x, out, g: [(0, g * apply("sign", x[0]))]),
    "sign": _unary("sign", _sign,
                   lambda a: ti.select(a > 0, 1.0, 0.0) - ti.select(a < 0, 1.0, 0.0)),
    # where(condition, a, b); a constant condition picks its branch, whatever the branches are
    "select": Operation(3, lambda c, a, b: a if c else b, lambda c, a, b: ti.select(c != 0, a, b),
                        lambda x, out, g: [(1, select(x[0], g, 0.0)), (2, select(x[0], 0.0, g))],
                        aten=("aten.where.self",), fold_on=(0,)),
    "lt": _comparison("lt", lambda a, b: a < b),
    "le": _comparison("le", lambda a, b: a <= b),
    "gt": _comparison("gt", lambda a, b: a > b),
    "ge": _comparison("ge", lambda a, b: a >= b),
    "eq": _comparison("eq", lambda a, b: a == b),
    "ne": _comparison("ne", lambda a, b: a != b),
    "and": Operation(2, lambda a, b: float(bool(a) and bool(b)),
                     lambda a, b: ti.select((a != 0) & (b != 0), 1.0, 0.0),
                     aten=("aten.logical_and.default",)),
    "or": Operation(2, lambda a, b: float(bool(a) or bool(b)),
                    lambda a, b: ti.select((a != 0) | (b != 0), 1.0, 0.0),
                    aten=("aten.logical_or.default",)),
    # the 9 entries of a 3x3 matrix (row-major), then the tolerance of its gradient's clamp;
    # tasks.constitutive.law_kernel translates ATen's SVD, a matrix at a time
    "svd": Operation(10, None, lambda *a: _emit_svd(a[:9]), _svd_derivative, constants=(9,),
                     outputs=SVD_VALUES, local=False),
    # in a reverse program, an SVD whose values the forward kernel saved: those are its last
    # 21 arguments (inputs of the reverse kernel)
    "svd_saved": Operation(10 + SVD_VALUES, None, lambda *a: list(a[10:]), _svd_derivative,
                           constants=(9,), outputs=SVD_VALUES, local=False),
    # value k (a constant) of a node of several values (its adjoint goes to that node's)
    "part": Operation(2, None, lambda values, k: values[int(k)], constants=(1,), local=False),
}  # fmt: skip


# ---------------------------------------------------------------------------------- kernels


def _emit(program: Program, wanted: Sequence[Scalar | float], inputs, parameters) -> list:
    """Taichi values (inside a kernel being compiled) of the ``wanted`` values."""
    needed = _needed(program, wanted)
    values: dict[int, object] = {}

    def value(plain):
        return plain[1] if isinstance(plain, tuple) else values[plain]

    for index in sorted(needed):
        name, args = program.nodes[index]
        if name == "input":
            values[index] = inputs[args[0]]
        elif name == "param":
            values[index] = parameters[args[0]]
        else:
            operation = OPERATIONS[name]
            result = operation.emit(*[value(a) for a in args])
            values[index] = _compat.local(result) if operation.local else result
    return [values[w.index] if isinstance(w, Scalar) else w for w in wanted]


class CompiledLaw:
    """A law ``out = f(x, parameters)`` on (N, inputs) rows, as two Taichi kernels.

    The forward kernel also writes each SVD's 21 values (``saved`` columns, after the outputs),
    which the reverse reads instead of decomposing again; everything else it recomputes.

    Its kernels are released when it is garbage-collected (or by :meth:`release`), as far as
    Taichi 1.7 allows: Taichi's Python runtime lists every kernel ever made (each holding its
    program, so the law's whole scalar program stays alive), and that entry is removed; but the
    compiled code stays in the Taichi program's C++ side (its kernel list and its JIT modules)
    until ``ti.reset()``, which has no per-kernel counterpart. Measured on the CPU backend
    (float32, compiling the 161-node test law of ``tests/bridges/test_scalar_law.py`` 40 times
    in one process), each law left 1.01 MB resident without the release and 0.86 MB with it;
    the rest is what :class:`sga_agent.sandbox.Recycling` bounds, by replacing the process.

    Parameters
    ----------
    program : Program
        The law for one particle.
    outputs : sequence of Scalar or float
        The particle's outputs, one per column of the result.
    svd_inputs : bool
        Whether the program's inputs are a 3x3 matrix's 9 entries and then its signed SVD's 21
        values (U, S, Vh: :data:`SVD_VALUES`), which :func:`apply_law` computes by
        :func:`bridges.linalg.svd` (the batched svd3 kernel and its reverse where they apply):
        the law's kernels then hold no Jacobi sweeps, and compile in a fraction of the time.
    """

    def __init__(self, program: Program, outputs: Sequence[Scalar | float],
                 svd_inputs: bool = False) -> None:  # fmt: skip
        self.inputs, self.parameters = len(program.inputs), len(program.parameters)
        if svd_inputs and self.inputs != 9 + SVD_VALUES:
            raise ValueError(f"a law of a matrix and its SVD has 30 inputs, not {self.inputs}")
        self.svd_inputs = svd_inputs
        self.outputs = len(outputs)
        svds = [i for i in sorted(_needed(program, outputs)) if program.nodes[i][0] == "svd"]
        saved = [program.op("part", Scalar(program, i), k) for i in svds for k in range(SVD_VALUES)]
        self.saved = len(saved)
        # the reverse's inputs: the law's, dL/d(output) (one per output), the saved SVDs
        first = self.inputs + self.outputs
        reverse = Program(first + self.saved, self.parameters)
        offsets = {svd: first + SVD_VALUES * j for j, svd in enumerate(svds)}
        rebuilt = _replay(program, reverse, outputs, offsets)
        grads = reverse.gradients(rebuilt, reverse.inputs[self.inputs : first],
                                  reverse.inputs[: self.inputs] + reverse.parameters)  # fmt: skip
        #: per parameter value: True where no gradient reaches it (not used, or only compared)
        self.constant_zero = [not isinstance(g, Scalar) and g == 0 for g in grads[self.inputs :]]
        self._forward = _kernel(program, list(outputs) + saved, self.inputs, self.parameters,
                                "compiled_law_forward")  # fmt: skip
        self._reverse = _kernel(reverse, grads, first + self.saved, self.parameters,
                                "compiled_law_reverse")  # fmt: skip
        #: forgets the kernels in Taichi's runtime once this law is collected (or released)
        self.release = weakref.finalize(self, _compat.forget, [self._forward, self._reverse])
        _compile(self._forward, self.inputs, self.parameters, self.outputs + self.saved)
        _compile(self._reverse, first + self.saved, self.parameters, self.inputs + self.parameters)

    def forward(self, x: torch.Tensor, parameters: torch.Tensor) -> torch.Tensor:
        """(N, outputs + saved) results of (N, inputs) rows: the outputs, then what the reverse
        reads (:meth:`backward`'s ``saved``)."""
        out = x.new_empty(x.shape[0], self.outputs + self.saved)
        self._forward(x, parameters, out)
        return out

    def backward(self, x: torch.Tensor, parameters: torch.Tensor, saved: torch.Tensor,
                 out_grad: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:  # fmt: skip
        """dL/dx (N, inputs) and dL/dparameters (parameters,) from dL/dout (N, outputs);
        ``saved``: the forward's columns after the outputs."""
        rows = torch.cat([x, out_grad, saved], dim=1)
        grads = x.new_empty(x.shape[0], self.inputs + self.parameters)
        self._reverse(rows, parameters, grads)
        return grads[:, : self.inputs], grads[:, self.inputs :].sum(0)


def _needed(program: Program, wanted: Sequence[Scalar | float]) -> set[int]:
    """The nodes the ``wanted`` values are computed from."""
    needed: set[int] = set()
    stack = [w.index for w in wanted if isinstance(w, Scalar)]
    while stack:
        index = stack.pop()
        if index in needed:
            continue
        needed.add(index)
        name, args = program.nodes[index]
        if name not in ("input", "param"):
            stack.extend(a for a in args if isinstance(a, int))
    return needed


def _replay(source: Program, target: Program, outputs: Sequence[Scalar | float],
            saved: dict[int, int]) -> list:  # fmt: skip
    """``outputs`` of ``source`` written again in ``target`` (its first inputs and its
    parameters standing for ``source``'s); the SVDs in ``saved`` read their values from
    ``target``'s inputs from the given column on."""
    values: list = []
    for index, (name, args) in enumerate(source.nodes):
        if name == "input":
            values.append(target.inputs[args[0]])
        elif name == "param":
            values.append(target.parameters[args[0]])
        else:
            plain = [a[1] if isinstance(a, tuple) else values[a] for a in args]
            if index in saved:
                start = saved[index]
                name, plain = "svd_saved", [*plain, *target.inputs[start : start + SVD_VALUES]]
            values.append(target.op(name, *plain))
    return [values[o.index] if isinstance(o, Scalar) else o for o in outputs]


def _kernel(program: Program, wanted: list, width: int, parameters: int, name: str):
    """A kernel ``(rows (N, width), parameters (P,), out (N, len(wanted)))``, serial loop,
    called ``name`` (in Taichi's profiles)."""
    count = len(wanted)

    def run(rows, params, out):
        ti.loop_config(serialize=True)
        for p in range(rows.shape[0]):
            ti.static(_write(program, wanted, rows, params, out, p, width, parameters, count))

    run.__name__ = run.__qualname__ = name
    # set here, not written on the arguments: this module's annotations are strings
    run.__annotations__ = {"rows": ti.types.ndarray(), "params": ti.types.ndarray(),
                           "out": ti.types.ndarray()}  # fmt: skip
    return ti.kernel(run)


def _write(program, wanted, rows, params, out, p, width, parameters, count) -> None:
    inputs = [_compat.element(rows, p, k) for k in range(width)]
    values = [_compat.element(params, k) for k in range(parameters)]
    results = _emit(program, wanted, inputs, values)
    for k in range(count):
        _compat.store(_compat.element(out, p, k), results[k])


def _compile(kernel, width: int, parameters: int, outputs: int) -> None:
    """Compile ``kernel`` (a launch on one row), quietly and without Taichi's offline cache.

    Taichi would warn that the program's writer is a plain Python function (it is meant to
    be: it runs once, while compiling). Its offline cache is for the simulator's own kernels:
    a law's kernels are compiled for the law at hand, so none is written to disk (a search
    would otherwise add two files to the user's cache per candidate)."""
    dtype = torch_dtype()
    with _compat.without_offline_cache(), warnings.catch_warnings():
        warnings.filterwarnings("ignore", category=SyntaxWarning)
        kernel(torch.zeros(1, width, dtype=dtype), torch.zeros(max(parameters, 1), dtype=dtype),
               torch.zeros(1, outputs, dtype=dtype))  # fmt: skip


def flat_parameters(parameters: Sequence[torch.Tensor], like: torch.Tensor) -> torch.Tensor:
    """The parameters' values in one vector of ``like``'s dtype (one zero if there are none: a
    Taichi array is never empty)."""
    values = [p.detach().reshape(-1).to(like.dtype) for p in parameters]
    return torch.cat(values) if values else like.new_zeros(1)


def split_parameters(flat: torch.Tensor, parameters: Sequence[torch.Tensor]) -> list[torch.Tensor]:
    """``flat`` cut into tensors shaped as ``parameters``."""
    pieces, start = [], 0
    for p in parameters:
        pieces.append(flat[start : start + p.numel()].reshape(p.shape).to(p.dtype))
        start += p.numel()
    return pieces


def apply_law(
    F: torch.Tensor, law: CompiledLaw, parameters: Sequence[torch.Tensor]
) -> torch.Tensor:
    """``law`` on (B, 3, 3) ``F`` with ``parameters`` (the program's, in its order), as a
    differentiable torch operation: its reverse is ``law``'s reverse kernel. A law of F and its
    SVD (``law.svd_inputs``) gets the signed SVD from :func:`bridges.linalg.svd` (rotations, the
    sign of det F on S[2]; the program turns it to the convention it needs), whose own reverse
    then takes the law's gradients of U, S and Vh to F."""
    if not law.svd_inputs:
        return _LawFunction.apply(law, F.shape, 1, F, *parameters)
    U, S, Vh = linalg.svd(F)  # signed: in float32 three views of svd3's output, no sign flips
    return _LawFunction.apply(law, F.shape, 4, F, U, S, Vh, *parameters)


def _rows(pieces: Sequence[torch.Tensor], law: CompiledLaw) -> torch.Tensor:
    """The law's (N, inputs) rows of its input tensors, contiguous, as its kernels read them."""
    count = pieces[0].shape[:-2].numel()
    if len(pieces) == 1:
        return pieces[0].detach().reshape(count, law.inputs).contiguous()
    return torch.cat([p.detach().reshape(count, -1) for p in pieces], dim=1)


class _LawFunction(torch.autograd.Function):
    @staticmethod
    def forward(ctx, law: CompiledLaw, shape: torch.Size, count: int, *tensors):
        pieces, parameters = tensors[:count], tensors[count:]
        rows = _rows(pieces, law)
        flat = flat_parameters(parameters, rows)
        ctx.law, ctx.shape, ctx.count = law, shape, count
        out = law.forward(rows, flat)
        result, saved = out[:, : law.outputs], out[:, law.outputs :]
        if law.saved:  # tensors of their own: a contiguous result is read without a copy
            result, saved = result.contiguous(), saved.contiguous()  # (the Hencky stress's)
        # the input tensors, not their rows: F is a view of the step's output or the step's own
        # input, and an SVD's factors are what its reverse keeps, which the graph keeps anyway,
        # while the rows are a copy (the reverse copies again)
        ctx.save_for_backward(*[p.detach() for p in pieces], flat, saved, *parameters)
        return result.reshape(shape)

    @staticmethod
    def backward(ctx, grad):
        saved_tensors = ctx.saved_tensors
        pieces, (flat, saved) = saved_tensors[: ctx.count], saved_tensors[ctx.count : ctx.count + 2]
        parameters = saved_tensors[ctx.count + 2 :]
        law: CompiledLaw = ctx.law
        rows = _rows(pieces, law)
        grad_rows, grad_flat = law.backward(rows, flat, saved,
                                            grad.reshape(rows.shape[0], -1))  # fmt: skip
        batch = len(ctx.shape) - 2
        widths = [p.shape[batch:].numel() for p in pieces]
        grad_pieces = [g.reshape(p.shape) for g, p in
                       zip(grad_rows.split(widths, dim=1), pieces, strict=True)]  # fmt: skip
        pieces_grads = split_parameters(grad_flat, parameters)
        unused = split_parameters(torch.tensor(law.constant_zero), parameters)
        first = 3 + ctx.count
        return (
            None,
            None,
            None,
            *grad_pieces,
            *[
                None if bool(zero.all()) or not ctx.needs_input_grad[first + index] else piece
                for index, (piece, zero) in enumerate(zip(pieces_grads, unused, strict=True))
            ],
        )
