"""A captured law written out as a per-particle scalar program, to run as Taichi kernels.

:func:`translate` reads a checked :class:`~tasks.constitutive.law_graph.LawGraph` and writes one
particle's law as a :class:`bridges.scalar_law.Program`: every tensor of the graph becomes a NumPy
array of the program's scalars with the graph's shape, the batch dimension of size 1 (a
constitutive law maps each particle on its own), and every operation the array operation that
computes the same values. Operations with no such translation here (an einsum, say; an SVD
unless asked for) leave the law to torch: :func:`translate` raises :class:`Untranslatable`.

:func:`kernel_law` translates, compiles and checks: on the observed deformation gradients, the
kernels must give the torch graph's stresses and gradients (the law's parameters and F), and
the torch graph must map particles independently; otherwise the law stays in torch. Nothing of
the graph is executed as code: the program is built from its operation names and values.
"""

from __future__ import annotations

import math
import operator
from collections.abc import Callable
from functools import partial
from typing import Any

import numpy as np
import torch

from bridges import scalar_law as sl
from bridges.linalg import stable_linalg
from tasks.constitutive.law_graph import GraphLaw, LawGraph

#: Most values one tensor of a particle's law may hold here (a 3x3 law needs a few dozen).
MAX_ELEMENTS = 4096
#: Particles the translation is checked on (from the observed states), and how closely.
CHECK_PARTICLES = 512
TOLERANCE = {torch.float32: 2e-4, torch.float64: 1e-9}


class Untranslatable(ValueError):
    """The graph uses something :func:`translate` does not write out."""


def translate(graph: LawGraph, dtype: torch.dtype, svd: bool = True,
              factored: bool = False) -> tuple[sl.Program, list]:  # fmt: skip
    """(program, its 9 outputs): the law for one particle, parameters in the graph's order,
    for the floats of ``dtype`` (an SVD's gradient clamp depends on them).

    With ``factored``, the SVDs of the law's input F itself read U, S and Vh from 21 more
    inputs of the program (after F's 9: :class:`bridges.scalar_law.CompiledLaw`'s
    ``svd_inputs``, computed outside the law's kernels); other SVDs are written out as Jacobi
    sweeps with ``svd``, and without it are :class:`Untranslatable`.
    """
    sizes = [math.prod(t.shape) for t in graph.parameters.values()]
    of_input = factored and any(op == _SVD and args and args[0] == {"input": 0}
                                for op, args, _ in graph.nodes)  # fmt: skip
    program = sl.Program(9 + sl.SVD_VALUES * of_input, sum(sizes))
    F = _array(program.inputs[:9]).reshape(1, 3, 3)
    factors = _factors(program.inputs[9:]) if of_input else None
    values: dict[str, list] = {"input": [F]}
    start, params = 0, []
    for size, tensor in zip(sizes, graph.parameters.values(), strict=True):
        params.append(_array(program.parameters[start : start + size]).reshape(tensor.shape))
        start += size
    values["param"] = params
    values["constant"] = [_array(list(map(float, c.values))).reshape(c.shape)
                          for c in graph.constants]  # fmt: skip
    values["node"] = []

    def resolve(value: Any) -> Any:
        if isinstance(value, list):
            return [resolve(item) for item in value]
        if isinstance(value, dict):
            ((kind, payload),) = value.items()
            if kind in values:
                return values[kind][payload]
            if kind == "float":
                return float(payload)
            return None  # dtype, device, layout, memory format: floats only here
        return value

    inline = partial(_svd, tolerance=_svd_tolerance(dtype)) if svd else None
    rules = RULES | {_SVD: partial(_svd_rule, F=F, factors=factors, inline=inline)}
    for op, args, kwargs in graph.nodes:
        rule = rules.get(op)
        if rule is None:
            raise Untranslatable(op)
        kwargs = {k: resolve(v) for k, v in kwargs.items() if k not in _IGNORED}
        try:
            result = rule(*resolve(args), **kwargs)
        except (TypeError, ValueError, IndexError, ZeroDivisionError, NotImplementedError) as e:
            raise Untranslatable(f"{op}: {e}") from None
        for part in result if isinstance(result, tuple) else (result,):
            if isinstance(part, np.ndarray) and part.size > MAX_ELEMENTS:
                raise Untranslatable(f"{op} makes {part.size} values per particle")
        values["node"].append(result)
    out = resolve(graph.output)
    if not isinstance(out, np.ndarray) or out.shape != (1, 3, 3):
        raise Untranslatable("the output is not one 3x3 matrix per particle")
    return program, list(out.reshape(-1))


