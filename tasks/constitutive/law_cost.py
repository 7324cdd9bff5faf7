"""What a captured law costs, estimated from its graph before any fit: sizes, not values.

A captured graph is small data but can ask for a lot of work: ``torch.ones(1024, 1024, 256)``
is one node with three integers, yet a gigabyte at every step of the fit; ``flat @ flat.T`` on
the (B, 9) flattened F is one node too, yet B x B values. The capture runs on fake tensors and
never notices. :func:`check_cost` runs the graph's operations on ``meta`` tensors (shapes
only: nothing is allocated or computed) at a few batch sizes B, in lockstep, and reads each
intermediate's size as ``per_particle * B + fixed``. It refuses, with a sentence the next
prompt can use, a graph where

- an intermediate grows faster than the number of particles (a (B, B) product);
- an intermediate that does not scale with the particles holds more than
  :data:`MAX_FIXED_ELEMENTS` values (a constant 1 GB tensor), or all of them together more than
  :data:`MAX_FIXED_TOTAL`;
- an intermediate holds more than :data:`MAX_PER_PARTICLE` values per particle;
- the values touched per particle at every step (the sum over intermediates, the estimated
  cost) exceed :data:`MAX_COST`, far beyond what the seed, ground-truth and GP laws touch.

Nothing of a candidate runs here: the operations are the allowed ATen operations the graph
names (:mod:`tasks.constitutive.law_ops`), applied to tensors that hold no data, and factories
are always given the meta device. A value-dependent size (``x[mask]``) is taken at its largest
(every element selected). The shapes of the common operations (elementwise, reductions,
products, the linear algebra of 3x3 laws, indexing) are computed here: ATen's meta kernels for
them are written in Python and import sympy and ``torch._dynamo`` (over a second), which a fit
worker otherwise never loads (tested). The rest run as ATen's meta kernels.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import torch

from tasks.constitutive import law_ops

if TYPE_CHECKING:
    from tasks.constitutive.law_graph import LawGraph

#: Batch sizes the graph is sized at: two to read ``per_particle * B + fixed``, a larger one
#: to see whether anything grows faster than B (beyond the scenes' 1,000 particles).
BATCHES = (1_000, 2_000, 100_000)
#: Most values an intermediate that does not scale with the particles may hold (as many as the
#: graph's constants together may, :data:`~tasks.constitutive.law_graph.MAX_CONSTANT_ELEMENTS`).
MAX_FIXED_ELEMENTS = 100_000
#: Most values all such intermediates may hold together, per step.
MAX_FIXED_TOTAL = 1_000_000
#: Most values per particle one intermediate may hold (as in the compiled kernels; a 3x3 law's
#: largest intermediates hold 9 to 21, an SVD's three factors together).
MAX_PER_PARTICLE = 4096
#: Most values per particle all intermediates together may hold, per step: the estimated cost.
#: The seed and ground-truth laws touch 74 to 440, the capture's warm-up law 618 and random GP
#: laws up to about 650 (tests/tasks/constitutive/test_law_cost.py prints them): 30x and more.
MAX_COST = 20_000
#: Most tensors one operation may return (a split into pieces per particle is refused).
MAX_PIECES = 256
#: How much faster than linear between the sizes counts as growing faster than B (a size
#: rounded down, such as B // 3, is slightly sublinear).
_SLACK = 1.01


@dataclass(frozen=True)
class NodeCost:
    """One intermediate's size: ``per_particle * B + fixed`` values; its shape at B = 1,000."""

    op: str
    shape: str
    per_particle: float
    fixed: float


@dataclass(frozen=True)
class LawCost:
    """A graph's estimated cost per step: values touched per particle, and those that do not
    scale with the particles; every intermediate's size."""

    per_particle: float
    fixed: float
    nodes: tuple[NodeCost, ...]


class CostRefused(ValueError):
    """The law costs too much (or cannot be sized); the message says why, for the model."""


class _Refused(Exception):
    """Raised inside the sizing with the sentence of the refusal."""


class _Unrunnable(Exception):
    """An operation of the graph fails on tensors of the shapes it is given."""

    def __init__(self, op: str, batch: int, error: BaseException) -> None:
        super().__init__(op)
        self.op, self.batch, self.kind = _short(op), batch, type(error).__name__


