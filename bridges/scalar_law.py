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

import taichi as ti
import torch

from bridges.step import torch_dtype
from taichi_mpm import _compat
from taichi_mpm.kernels.jacobi_svd import jacobi_svd

#: Operations of a program: name -> number of arguments.
ARITY = {"add": 2, "sub": 2, "mul": 2, "div": 2, "neg": 1, "powc": 2, "exp": 1, "log": 1,
         "sqrt": 1, "sin": 1, "cos": 1, "tanh": 1, "abs": 1, "sign": 1, "select": 3, "lt": 2,
         "le": 2, "gt": 2, "ge": 2, "eq": 2, "ne": 2, "and": 2, "or": 2, "svd": 10,
         "svd_saved": 11, "part": 2}  # fmt: skip
#: Most nodes a program may have (forward and reverse): Taichi's compile time grows with it.
MAX_NODES = 20_000


class ProgramTooLarge(ValueError):
    """The program outgrew :data:`MAX_NODES`."""


class Program:
    """Scalar operations on ``inputs`` input values and ``parameters`` parameter values.

    Nodes are numbered in the order they are made (a topological order); equal operations on
    equal arguments are made once, and operations on constants only are folded.
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
        """The node ``name(*args)`` (made once), or its value if every argument is a constant."""
        if ARITY.get(name) != len(args):
            raise ValueError(f"{name} takes {ARITY.get(name)} arguments, got {len(args)}")
        plain = tuple(a.index if isinstance(a, Scalar) else ("c", float(a)) for a in args)
        if all(isinstance(a, tuple) for a in plain):
            return _fold(name, [float(a) for a in args])
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
        parts: dict[int, list] = {}  # an SVD's node: the adjoints of its 21 values
        leaves = len(self.inputs) + len(self.parameters)  # the first nodes; their adjoints stay
        for index in range(len(self.nodes) - 1, leaves - 1, -1):
            g = adjoint.pop(index, None)
            name, args = self.nodes[index]
            if name == "part" and g is not None:
                parts.setdefault(args[0], [None] * 21)[int(args[1][1])] = g
                continue
            if name in ("svd", "svd_saved") and index in parts:
                values = [self._value(a) for a in args]
                own = [self.op("part", Scalar(self, index), k) for k in range(21)]
                grad = _svd_adjoint(own, parts.pop(index), values[9])
                for argument, local in zip(values[:9], grad, strict=True):
                    if isinstance(argument, Scalar) and not _is(local, 0.0):
                        adjoint[argument.index] = _plus(adjoint.get(argument.index), local)
                continue
            if g is None:
                continue
            values = [self._value(a) for a in args]
            for position, local in _local_gradients(self, name, values, Scalar(self, index), g):
                argument = values[position]
                if isinstance(argument, Scalar) and local is not None:
                    adjoint[argument.index] = _plus(adjoint.get(argument.index), local)
        return [adjoint.get(w.index, 0.0) for w in wrt]

    def _value(self, plain: int | tuple) -> Scalar | float:
        return plain[1] if isinstance(plain, tuple) else Scalar(self, plain)


def _plus(total: Scalar | float | None, term: Scalar | float) -> Scalar | float:
    return term if total is None else total + term


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
    """``name(*args)`` on scalars or constants (``name`` from :data:`ARITY`)."""
    for arg in args:
        if isinstance(arg, Scalar):
            return arg.program.op(name, *args)
    return _fold(name, [float(a) for a in args])


def select(condition, if_true, if_false):
    """``if_true`` where ``condition`` holds (non-zero), else ``if_false``."""
    if not isinstance(condition, Scalar):
        return if_true if condition else if_false
    return apply("select", condition, if_true, if_false)


def _fold(name: str, a: list[float]) -> float:
    """The value of an operation on constants, as Python computes it (IEEE double)."""
    try:
        return _FOLD[name](*a)
    except (ValueError, ZeroDivisionError, OverflowError):
        return math.nan


def _sign(x: float) -> float:
    return 1.0 if x > 0 else -1.0 if x < 0 else 0.0


def _div(a: float, b: float) -> float:
    if b == 0:
        return math.nan if a == 0 or a != a else math.copysign(math.inf, a) * math.copysign(1, b)
    return a / b


_FOLD: dict[str, Callable[..., float]] = {
    "add": lambda a, b: a + b, "sub": lambda a, b: a - b, "mul": lambda a, b: a * b,
    "div": _div, "neg": lambda a: -a, "powc": math.pow, "exp": math.exp,
    "log": lambda a: -math.inf if a == 0 else math.log(a), "sqrt": math.sqrt, "sin": math.sin,
    "cos": math.cos, "tanh": math.tanh, "abs": abs, "sign": _sign,
    "select": lambda c, a, b: a if c else b,
    "lt": lambda a, b: float(a < b), "le": lambda a, b: float(a <= b),
    "gt": lambda a, b: float(a > b), "ge": lambda a, b: float(a >= b),
    "eq": lambda a, b: float(a == b), "ne": lambda a, b: float(a != b),
    "and": lambda a, b: float(bool(a) and bool(b)), "or": lambda a, b: float(bool(a) or bool(b)),
}  # fmt: skip


def _local_gradients(program: Program, name: str, a: list, out: Scalar, g):
    """(argument position, g * d out / d argument) pairs, with torch's backward formulas."""
    if name == "add":
        return [(0, g), (1, g)]
    if name == "sub":
        return [(0, g), (1, -g)]
    if name == "mul":
        return [(0, g * a[1]), (1, g * a[0])]
    if name == "div":
        return [(0, g / a[1]), (1, -g * a[0] / (a[1] * a[1]))]
    if name == "neg":
        return [(0, -g)]
    if name == "powc":
        exponent = a[1]
        return [(0, 0.0 if exponent == 0 else g * (exponent * a[0] ** (exponent - 1)))]
    if name == "exp":
        return [(0, g * out)]
    if name == "log":
        return [(0, g / a[0])]
    if name == "sqrt":
        return [(0, g / (2.0 * out))]
    if name == "sin":
        return [(0, g * apply("cos", a[0]))]
    if name == "cos":
        return [(0, -g * apply("sin", a[0]))]
    if name == "tanh":
        return [(0, g * (1.0 - out * out))]
    if name == "abs":
        return [(0, g * apply("sign", a[0]))]
    if name == "select":
        return [(1, select(a[0], g, 0.0)), (2, select(a[0], 0.0, g))]
    return []  # comparisons, sign, and, or: constant almost everywhere