def kernel_law(law: GraphLaw, F: torch.Tensor, svd: bool = False,
               factored: bool = False) -> sl.CompiledLaw | None:  # fmt: skip
    """The compiled kernels of ``law`` if they compute what its torch graph computes on the
    deformation gradients ``F`` (N, 3, 3) and their neighbourhood, else None. A law with an SVD
    is compiled only with ``factored`` (an SVD of F itself: its factors as the kernels' inputs)
    or ``svd`` (any other SVD, and with ``factored`` false every SVD, as Jacobi sweeps in the
    kernels, which take seconds to compile: see the task option ``law_kernels``)."""
    try:
        program, outputs = translate(law.graph, F.dtype, svd, factored)
        svd_inputs = len(program.inputs) == 9 + sl.SVD_VALUES
        compiled = sl.CompiledLaw(program, outputs, svd_inputs)
    except (Untranslatable, sl.ProgramTooLarge):
        return None
    return compiled if _agrees(law, compiled, F) else None


def _agrees(law: GraphLaw, compiled: sl.CompiledLaw, F: torch.Tensor) -> bool:
    """Same stresses and gradients as the torch graph, and a torch graph that maps each
    particle on its own (a per-particle program cannot mix them)."""
    rows = F.reshape(-1, 3, 3)[:CHECK_PARTICLES]
    noise = torch.randn(rows.shape, generator=torch.Generator().manual_seed(1), dtype=F.dtype)
    rows = torch.cat([rows, rows + 0.05 * noise])
    parameters = law.graph_parameters
    F_torch = rows.clone().requires_grad_(True)
    try:
        with torch.enable_grad(), stable_linalg():
            expected = law.torch_forward(F_torch)
            if not torch.isfinite(expected).all():
                return False
            seed = torch.randn(expected.shape, generator=torch.Generator().manual_seed(2),
                               dtype=F.dtype)  # fmt: skip
            grads = torch.autograd.grad((expected * seed).sum(), [F_torch, *parameters],
                                        allow_unused=True)  # fmt: skip
            half = rows.shape[0] // 2
            split = torch.cat([law.torch_forward(rows[:half]), law.torch_forward(rows[half:])])
            flipped = law.torch_forward(rows.flip(0)).flip(0)
    except Exception:  # the law fails in torch: the fit reports how, from torch
        return False
    expected, split, flipped = expected.detach(), split.detach(), flipped.detach()
    tolerance = TOLERANCE.get(F.dtype, 2e-4)
    if not all(_close(other, expected, tolerance) for other in (split, flipped)):
        return False
    F_kernels = rows.clone().requires_grad_(True)
    with torch.enable_grad():
        actual = sl.apply_law(F_kernels, compiled, parameters)
        mine = torch.autograd.grad((actual * seed).sum(), [F_kernels, *parameters],
                                   allow_unused=True)  # fmt: skip
    for theirs, ours, like in zip(grads, mine, [rows, *parameters], strict=True):
        zero = torch.zeros_like(like)
        if not _close(zero if ours is None else ours, zero if theirs is None else theirs,
                      tolerance):  # fmt: skip
            return False
    return _close(actual.detach(), expected, tolerance)