def check_cost(graph: LawGraph, operation: Callable[[str], Callable[..., Any]]) -> LawCost:
    """The graph's estimated cost, or :class:`CostRefused` with the reason it is refused.

    ``operation`` maps an operation's name to ATen's callable
    (:func:`tasks.constitutive.law_graph.aten_operation`); what it raises is passed on.
    """
    try:
        return _estimate(graph, operation)
    except _Refused as refusal:
        raise CostRefused(str(refusal)) from None
    except _Unrunnable as error:
        raise CostRefused(
            f"the law's graph cannot be run on {error.batch:,} particles ({error.op} raises "
            f"{error.kind}): write it for any number of particles B"
        ) from None


def _estimate(graph: LawGraph, operation: Callable[[str], Callable[..., Any]]) -> LawCost:
    """Every intermediate's size, the totals; raises :class:`_Refused` past a budget."""
    runs = [_Run(graph, batch, operation) for batch in BATCHES]
    nodes: list[NodeCost] = []
    for index, (op, args, kwargs) in enumerate(graph.nodes):
        small = [run.step(index, op, args, kwargs) for run in runs[:2]]
        cost = _linear(op, *small, runs[0].batch, runs[1].batch)
        try:
            large, _ = runs[2].step(index, op, args, kwargs)
        except _Unrunnable:  # a size beyond int64, say, where it was fine at fewer particles
            _check_node(cost, small[0][0])
            raise _Refused(_faster_than_b(cost)) from None
        slope = (large - small[1][0]) / (runs[2].batch - runs[1].batch)
        if slope > _SLACK * cost.per_particle + 1e-3:
            raise _Refused(_faster_than_b(cost))
        _check_node(cost, small[0][0])
        nodes.append(cost)
    total = LawCost(sum(n.per_particle for n in nodes), sum(n.fixed for n in nodes), tuple(nodes))
    if total.fixed > MAX_FIXED_TOTAL:
        raise _Refused(
            f"the law's tensors that do not scale with the particles hold {total.fixed:,.0f} "
            f"values together at every step, more than the {MAX_FIXED_TOTAL:,} allowed; {_KEEP}"
        )
    if total.per_particle > MAX_COST:
        raise _Refused(
            f"the law is too costly: its intermediates hold about {total.per_particle:,.0f} "
            f"values per particle at every step, more than the {MAX_COST:,} allowed (the "
            "ground-truth laws need under 500): compute the stress or the return mapping "
            "directly, with few batched operations on (B, 3, 3) and (B, 3) tensors"
        )
    return total


_KEEP = ("keep every intermediate per particle, shaped (B, ...) with a few values per particle, "
         "and drop tensors that do not contribute")  # fmt: skip


def _check_node(cost: NodeCost, elements: int) -> None:
    if cost.fixed > MAX_FIXED_ELEMENTS:
        raise _Refused(
            f"the law keeps a constant tensor of {cost.fixed:,.0f} elements (shape {cost.shape}, "
            f"from {cost.op}) that does not scale with the particles, more than the "
            f"{MAX_FIXED_ELEMENTS:,} allowed at every step; {_KEEP}"
        )
    if cost.per_particle > MAX_PER_PARTICLE:
        raise _Refused(
            f"the law builds an intermediate of {cost.per_particle:,.0f} values per particle "
            f"(shape {cost.shape}, from {cost.op}, {elements:,} values at {BATCHES[0]:,} "
            f"particles), more than the {MAX_PER_PARTICLE:,} allowed; {_KEEP}"
        )


def _faster_than_b(cost: NodeCost) -> str:
    return (
        f"the law builds an intermediate of shape {cost.shape} (from {cost.op}) whose size grows "
        "faster than the number of particles B: it mixes particles with each other (an outer "
        "product of the batch with itself, say), and a law maps each particle's F on its own; "
        "keep every intermediate per particle, shaped (B, ...), and reduce over a particle's "
        "own dimensions, never across particles"
    )