def svd(entries: Sequence[Scalar | float], tolerance: float) -> list[Scalar | float]:
    """The SVD ``A = U diag(S) Vh`` of the 3x3 matrix with row-major ``entries``, as torch's
    ``linalg.svd`` gives it (S >= 0 descending): U's 9 entries, S's 3, Vh's 9. Computed by
    :func:`taichi_mpm.kernels.jacobi_svd.jacobi_svd`; its reverse is the clamped one of
    :mod:`bridges.linalg` with ``tolerance`` (square root of the machine epsilon)."""
    program = next((e.program for e in entries if isinstance(e, Scalar)), None)
    if program is None:
        raise NotImplementedError("the SVD of a constant matrix")
    node = program.op("svd", *entries, tolerance)
    return [program.op("part", node, k) for k in range(21)]


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


# ---------------------------------------------------------------------------------- kernels


def _emit(program: Program, wanted: Sequence[Scalar | float], inputs, parameters) -> list:
    """Taichi expressions (inside a kernel being compiled) of the ``wanted`` values."""
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
        elif name == "svd":
            values[index] = _emit_svd([value(a) for a in args[:9]])
        elif name == "svd_saved":
            start = int(args[10][1])
            values[index] = inputs[start : start + 21]
        elif name == "part":
            values[index] = values[args[0]][int(args[1][1])]
        else:
            values[index] = _compat.local(_EMIT[name](*[value(a) for a in args]))
    return [values[w.index] if isinstance(w, Scalar) else w for w in wanted]