def _close(actual: torch.Tensor, expected: torch.Tensor, tolerance: float) -> bool:
    scale = float(expected.abs().max()) if expected.numel() else 0.0
    return bool(torch.allclose(actual, expected, rtol=tolerance, atol=tolerance * scale + 1e-30,
                               equal_nan=True))  # fmt: skip


# ------------------------------------------------------------------------------ translation

_IGNORED = ("dtype", "device", "layout", "pin_memory", "memory_format", "non_blocking")


def _array(items: list) -> np.ndarray:
    array = np.empty(len(items), dtype=object)
    array[:] = items
    return array


def _tensor(value: Any) -> np.ndarray:
    if isinstance(value, np.ndarray):
        return value
    if isinstance(value, (bool, int, float, sl.Scalar)):
        array = np.empty((), dtype=object)
        array[()] = float(value) if isinstance(value, (bool, int)) else value
        return array
    raise TypeError(f"not a tensor: {type(value).__name__}")


def _allocated(shape: Any, fill: Any = None) -> np.ndarray:
    """An object array of ``shape``: refused beyond :data:`MAX_ELEMENTS` (a law of large
    per-particle tensors stays in torch, so translating it costs no time or memory)."""
    shape = tuple(int(n) for n in shape)
    if math.prod(shape) > MAX_ELEMENTS:
        raise Untranslatable(f"a tensor of {math.prod(shape)} values per particle")
    return np.full(shape, fill, dtype=object)


def _elementwise(function: Callable, *values: Any) -> np.ndarray:
    arrays = np.broadcast_arrays(*[_tensor(v) for v in values])
    out = _allocated(arrays[0].shape)
    for index in np.ndindex(out.shape):
        out[index] = function(*(a[index] for a in arrays))
    return out


def _op(name: str) -> Callable:
    return lambda *values: _elementwise(lambda *a: sl.apply(name, *a), *values)


def _scaled(value: Any, alpha: Any) -> Any:
    return value if alpha == 1 else _elementwise(lambda a: sl.apply("mul", a, alpha), value)


def _lifted(name: str, operation: sl.Operation) -> Callable:
    """The rule of an ATen overload that is ``operation`` applied element-wise: ATen's
    ``alpha`` scales the second argument first (add, sub), a ``rounding_mode`` (div) is
    refused, and so is a tensor where the operation takes a constant (a power's exponent)."""

    def rule(*args, alpha=1, rounding_mode=None):
        if rounding_mode is not None:
            raise NotImplementedError("rounding division")
        for position in operation.constants:
            if position < len(args) and isinstance(args[position], np.ndarray):
                raise NotImplementedError(f"a tensor as argument {position} of {name}")
        if alpha != 1:
            args = (args[0], _scaled(args[1], alpha), *args[2:])
        return _op(name)(*args)

    return rule


def _rsub(a, b, alpha=1):
    return _op("sub")(b, _scaled(a, alpha))


def _clamp(x, min=None, max=None):  # noqa: A002 - ATen's names
    if min is not None:
        x = _elementwise(lambda v, low: sl.select(sl.apply("lt", v, low), low, v), x, min)
    if max is not None:
        x = _elementwise(lambda v, high: sl.select(sl.apply("gt", v, high), high, v), x, max)
    return _tensor(x)


def _relu(x):
    return _elementwise(lambda a: sl.select(sl.apply("le", a, 0.0), 0.0, a), x)


def _maximum(a, b, larger=True):
    def one(x, y):
        first = sl.apply("gt" if larger else "lt", x, y)
        second = sl.apply("lt" if larger else "gt", x, y)
        tie = sl.apply("mul", sl.apply("add", x, y), 0.5)  # torch splits a tie's gradient
        return sl.select(first, x, sl.select(second, y, tie))

    return _elementwise(one, a, b)


def _axes(x: np.ndarray, dims: Any) -> tuple[int, ...]:
    if dims is None or dims == []:
        return tuple(range(x.ndim))
    dims = [dims] if isinstance(dims, int) else dims
    return tuple(sorted(d % x.ndim for d in dims))