def _linear(
    op: str, first: tuple[int, tuple], second: tuple[int, tuple], b1: int, b2: int
) -> NodeCost:
    (n1, shape1), (n2, shape2) = first, second
    per_particle = (n2 - n1) / (b2 - b1)
    fixed = max(n1 - per_particle * b1, 0.0)
    return NodeCost(_short(op), _shape_text(shape1, shape2, b1, b2), per_particle, fixed)


def _shape_text(shape1: tuple, shape2: tuple, b1: int, b2: int) -> str:
    """``(B, B)``, ``(1024, 1024, 256)``: dims that follow the batch size written with B."""
    if not shape1:
        return "()"
    parts = []
    for d1, d2 in zip(shape1, shape2, strict=False):
        if d1 == d2:
            parts.append(f"{d1}")
        elif d1 * b2 == d2 * b1:
            ratio = d1 // b1 if d1 % b1 == 0 else d1 / b1
            parts.append("B" if ratio == 1 else f"{ratio}B")
        else:
            parts.append(f"{d1} at B = {b1:,}")
    return "(" + ", ".join(parts) + ")"


def _short(op: str) -> str:
    """``aten.mm.default`` -> ``torch.mm``: what the law called, near enough."""
    parts = op.split(".")
    return f"torch.{parts[1]}" if len(parts) == 3 and parts[0] == "aten" else op


class _Run:
    """The graph's values at one batch size, as meta tensors (shapes without data)."""

    def __init__(
        self, graph: LawGraph, batch: int, operation: Callable[[str], Callable[..., Any]]
    ) -> None:
        self.batch, self.operation = batch, operation
        meta = {"device": "meta", "dtype": torch.float32}
        self.inputs: dict[str, list[Any]] = {
            "input": [torch.empty(batch, 3, 3, **meta)],
            "param": [torch.empty(t.shape, **meta) for t in graph.parameters.values()],
            "constant": [torch.empty(t.shape, **_dtype(t.dtype)) for t in graph.constants],
            "node": [],
        }

    def step(self, index: int, op: str, args: list, kwargs: dict) -> tuple[int, tuple]:
        """Run node ``index``; its number of values and its (first tensor's) shape."""
        assert len(self.inputs["node"]) == index
        target = self.operation(op)
        try:
            args = self._resolve(args)
            kwargs = {key: self._resolve(value) for key, value in kwargs.items()}
            if isinstance(target, torch._ops.OpOverload):
                if any(argument.name == "device" for argument in target._schema.arguments):
                    kwargs["device"] = torch.device("meta")  # never a tensor with data
            else:
                _check_integers(op, args)
            value = _meta_call(op, target, args, kwargs)
        except Exception as error:  # whatever the operation raises on these shapes
            raise _Unrunnable(op, self.batch, error) from None
        self.inputs["node"].append(value)
        tensors = _tensors(value)
        if len(tensors) > MAX_PIECES:
            raise _Refused(
                f"the law splits a tensor into {len(tensors):,} pieces ({_short(op)}) at "
                f"{self.batch:,} particles; {_KEEP}"
            )
        shape = tuple(tensors[0].shape) if tensors else ()
        return sum(t.numel() for t in tensors), shape

    def _resolve(self, value: Any) -> Any:
        if isinstance(value, list):
            return [self._resolve(item) for item in value]
        if isinstance(value, dict):
            ((kind, payload),) = value.items()
            if kind in self.inputs:
                return self.inputs[kind][payload]
            return _literal(kind, payload)
        return value


def _check_integers(op: str, args: list) -> None:
    """Python arithmetic on sizes stays within 64 bits (``10 ** 10 ** 9`` would take minutes)."""
    numbers = [value for value in args if isinstance(value, int)]
    if any(abs(n) >= 2**63 for n in numbers) or (
        op == "operator.pow" and len(numbers) == 2 and abs(numbers[1]) > 64
    ):
        raise OverflowError("an integer of the graph leaves the 64-bit range")