def _emit_svd(entries: list) -> list:
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


def _select(c, a, b):
    return ti.select(c != 0, a, b)


_EMIT: dict[str, Callable] = {
    "add": lambda a, b: a + b, "sub": lambda a, b: a - b, "mul": lambda a, b: a * b,
    "div": lambda a, b: a / b, "neg": lambda a: -a, "powc": lambda a, b: _power(a, b),
    "exp": ti.exp, "log": ti.log, "sqrt": ti.sqrt, "sin": ti.sin, "cos": ti.cos,
    "tanh": ti.tanh, "abs": ti.abs,
    "sign": lambda a: ti.select(a > 0, 1.0, 0.0) - ti.select(a < 0, 1.0, 0.0),
    "select": _select,
    "lt": lambda a, b: ti.select(a < b, 1.0, 0.0), "le": lambda a, b: ti.select(a <= b, 1.0, 0.0),
    "gt": lambda a, b: ti.select(a > b, 1.0, 0.0), "ge": lambda a, b: ti.select(a >= b, 1.0, 0.0),
    "eq": lambda a, b: ti.select(a == b, 1.0, 0.0), "ne": lambda a, b: ti.select(a != b, 1.0, 0.0),
    "and": lambda a, b: ti.select((a != 0) & (b != 0), 1.0, 0.0),
    "or": lambda a, b: ti.select((a != 0) | (b != 0), 1.0, 0.0),
}  # fmt: skip


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
    """

    def __init__(self, program: Program, outputs: Sequence[Scalar | float]) -> None:
        self.inputs, self.parameters = len(program.inputs), len(program.parameters)
        self.outputs = len(outputs)
        svds = [i for i in sorted(_needed(program, outputs)) if program.nodes[i][0] == "svd"]
        saved = [program.op("part", Scalar(program, i), k) for i in svds for k in range(21)]
        self.saved = len(saved)
        # the reverse's inputs: the law's, dL/d(output) (one per output), the saved SVDs
        first = self.inputs + self.outputs
        reverse = Program(first + self.saved, self.parameters)
        offsets = {svd: first + 21 * j for j, svd in enumerate(svds)}
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
                name, plain = "svd_saved", [*plain, saved[index]]
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
    differentiable torch operation: its reverse is ``law``'s reverse kernel."""
    return _LawFunction.apply(F, law, *parameters)


def _rows(F: torch.Tensor, law: CompiledLaw) -> torch.Tensor:
    """The law's (N, inputs) rows of ``F``, contiguous, as its kernels read them."""
    return F.detach().reshape(-1, law.inputs).contiguous()


class _LawFunction(torch.autograd.Function):
    @staticmethod
    def forward(ctx, F, law: CompiledLaw, *parameters):
        rows = _rows(F, law)
        flat = flat_parameters(parameters, rows)
        ctx.law, ctx.shape = law, F.shape
        out = law.forward(rows, flat)
        # F itself, not its rows: F is a view of the step's output or the step's own input,
        # which the graph keeps anyway, while the rows are a copy (the reverse copies again)
        ctx.save_for_backward(F.detach(), flat, out[:, law.outputs :], *parameters)
        return out[:, : law.outputs].reshape(F.shape)

    @staticmethod
    def backward(ctx, grad):
        F, flat, saved, *parameters = ctx.saved_tensors
        law: CompiledLaw = ctx.law
        rows = _rows(F, law)
        grad_rows, grad_flat = law.backward(rows, flat, saved,
                                            grad.reshape(rows.shape[0], -1))  # fmt: skip
        pieces = split_parameters(grad_flat, parameters)
        unused = split_parameters(torch.tensor(law.constant_zero), parameters)
        return (
            grad_rows.reshape(ctx.shape),
            None,
            *[
                None if bool(zero.all()) or not ctx.needs_input_grad[2 + index] else piece
                for index, (piece, zero) in enumerate(zip(pieces, unused, strict=True))
            ],
        )