def _sum(x, dims=None, keepdim=False):
    x = _tensor(x)
    axes = _axes(x, dims)
    if not axes:
        return x
    moved = np.moveaxis(x, axes, range(-len(axes), 0))
    flat = moved.reshape(*moved.shape[: moved.ndim - len(axes)], -1)
    out = _allocated(flat.shape[:-1])
    for index in np.ndindex(out.shape):
        out[index] = _total(flat[index])
    if keepdim:
        out = np.expand_dims(out, axes)
    return out


def _total(items: Any) -> Any:
    """The sum of ``items``, added in order (as a reduction adds them)."""
    total: Any = 0.0
    for item in items:
        total = sl.apply("add", total, item)
    return total


def _mean(x, dims=None, keepdim=False):
    x = _tensor(x)
    count = math.prod(x.shape[a] for a in _axes(x, dims))
    return _op("div")(_sum(x, dims, keepdim), float(count))


def _softmax(x, dim, half_to_float=False):
    x = _tensor(x)
    axis = dim % x.ndim
    moved = np.moveaxis(x, axis, -1)
    out = _allocated(moved.shape)
    for index in np.ndindex(moved.shape[:-1]):
        row = moved[index]
        top = row[0]
        for item in row[1:]:
            top = sl.select(sl.apply("gt", item, top), item, top)
        exps = [sl.apply("exp", sl.apply("sub", item, top)) for item in row]
        total = _total(exps)
        out[index] = [sl.apply("div", e, total) for e in exps]
    return np.moveaxis(out, -1, axis)


def _view(x, sizes):
    return _tensor(x).reshape([int(s) for s in sizes])


def _expand(x, sizes, implicit=False):
    x = _tensor(x)
    sizes = [int(s) for s in sizes]
    lead = len(sizes) - x.ndim
    shape = [x.shape[i - lead] if s == -1 else s for i, s in enumerate(sizes)]
    return np.broadcast_to(x, shape)


def _transpose(x, a, b):
    return np.swapaxes(_tensor(x), a, b)


def _select(x, dim, index):
    return np.take(_tensor(x), index, axis=dim)


def _slice(x, dim=0, start=None, end=None, step=1):
    x = _tensor(x)
    index = [slice(None)] * x.ndim
    index[dim] = slice(start, end, step)
    return x[tuple(index)]


def _squeeze(x, dims=None):
    x = _tensor(x)
    if dims is None:
        return x.reshape([s for s in x.shape if s != 1])
    dims = [dims] if isinstance(dims, int) else dims
    keep = [s for i, s in enumerate(x.shape) if not (i in [d % x.ndim for d in dims] and s == 1)]
    return x.reshape(keep)


def _diag_embed(x, offset=0, dim1=-2, dim2=-1):
    if offset != 0 or (dim1, dim2) not in ((-2, -1), (-1, -2)):
        raise NotImplementedError("diag_embed off the last two dimensions")
    x = _tensor(x)
    n = x.shape[-1]
    out = _allocated((*x.shape, n), 0.0)
    for i in range(n):
        out[..., i, i] = x[..., i]
    return out


def _diagonal(x, offset=0, dim1=0, dim2=1):
    return np.diagonal(_tensor(x), offset, dim1, dim2)


def _eye(n, m=None):
    out = _allocated((n, n if m is None else m), 0.0)
    for i in range(min(out.shape)):
        out[i, i] = 1.0
    return out


def _full(size, value):
    return _allocated(size, float(value))


def _cat(tensors, dim=0):
    return np.concatenate([_tensor(t) for t in tensors], axis=dim)


def _stack(tensors, dim=0):
    return np.stack([_tensor(t) for t in tensors], axis=dim)


def _matmul(a, b):
    a, b = _tensor(a), _tensor(b)
    if a.ndim >= 2 and b.ndim >= 2:  # refuse a large product before computing it
        batch = np.broadcast_shapes(a.shape[:-2], b.shape[:-2])
        _allocated((*batch, a.shape[-2], b.shape[-1]))
    return np.matmul(a, b)