def _meta_call(op: str, target: Callable[..., Any], args: list, kwargs: dict) -> Any:
    """The operation on meta tensors; masks selecting elements taken at their largest."""
    name = op.split(".")[1] if op.startswith("aten.") else ""
    if isinstance(target, torch._ops.OpOverload):
        if torch.Tag.pointwise in target.tags:
            return _pointwise(name, [*args, *kwargs.values()])
        shaped = _SHAPES.get(name)
        if shaped is not None:
            return shaped(_bound(target, args, kwargs))
    if name == "index_put":  # the result has the input's shape, whatever the indices select
        return _like(args[0], args[0].shape)
    if name == "index" and len(args) > 1:
        return _indexed(args[0], _largest_selection(args[1]))
    return target(*args, **kwargs)


def _indexed(tensor: torch.Tensor, indices: list) -> torch.Tensor:
    """``tensor[indices]`` with integer index tensors (or None): NumPy's advanced indexing."""
    if len(indices) > tensor.dim():
        raise IndexError("too many indices for the tensor")
    dims = list(tensor.shape)
    taken = [i for i, index in enumerate(indices) if index is not None]
    if not taken:
        return _like(tensor, dims)
    selected = list(_broadcast([tuple(indices[i].shape) for i in taken]))
    kept = [n for i, n in enumerate(dims) if i not in taken]
    if taken == list(range(taken[0], taken[-1] + 1)):
        return _like(tensor, [*dims[: taken[0]], *selected, *dims[taken[-1] + 1 :]])
    return _like(tensor, [*selected, *kept])


def _pointwise(name: str, operands: list) -> torch.Tensor:
    """An elementwise operation's result: its tensor operands' shapes broadcast (computed
    here because ATen's meta kernels of these operations load torch's compiler stack)."""
    tensors = [value for value in operands if isinstance(value, torch.Tensor)]
    shape = _broadcast([tuple(tensor.shape) for tensor in tensors])
    values = [tensor.dtype for tensor in tensors if tensor.dtype != torch.bool]
    dtype = torch.bool if name in _TESTS or not values else values[0]
    return torch.empty(shape, dtype=dtype, device="meta")


def _bound(target: torch._ops.OpOverload, args: list, kwargs: dict) -> dict[str, Any]:
    """The operation's arguments by name, defaults filled in."""
    bound = {}
    for index, argument in enumerate(target._schema.arguments):
        if index < len(args):
            bound[argument.name] = args[index]
        elif argument.name in kwargs:
            bound[argument.name] = kwargs[argument.name]
        else:
            bound[argument.name] = argument.default_value if argument.has_default_value() else None
    return bound


def _reduced(a: dict[str, Any]) -> torch.Tensor:
    """A reduction over ``dim`` (every dimension when None or empty), ``keepdim`` or not."""
    tensor, dim = a["self"], a.get("dim")
    rank = tensor.dim()
    dims = [] if dim is None else [dim] if isinstance(dim, int) else list(dim)
    if any(not -max(rank, 1) <= d < max(rank, 1) for d in dims):
        raise IndexError("a reduction's dimension is out of range")
    dims = {d % max(rank, 1) for d in dims} or set(range(rank))
    keep = bool(a.get("keepdim"))
    shape = [1 if i in dims else n for i, n in enumerate(tensor.shape) if keep or i not in dims]
    return _like(tensor, shape)


def _diag_embed(a: dict[str, Any]) -> torch.Tensor:
    tensor, offset = a["self"], abs(a.get("offset") or 0)
    dims = sorted(d % (tensor.dim() + 1) for d in (a.get("dim1", -2), a.get("dim2", -1)))
    shape = list(tensor.shape[:-1])
    side = tensor.shape[-1] + offset
    for d in dims:
        shape.insert(d, side)
    return torch.empty(shape, dtype=tensor.dtype, device="meta")


def _joined(a: dict[str, Any], new_dim: bool) -> torch.Tensor:
    """``cat`` (``new_dim`` False) or ``stack`` of ``tensors`` along ``dim``."""
    tensors = [t for t in a["tensors"] if not (t.dim() == 1 and t.numel() == 0 and not new_dim)]
    first = list(tensors[0].shape)
    dim = (a.get("dim") or 0) % (len(first) + new_dim)
    if new_dim:
        if any(list(t.shape) != first for t in tensors):
            raise RuntimeError("stack expects each tensor to be equal size")
        first.insert(dim, len(tensors))
    else:
        if any(len(t.shape) != len(first) or [*t.shape[:dim], *t.shape[dim + 1:]] !=
               [*first[:dim], *first[dim + 1:]] for t in tensors):  # fmt: skip
            raise RuntimeError("cat expects tensors of matching sizes but in the dimension")
        first[dim] = sum(t.shape[dim] for t in tensors)
    return torch.empty(first, dtype=tensors[0].dtype, device="meta")


def _like(tensor: torch.Tensor, shape: Any, dtype: torch.dtype | None = None) -> torch.Tensor:
    return torch.empty(tuple(shape), dtype=dtype or tensor.dtype, device="meta")


def _square(a: dict[str, Any]) -> torch.Tensor:
    """The (..., n, n) argument of a linear-algebra operation, checked square."""
    matrix = a.get("A", a.get("self"))
    if matrix.dim() < 2 or matrix.shape[-1] != matrix.shape[-2]:
        raise RuntimeError("a linear-algebra operation needs square matrices")
    return matrix


def _svd(a: dict[str, Any]) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    A = a["A"]
    if A.dim() < 2:
        raise RuntimeError("svd needs matrices")
    *batch, m, n = A.shape
    k = min(m, n)
    full = a.get("full_matrices", True) and a.get("compute_uv", True)
    uv = a.get("compute_uv", True)
    U = _like(A, [*batch, m, m if full else k] if uv else [0])
    Vh = _like(A, [*batch, n if full else k, n] if uv else [0])
    return U, _like(A, [*batch, k]), Vh


def _det(a: dict[str, Any]) -> Any:
    A = _square(a)
    det = _like(A, A.shape[:-2])
    if a.get("A") is None:  # det, linalg_det: the determinant alone
        return det
    return det, _like(A, A.shape), _like(A, A.shape[:-1], torch.int32)


def _eigh(a: dict[str, Any]) -> tuple[torch.Tensor, torch.Tensor]:
    A = _square(a)
    vectors = A.shape if a.get("compute_v", True) else [0]
    return _like(A, A.shape[:-1]), _like(A, vectors)


def _matmul(first: torch.Tensor, second: torch.Tensor) -> torch.Tensor:
    """``torch.matmul``'s result shape: vectors promoted to matrices, batches broadcast."""
    a, b = list(first.shape), list(second.shape)
    if not a or not b:
        raise RuntimeError("a matrix product needs tensors of at least one dimension")
    left, right = len(a) == 1, len(b) == 1
    a, b = [1, *a] if left else a, [*b, 1] if right else b
    if a[-1] != b[-2]:
        raise RuntimeError(f"matrix shapes {tuple(first.shape)} and {tuple(second.shape)} "
                           "cannot be multiplied")  # fmt: skip
    shape = [*_broadcast([tuple(a[:-2]), tuple(b[:-2])]), a[-2], b[-1]]
    if right:
        shape.pop(-1)
    if left:
        shape.pop(-2 if not right else -1)
    return _like(first, shape)


def _product(a: dict[str, Any], rank: int) -> torch.Tensor:
    """``mm`` (rank 2), ``bmm`` (rank 3), ``mv`` and ``dot``: ranks checked, then matmul's."""
    first = a["self"]
    second = next(a[k] for k in ("mat2", "vec", "tensor") if a.get(k) is not None)
    if first.dim() != rank or second.dim() != (1 if "vec" in a or "tensor" in a else rank):
        raise RuntimeError("a matrix product's operands have the wrong number of dimensions")
    if rank == 3 and first.shape[0] != second.shape[0]:
        raise RuntimeError("bmm's batches differ")
    return _matmul(first, second)