def _det(A):
    A = _tensor(A)
    if A.shape[-2:] != (3, 3):
        raise NotImplementedError("a determinant of a matrix other than 3x3")
    a, b, c, d, e, f, g, h, i = (A[..., k // 3, k % 3] for k in range(9))
    return (a * (e * i - f * h) + b * (f * g - d * i) + c * (d * h - e * g), None, None)


def _inverse(A, check_errors=False):
    A = _tensor(A)
    if A.shape[-2:] != (3, 3):
        raise NotImplementedError("an inverse of a matrix other than 3x3")
    a, b, c, d, e, f, g, h, i = (A[..., k // 3, k % 3] for k in range(9))
    cof = [e * i - f * h, f * g - d * i, d * h - e * g, c * h - b * i, a * i - c * g,
           b * g - a * h, b * f - c * e, c * d - a * f, a * e - b * d]  # fmt: skip
    det = a * cof[0] + b * cof[1] + c * cof[2]
    rows = [[cof[3 * col + row] / det for col in range(3)] for row in range(3)]
    out = _allocated(A.shape)
    for row in range(3):
        for col in range(3):
            out[..., row, col] = rows[row][col]
    return out, _allocated(A.shape[:-2], 0.0)


def _svd_tolerance(dtype: torch.dtype) -> float:
    """The clamp of :mod:`bridges.linalg`'s SVD gradient: the square root of the epsilon."""
    return torch.finfo(dtype).eps ** 0.5


_SVD = "aten._linalg_svd.default"


def _factors(inputs: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """U (1, 3, 3), S (1, 3), Vh (1, 3, 3) in torch's convention (S >= 0) from the program's 21
    inputs ``inputs``: the signed SVD (rotations, S[2] of det F's sign) that
    :func:`bridges.scalar_law.apply_law` computes, its last column of U and last singular value
    negated where S[2] < 0, as :func:`bridges.linalg.svd` does for ``signed=False``."""
    U, S = _array(inputs[:9]).reshape(1, 3, 3), _array(inputs[9:12]).reshape(1, 3)
    flip = sl.apply("lt", S[0, 2], 0.0)
    U[0, :, 2] = [sl.select(flip, -u, u) for u in U[0, :, 2]]
    S[0, 2] = abs(S[0, 2])
    return U, S, _array(inputs[12:]).reshape(1, 3, 3)


def _svd_rule(A, full_matrices=True, compute_uv=True, driver=None, *, F: np.ndarray,
              factors: tuple | None, inline: Callable | None):  # fmt: skip
    """An SVD: of the law's input ``F`` itself the ``factors`` where given, else the
    ``inline`` Jacobi sweeps where given."""
    A = _tensor(A)
    if not compute_uv or driver is not None:
        raise NotImplementedError("an SVD without U and Vh, or with a driver")
    if factors is not None and A is F:
        return factors
    if inline is None:
        raise NotImplementedError("an SVD of something other than F")
    return inline(A)


def _svd(A, *, tolerance: float):
    if A.shape[-2:] != (3, 3):
        raise NotImplementedError("an SVD other than of 3x3 matrices with U and Vh")
    U, S, Vh = _allocated(A.shape), _allocated(A.shape[:-1]), _allocated(A.shape)
    for index in np.ndindex(A.shape[:-2]):
        parts = sl.svd(list(A[index].reshape(-1)), tolerance)
        U[index] = np.array(parts[:9], dtype=object).reshape(3, 3)
        S[index] = parts[9:12]
        Vh[index] = np.array(parts[12:], dtype=object).reshape(3, 3)
    return U, S, Vh


def _same(x, *_, **__):
    return _tensor(x)


def _like(value):
    return lambda x, *_, **__: _allocated(_tensor(x).shape, value)


def _full_like(x, value, **_):
    return _allocated(_tensor(x).shape, float(value))


def _new(value):
    return lambda x, size, *_, **__: _allocated(size, value)


#: How each ATen operation a law graph may hold is written out: those that are one operation
#: of the program element-wise as its table entry says (``bridges.scalar_law.OPERATIONS``),
#: the others as compositions of them or as reshaping of the arrays.
RULES: dict[str, Callable] = {
    **{overload: _lifted(name, operation) for name, operation in sl.OPERATIONS.items()
       for overload in operation.aten},
    "aten.rsub.Scalar": _rsub, "aten.rsub.Tensor": _rsub,
    "aten.reciprocal.default": lambda x: _op("div")(1.0, x),
    "aten.rsqrt.default": lambda x: _op("div")(1.0, _op("sqrt")(x)),
    "aten.square.default": lambda x: _op("mul")(x, x),
    "aten.sigmoid.default": lambda x: _op("div")(1.0, _op("add")(1.0, _op("exp")(_op("neg")(x)))),
    "aten.relu.default": _relu,
    "aten.clamp.default": _clamp, "aten.clip.default": _clamp, "aten.clamp.Tensor": _clamp,
    "aten.clamp_min.default": lambda x, m: _clamp(x, m, None),
    "aten.clamp_max.default": lambda x, m: _clamp(x, None, m),
    "aten.maximum.default": _maximum,
    "aten.minimum.default": lambda a, b: _maximum(a, b, larger=False),
    "aten.sum.dim_IntList": _sum, "aten.sum.default": lambda x, **_: _sum(x),
    "aten.mean.dim": _mean, "aten.mean.default": lambda x, **_: _mean(x),
    "aten._softmax.default": _softmax,
    "aten.view.default": _view, "aten.reshape.default": _view, "aten._unsafe_view.default": _view,
    "aten.expand.default": _expand,
    "aten.permute.default": lambda x, dims: np.transpose(_tensor(x), dims),
    "aten.transpose.int": _transpose, "aten.t.default": lambda x: _tensor(x).T,
    "aten.unsqueeze.default": lambda x, d: np.expand_dims(_tensor(x), d % (_tensor(x).ndim + 1)),
    "aten.squeeze.dim": _squeeze, "aten.squeeze.dims": _squeeze, "aten.squeeze.default": _squeeze,
    "aten.select.int": _select, "aten.slice.Tensor": _slice,
    "aten.cat.default": _cat, "aten.stack.default": _stack,
    "aten.diag_embed.default": _diag_embed, "aten.diagonal.default": _diagonal,
    "aten.eye.default": _eye, "aten.eye.m": _eye,
    "aten.zeros_like.default": _like(0.0), "aten.ones_like.default": _like(1.0),
    "aten.full_like.default": _full_like,
    "aten.zeros.default": lambda size, **_: _full(size, 0.0),
    "aten.ones.default": lambda size, **_: _full(size, 1.0),
    "aten.full.default": lambda size, value, **_: _full(size, value),
    "aten.new_zeros.default": _new(0.0), "aten.new_ones.default": _new(1.0),
    "aten.scalar_tensor.default": lambda value, **_: _tensor(float(value)),
    "aten.clone.default": _same, "aten.alias.default": _same, "aten.contiguous.default": _same,
    "aten._to_copy.default": _same, "aten.lift_fresh_copy.default": _same,
    "aten.bmm.default": _matmul, "aten.mm.default": _matmul, "aten.matmul.default": _matmul,
    "aten._linalg_det.default": _det, "aten.linalg_inv_ex.default": _inverse,
    # torch raises for a singular matrix here; the kernels give inf or NaN, and the fit stops
    "aten._linalg_check_errors.default": lambda *_, **__: None,
    "aten.sym_size.int": lambda x, d: _tensor(x).shape[d],
    "operator.getitem": lambda values, index: values[index],
    **{f"operator.{name}": getattr(operator, name)
       for name in ("add", "sub", "mul", "floordiv", "truediv", "mod", "neg", "pow")},
}  # fmt: skip