#: Shapes computed here for operations whose ATen meta kernels are written in Python and load
#: torch's compiler stack or sympy (over a second, which a fit worker otherwise never pays).
_SHAPES: dict[str, Callable[[dict[str, Any]], Any]] = {
    **dict.fromkeys(("sum", "mean", "amax", "amin", "linalg_vector_norm", "logsumexp", "prod",
                     "norm", "std", "var", "any", "all"), _reduced),  # fmt: skip
    **dict.fromkeys(("zeros_like", "ones_like", "full_like", "empty_like", "_softmax",
                     "_log_softmax", "softmax", "log_softmax", "cumsum", "cumprod", "flip",
                     "roll", "tril", "triu", "fill", "zero", "copy", "detach", "alias"),
                    lambda a: _like(a["self"], a["self"].shape)),  # fmt: skip
    "diag_embed": _diag_embed,
    "eye": lambda a: torch.empty(a["n"], a["m"] if a.get("m") is not None else a["n"],
                                 device="meta"),  # fmt: skip
    "matmul": lambda a: _matmul(a["self"], a["other"]),
    "mm": lambda a: _product(a, 2),
    "bmm": lambda a: _product(a, 3),
    "mv": lambda a: _product(a, 2),
    "dot": lambda a: _product(a, 1),
    "outer": lambda a: _like(a["self"], [*a["self"].shape, *a["vec2"].shape]),
    "_linalg_svd": _svd,
    **dict.fromkeys(("_linalg_det", "linalg_det", "det"), _det),
    **dict.fromkeys(("_linalg_eigh", "linalg_eigh"), _eigh),
    **dict.fromkeys(("inverse", "linalg_inv"), lambda a: _like(_square(a), _square(a).shape)),
    "linalg_inv_ex": lambda a: (_like(_square(a), _square(a).shape),
                                _like(_square(a), _square(a).shape[:-2], torch.int32)),
    "_linalg_check_errors": lambda a: None,
    "cat": lambda a: _joined(a, new_dim=False),
    "stack": lambda a: _joined(a, new_dim=True),
}


def _broadcast(shapes: list[tuple[int, ...]]) -> tuple[int, ...]:
    """Shapes broadcast together (``torch.broadcast_shapes``, without its import of sympy)."""
    result: list[int] = []
    for shape in shapes:
        padded = [1] * (len(shape) - len(result)) + result
        shape = (1,) * (len(padded) - len(shape)) + shape
        for index, (mine, theirs) in enumerate(zip(padded, shape, strict=True)):
            if mine != theirs and 1 not in (mine, theirs):
                raise RuntimeError(f"shapes {tuple(padded)} and {shape} do not broadcast")
            padded[index] = theirs if mine == 1 else mine
        result = padded
    return tuple(result)


#: Elementwise operations whose result is boolean.
_TESTS = frozenset({"eq", "ne", "lt", "le", "gt", "ge", "isfinite", "isinf", "isnan",
                    "logical_and", "logical_or", "logical_xor", "logical_not"})  # fmt: skip


def _largest_selection(indices: list) -> list:
    """Boolean masks replaced by the integer indices of a mask selecting everything."""
    result: list = []
    for index in indices:
        if isinstance(index, torch.Tensor) and index.dtype == torch.bool:
            count = index.numel()
            empty = torch.empty(count, dtype=torch.long, device="meta")
            result.extend(empty for _ in range(max(index.dim(), 1)))
        else:
            result.append(index)
    return result


def _literal(kind: str, payload: str) -> Any:
    if kind == "float":
        return float(payload)
    if kind == "str":
        return payload
    if kind == "dtype":
        return torch.float32 if payload in law_ops.FLOAT_DTYPES else getattr(torch, payload)
    if kind == "device":
        return torch.device("meta")
    if kind == "layout":
        return torch.strided
    return getattr(torch, payload)  # memory_format, checked against law_ops.MEMORY_FORMATS


def _dtype(name: str) -> dict[str, Any]:
    dtype = torch.float32 if name in law_ops.FLOAT_DTYPES else getattr(torch, name)
    return {"device": "meta", "dtype": dtype}


def _tensors(value: Any) -> list[torch.Tensor]:
    if isinstance(value, torch.Tensor):
        return [value]
    if isinstance(value, (list, tuple)):
        return [t for item in value for t in _tensors(item)]
    return []


def describe(cost: LawCost) -> str:
    """One line: values per particle per step, and those that do not scale with particles."""
    return (f"about {cost.per_particle:,.0f} values per particle and {cost.fixed:,.0f} fixed "
            f"values per step, in {len(cost.nodes)} operations")  # fmt: skip

