"""A captured law as data, and the trusted side that checks it and turns it back into a module.

A proposed law is code, and code can do anything in the process that runs it. So the law runs
only in the sandboxed capture process (:mod:`tasks.constitutive.law_capture`), which records what
``Physics.forward`` computes as a graph of ATen operations. This module is the trusted side: it
reads that graph from plain JSON (loading it executes nothing), checks every part of it, and
builds a ``torch.nn.Module`` that computes the graph with the law's parameters as
``nn.Parameter`` s. Nothing of the candidate's code or objects ever reaches it.

The JSON document (``FORMAT`` 1)::

    {"format": 1,
     "parameters": [{"name": "log_E", "shape": [], "values": [13.0]}, ...],
     "constants": [{"dtype": "float64", "shape": [3], "values": [...]}, ...],
     "nodes": [{"op": "aten.mul.Tensor", "args": [...], "kwargs": {...}}, ...],
     "output": {"node": 41}}

A value in ``args``, ``kwargs`` and ``output`` is a JSON number, boolean, null or list, or one of
``{"input": 0}`` (the deformation gradient F, (B, 3, 3)), ``{"param": k}``, ``{"constant": k}``,
``{"node": i}`` (the result of an earlier node), ``{"float": "inf"|"-inf"|"nan"}``,
``{"dtype": name}``, ``{"device": "cpu"}``, ``{"layout": "strided"}``,
``{"memory_format": name}`` or ``{"str": text}`` (an einsum equation or a mode: at most 64
letters, digits and ``,.->_`` or spaces; in practice a mode, such as ``rounding_mode``). No
other text travels through a graph except parameter
names, and those are short identifiers.
"""

from __future__ import annotations

import math
import operator
import re
from dataclasses import dataclass
from typing import Any

import torch
from torch import fx, nn

from bridges import closed_form, linalg, products, scalar_law
from tasks.constitutive import law_cost, law_ops

FORMAT = law_ops.GRAPH_FORMAT
MAX_NODES = 4000
MAX_PARAMETERS = 64
MAX_PARAMETER_ELEMENTS = 4096
MAX_CONSTANTS = 64
MAX_CONSTANT_ELEMENTS = 100_000
MAX_NAME_CHARS = 40
MAX_NESTING = 6
#: A parameter name: identifiers joined by dots (a submodule's parameter), or list indices.
NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z0-9_]+)*\Z")
_INT64 = 2**63
_REFERENCES = ("input", "param", "constant", "node")
#: Text an operation may take as an argument (einsum equations, rounding and norm modes).
ARGUMENT_TEXT = re.compile(r"[A-Za-z0-9_,.\-> ]{0,64}\Z")


class LawGraphError(ValueError):
    """The captured graph is malformed or uses something not allowed; one line for the model."""


@dataclass(frozen=True)
class TensorData:
    """A tensor as data: its shape and its values, flattened in row-major order."""

    shape: tuple[int, ...]
    values: tuple[float | int | bool, ...]
    dtype: str = "float64"


@dataclass(frozen=True)
class LawGraph:
    """A checked graph: parameters by name, constants, nodes and the output, all inert data."""

    parameters: dict[str, TensorData]
    constants: list[TensorData]
    nodes: list[tuple[str, list[Any], dict[str, Any]]]
    output: Any

    @classmethod
    def from_json(cls, data: Any) -> LawGraph:
        """Check ``data`` (a parsed JSON document) completely; :class:`LawGraphError` if bad."""
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise LawGraphError(f"not a captured law graph of format {FORMAT}")
        parameters = _parameters(data.get("parameters"))
        constants = _constants(data.get("constants"))
        raw_nodes = data.get("nodes")
        if not isinstance(raw_nodes, list):
            raise LawGraphError("the graph has no list of nodes")
        if len(raw_nodes) > MAX_NODES:
            raise LawGraphError(
                f"the law has {len(raw_nodes)} operations, more than the {MAX_NODES} allowed: "
                "write it with fewer, batched tensor operations (no Python loops over elements)"
            )
        checker = _ValueChecker(len(parameters), len(constants))
        nodes = []
        for index, node in enumerate(raw_nodes):
            if not isinstance(node, dict) or not isinstance(node.get("op"), str):
                raise LawGraphError(f"node {index} is malformed")
            op = node["op"]
            if not law_ops.is_allowed(op):
                raise LawGraphError(
                    f"the law uses {_known(op)}, which is not allowed: {law_ops.HINT}"
                )
            args, kwargs = node.get("args", []), node.get("kwargs", {})
            if not isinstance(args, list) or not isinstance(kwargs, dict):
                raise LawGraphError(f"node {index} is malformed")
            if not all(isinstance(key, str) and key.isidentifier() for key in kwargs):
                raise LawGraphError(f"node {index} has a malformed keyword argument")
            checker.nodes = index
            checked = {key: checker.check(value) for key, value in kwargs.items()}
            nodes.append((op, checker.check(args), checked))
        checker.nodes = len(nodes)
        output = checker.check(data.get("output"))
        if not (isinstance(output, dict) and set(output) <= set(_REFERENCES)):
            raise LawGraphError("the law's output is not a tensor")
        return cls(parameters, constants, nodes, output)


#: Operations that only lay data out (shapes, views, indexing), not counted in a law's size.
LAYOUT = frozenset({"view", "expand", "sym_size", "getitem", "transpose", "unsqueeze",
                    "squeeze", "permute", "reshape", "clone", "_to_copy", "alias", "t",
                    "contiguous", "detach", "lift_fresh_copy"})  # fmt: skip


def captured_graph(artifacts: dict[str, Any] | None) -> Any:
    """The law's graph in what an evaluation left for reports (``{"captured": {"law": ...}}``),
    or None: data as the capture recorded it, not yet checked."""
    return ((artifacts or {}).get("captured") or {}).get("law")


def law_size(data: Any) -> int | None:
    """The operations of a captured law's graph (``data`` as the capture recorded it) that do
    more than lay data out (:data:`LAYOUT`); None for data that is no graph. Read only, never
    run: the size the report's loss-versus-size front ranks laws by."""
    nodes = data.get("nodes") if isinstance(data, dict) else None
    if not isinstance(nodes, list):
        return None
    names = (str(node.get("op", "")) if isinstance(node, dict) else "" for node in nodes)
    return sum(name.split(".")[1 if name.startswith("aten.") else -1] not in LAYOUT
               for name in names)  # fmt: skip


def build_law(data: Any, dtype: torch.dtype) -> GraphLaw:
    """The module computing the captured law ``data``, its floats in ``dtype``.

    Raises :class:`LawGraphError` for anything wrong with ``data``, whatever fails first,
    and for a law whose estimated cost is past :mod:`~tasks.constitutive.law_cost`'s budgets
    (sized on shapes alone, before any fit: refused in well under a second).
    """
    try:
        graph = LawGraph.from_json(data)
        law_cost.check_cost(graph, aten_operation)
        return GraphLaw(graph, dtype)
    except law_cost.CostRefused as error:
        raise LawGraphError(str(error)) from None
    except LawGraphError:
        raise
    except (ValueError, TypeError, IndexError, KeyError, AttributeError, RuntimeError,
            OverflowError, RecursionError) as error:  # fmt: skip
        raise LawGraphError(f"the graph cannot be built ({type(error).__name__})") from None


class GraphLaw(nn.Module):
    """A law rebuilt from its checked graph: ``forward(F)`` runs the graph's operations.

    Parameters keep the names the law gave them (``named_parameters()`` lists them in the
    captured order). The operations are turned into a ``torch.fx.GraphModule`` whose code is
    generated from the allowed operations and numeric literals only. Once :meth:`use_kernels`
    has given it the law compiled into Taichi kernels (:mod:`tasks.constitutive.law_kernel`),
    ``forward`` runs those instead.
    """

    def __init__(self, graph: LawGraph, dtype: torch.dtype) -> None:
        super().__init__()
        holder = nn.Module()
        for index, constant in enumerate(graph.constants):
            holder.register_buffer(f"c{index}", _tensor(constant, dtype))
        self.graph_constants = holder
        for name, tensor in graph.parameters.items():
            self._add_parameter(name, nn.Parameter(_tensor(tensor, dtype)))
        object.__setattr__(self, "graph", graph)
        #: the parameters in the graph's order (``parameters()`` lists a submodule's later)
        object.__setattr__(self, "graph_parameters",
                           [self.get_parameter(name) for name in graph.parameters])  # fmt: skip
        object.__setattr__(self, "_graph_module", _compile(self, graph, dtype))
        object.__setattr__(self, "kernels", None)

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        if self.kernels is not None:
            return scalar_law.apply_law(F, self.kernels, self.graph_parameters)
        return self._graph_module(F)

    def torch_forward(self, F: torch.Tensor) -> torch.Tensor:
        """The law computed by torch from its graph, whatever :meth:`use_kernels` set."""
        return self._graph_module(F)

    def use_kernels(self, kernels: scalar_law.CompiledLaw | None) -> None:
        """Compute ``forward`` with ``kernels`` (the same law compiled), or torch again (None)."""
        object.__setattr__(self, "kernels", kernels)

    def _add_parameter(self, name: str, parameter: nn.Parameter) -> None:
        *path, leaf = name.split(".")
        owner: nn.Module = self
        for part in path:
            child = owner._modules.get(part)
            if child is None:
                if hasattr(owner, part):
                    raise LawGraphError(f"parameter {name!r} clashes with a module attribute")
                child = nn.Module()
                owner.add_module(part, child)
            owner = child
        try:
            owner.register_parameter(leaf, parameter)
        except (KeyError, TypeError) as error:
            raise LawGraphError(f"parameter {name!r} cannot be registered: {error}") from None


def _compile(law: GraphLaw, graph: LawGraph, dtype: torch.dtype) -> fx.GraphModule:
    built = fx.Graph()
    inputs = {"input": [built.placeholder("F")]}
    inputs["param"] = [built.get_attr(name) for name in graph.parameters]
    inputs["constant"] = [
        built.get_attr(f"graph_constants.c{i}") for i in range(len(graph.constants))
    ]
    inputs["node"] = []

    def resolve(value: Any) -> Any:
        if isinstance(value, list):
            return [resolve(item) for item in value]
        if isinstance(value, dict):
            ((kind, payload),) = value.items()
            if kind in _REFERENCES:
                return inputs[kind][payload]
            return _literal(kind, payload, dtype)
        return value

    for op, args, kwargs in graph.nodes:
        target = _target(op)
        node = built.call_function(
            target, tuple(resolve(arg) for arg in args), {k: resolve(v) for k, v in kwargs.items()}
        )
        inputs["node"].append(node)
    built.output(resolve(graph.output))
    _keep_lu_where_used(built)
    _diagonal_products_as_scaling(built)
    return fx.GraphModule(law, built, class_name="CapturedLaw")


def _keep_lu_where_used(graph: fx.Graph) -> None:
    """Back to ATen's ``_linalg_det`` wherever the graph reads its LU factors or pivots,
    which :func:`closed_form_det` does not compute."""
    for node in graph.nodes:
        if node.target is not closed_form_det:
            continue
        if any(user.target is not operator.getitem or (user.args[1] != 0 and user.users)
               for user in node.users):  # fmt: skip
            node.target = torch.ops.aten._linalg_det.default


#: Operations that only re-view a tensor (as ``matmul`` wraps the factors of a product).
_VIEWS = (torch.ops.aten.view.default, torch.ops.aten.expand.default,
          torch.ops.aten._unsafe_view.default, torch.ops.aten.reshape.default)  # fmt: skip
_VIEW_NAMES = {view: view.__name__.split(".")[0] for view in _VIEWS}
_VIEW_BY_NAME = {name: view for view, name in _VIEW_NAMES.items()}


def _diagonal_products_as_scaling(graph: fx.Graph) -> None:
    """A product with a diagonal matrix made by ``diag_embed`` (``U @ diag_embed(s) @ Vh``, the
    usual way back from singular values) scales the other factor's columns (or rows) instead,
    where the shapes at run time show that it is one (:func:`times_diagonal`): the result is
    the same, and autograd keeps no tensor of its own for it (the factor and ``s`` are kept by
    the operations that made them), where a product keeps both of its factors."""
    for node in list(graph.nodes):
        if node.target is not batched_product:
            continue
        left, right = node.args
        if (values := _diagonal_of(right)) is not None:
            node.target, node.args = times_diagonal, (left, right, values, True)
        elif (values := _diagonal_of(left)) is not None:
            node.target, node.args = times_diagonal, (right, left, values, False)
    _scaled_factors_into_products(graph)


def _scaled_factors_into_products(graph: fx.Graph) -> None:
    """A product whose left factor is a column scaling (``(U @ diag_embed(s)) @ Vh``, seen
    through views) computes both at once (:func:`product_of_scaled`): autograd then keeps the
    factors and ``s``, which the operations that made them keep anyway, not the scaled
    factor, a tensor of its own."""
    for node in list(graph.nodes):
        if node.target is not batched_product:
            continue
        left, right = node.args
        left, views = _beneath_views(left)
        if isinstance(left, fx.Node) and left.target is times_diagonal and left.args[3]:
            other, diagonal, values, _ = left.args
            node.target = product_of_scaled
            node.args = (other, diagonal, values, right, views)
    graph.eliminate_dead_code()


def _beneath_views(node: Any) -> tuple[Any, list[tuple[str, Any]]]:
    """The node that ``node`` re-views (itself if it is no view), and the view operations
    from it to ``node``, in the order they run: (name, shape) pairs."""
    views = []
    while isinstance(node, fx.Node) and node.target in _VIEWS:
        views.append((_VIEW_NAMES[node.target], node.args[1]))
        node = node.args[0]
    return node, views[::-1]


def _diagonal_of(node: Any) -> fx.Node | None:
    """The vector ``s`` when ``node`` is ``diag_embed(s)`` (main diagonal, last two dimensions)
    seen through views only; else None."""
    node, _views = _beneath_views(node)
    if not isinstance(node, fx.Node) or node.target is not torch.ops.aten.diag_embed.default:
        return None
    arguments = dict(zip(("offset", "dim1", "dim2"), node.args[1:], strict=False)) | node.kwargs
    if (arguments.get("offset", 0), arguments.get("dim1", -2), arguments.get("dim2", -1)) not in (
        (0, -2, -1), (0, 1, 2)
    ):  # fmt: skip
        return None
    return node.args[0]


def times_diagonal(
    other: torch.Tensor, diagonal: torch.Tensor, values: torch.Tensor, diagonal_right: bool
) -> torch.Tensor:
    """``bmm(other, diagonal)`` (or ``bmm(diagonal, other)``) where ``diagonal`` was made
    from ``values`` by ``diag_embed`` and views: ``other`` scaled by ``values``, column by
    column (row by row), when ``diagonal`` has the shape of ``diag_embed(values)`` (the views
    then changed nothing) and ``other`` that of the product; else the product itself."""
    if _is_scaling(other, diagonal, values):
        return other * values.unsqueeze(-2 if diagonal_right else -1)
    if diagonal_right:
        return batched_product(other, diagonal)
    return batched_product(diagonal, other)


def _is_scaling(other: torch.Tensor, diagonal: torch.Tensor, values: torch.Tensor) -> bool:
    """Whether ``diagonal`` (``diag_embed(values)`` seen through views) has the shape
    ``diag_embed`` gave it, one (n, n) matrix per row of the (N, n) ``values``, as ``other``
    has: the views changed nothing, and the product with it scales ``other``."""
    if values.dim() != 2:
        return False
    batch, size = values.shape
    return tuple(diagonal.shape) == (batch, size, size) == tuple(other.shape)


def product_of_scaled(
    other: torch.Tensor, diagonal: torch.Tensor, values: torch.Tensor, right: torch.Tensor,
    views: list[tuple[str, list[int]]],
) -> torch.Tensor:
    """``bmm(V(times_diagonal(other, diagonal, values, True)), right)``, V the view operations
    ``views`` (names and shapes, in order): one :func:`bridges.products.scaled_product` where
    the shapes at run time show that the scaling is one and the views re-view nothing; else
    those operations one by one."""
    shape = tuple(other.shape)
    if (_is_scaling(other, diagonal, values) and tuple(right.shape) == shape
            and all(tuple(size) == shape for _name, size in views)):  # fmt: skip
        return products.scaled_product(other, values, right)
    left = times_diagonal(other, diagonal, values, True)
    for name, size in views:
        left = _VIEW_BY_NAME[name](left, size)
    return batched_product(left, right)


def _target(op: str) -> Any:
    """The callable of an allowed operation name (checked by :func:`law_ops.is_allowed`)."""
    if op in law_ops.PYTHON_OPS:
        return law_ops.PYTHON_OPS[op]
    _, name, overload_name = op.split(".")
    if name == "_linalg_svd" and overload_name == "default":
        return stable_svd
    if name == "_linalg_det" and overload_name == "default":
        return closed_form_det
    if name == "linalg_inv_ex" and overload_name == "default":
        return closed_form_inverse
    if name == "bmm" and overload_name == "default":
        return batched_product
    overload = aten_operation(op)
    if name in law_ops.ZERO_FILLED:
        return _ZeroFilled(overload)
    return overload


def aten_operation(op: str) -> Any:
    """The ATen overload (or Python operator) an allowed operation name stands for, as ATen
    defines it; :class:`LawGraphError` if torch has none or it writes into its arguments."""
    if op in law_ops.PYTHON_OPS:
        return law_ops.PYTHON_OPS[op]
    _, name, overload_name = op.split(".")
    packet = getattr(torch.ops.aten, name, None)
    overload = getattr(packet, overload_name, None) if packet is not None else None
    if not isinstance(overload, torch._ops.OpOverload):
        raise LawGraphError("the graph names an operation torch does not have")
    if overload._schema.is_mutable:
        raise LawGraphError(f"{op} writes into its arguments, which is not allowed")
    return overload


class _ZeroFilled:
    """An ``empty`` factory made deterministic: its result is filled with zeros."""

    def __init__(self, factory: torch._ops.OpOverload) -> None:
        self.factory = factory
        self.__name__ = f"zero_filled_{factory._opname}"

    def __call__(self, *args: Any, **kwargs: Any) -> torch.Tensor:
        return self.factory(*args, **kwargs).zero_()



def stable_svd(
    A: torch.Tensor, full_matrices: bool = True, compute_uv: bool = True, driver: Any = None
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``aten._linalg_svd`` with :func:`bridges.linalg.svd`'s stable gradient for 3x3 inputs."""
    if compute_uv and driver is None and linalg.real_3x3(A):
        return linalg.svd(A, signed=False)
    return torch.ops.aten._linalg_svd.default(A, full_matrices, compute_uv, driver=driver)


def closed_form_det(A: torch.Tensor) -> tuple[torch.Tensor, Any, Any]:
    """``aten._linalg_det`` by :func:`bridges.closed_form.det3` for 3x3 inputs; the LU factors
    and pivots are not computed (None), so it stands only where the graph reads neither."""
    if not linalg.real_3x3(A):
        return torch.ops.aten._linalg_det.default(A)
    return closed_form.det3(A), None, None


def closed_form_inverse(
    A: torch.Tensor, check_errors: bool = False
) -> tuple[torch.Tensor, torch.Tensor]:
    """``aten.linalg_inv_ex`` by :func:`bridges.closed_form.inv3` for 3x3 inputs; ``info`` is
    1 for an exactly singular matrix, as LU reports a zero pivot."""
    if check_errors or not linalg.real_3x3(A):
        return torch.ops.aten.linalg_inv_ex.default(A, check_errors=check_errors)
    inverse, det = closed_form.inverse_and_det(A)
    return inverse, (det.detach() == 0).to(torch.int32)


def batched_product(A: torch.Tensor, B: torch.Tensor) -> torch.Tensor:
    """``aten.bmm`` by :func:`bridges.products.bmm3` for (N, 3, 3) batches where that is faster
    (:func:`bridges.products.worthwhile`), else ATen's."""
    product = products.bmm3(A, B) if products.worthwhile(A) else None
    return product if product is not None else torch.ops.aten.bmm.default(A, B)


def _literal(kind: str, payload: str, dtype: torch.dtype) -> Any:
    if kind == "float":
        return float(payload)
    if kind == "str":
        return payload
    if kind == "dtype":
        return dtype if payload in law_ops.FLOAT_DTYPES else getattr(torch, payload)
    if kind == "device":
        return torch.device(payload)
    if kind == "layout":
        return torch.strided
    return getattr(torch, payload)  # memory_format, checked against law_ops.MEMORY_FORMATS


def _tensor(data: TensorData, dtype: torch.dtype) -> torch.Tensor:
    kind = dtype if data.dtype in law_ops.FLOAT_DTYPES else getattr(torch, data.dtype)
    return torch.tensor(data.values, dtype=kind).reshape(data.shape)


def _known(op: str) -> str:
    """``op`` if it names a real ATen operation, else a description (no text of the graph's)."""
    parts = op.split(".")
    if len(parts) == 3 and parts[0] == "aten" and len(op) <= 80 and parts[1].isidentifier():
        packet = getattr(torch.ops.aten, parts[1], None)
        if isinstance(packet, torch._ops.OpOverloadPacket) and parts[2] in packet.overloads():
            return op
    return "an operation that is not an ATen operation"


# ------------------------------------------------------------------------------ checking


class _ValueChecker:
    """Checks argument values: literals of allowed kinds, references to earlier values."""

    def __init__(self, parameters: int, constants: int) -> None:
        self.limits = {"input": 1, "param": parameters, "constant": constants}
        self.nodes = 0

    def check(self, value: Any, depth: int = 0) -> Any:
        if depth > MAX_NESTING:
            raise LawGraphError("an argument is nested too deeply")
        if value is None or isinstance(value, bool):
            return value
        if isinstance(value, int):
            if not -_INT64 <= value < _INT64:
                raise LawGraphError("an integer argument is out of the 64-bit range")
            return value
        if isinstance(value, float):
            if not math.isfinite(value):
                raise LawGraphError("a non-finite float must be written as {'float': ...}")
            return value
        if isinstance(value, list):
            return [self.check(item, depth + 1) for item in value]
        if isinstance(value, dict) and len(value) == 1:
            ((kind, payload),) = value.items()
            self._check_tagged(kind, payload)
            return value
        raise LawGraphError("an argument is of a kind a law graph cannot hold")

    def _check_tagged(self, kind: Any, payload: Any) -> None:
        if kind in _REFERENCES:
            limit = self.nodes if kind == "node" else self.limits[kind]
            if isinstance(payload, bool) or not isinstance(payload, int):
                raise LawGraphError(f"a {kind} reference is not an index")
            if not 0 <= payload < limit:
                raise LawGraphError(f"a {kind} reference points outside the graph")
            return
        if kind == "str":
            if not (isinstance(payload, str) and ARGUMENT_TEXT.match(payload)):
                raise LawGraphError("a text argument is not an equation or a mode")
            return
        allowed = {
            "float": ("inf", "-inf", "nan"),
            "dtype": law_ops.DTYPES,
            "device": ("cpu",),
            "layout": law_ops.LAYOUTS,
            "memory_format": law_ops.MEMORY_FORMATS,
        }.get(kind)
        if allowed is None or payload not in allowed:
            raise LawGraphError("an argument has an unknown tag or value")


def _parameters(raw: Any) -> dict[str, TensorData]:
    if not isinstance(raw, list):
        raise LawGraphError("the graph has no list of parameters")
    if len(raw) > MAX_PARAMETERS:
        raise LawGraphError(f"the law has {len(raw)} parameters, more than {MAX_PARAMETERS}")
    parameters: dict[str, TensorData] = {}
    total = 0
    for index, item in enumerate(raw):
        name = item.get("name") if isinstance(item, dict) else None
        if not (isinstance(name, str) and len(name) <= MAX_NAME_CHARS and NAME.match(name)):
            raise LawGraphError(
                f"parameter {index + 1}'s name is not a Python identifier of at most "
                f"{MAX_NAME_CHARS} characters: name parameters like log_youngs_modulus"
            )
        if name in parameters:
            raise LawGraphError(f"parameter {name!r} appears twice")
        tensor = _tensor_data(item, floats_only=True)
        total += len(tensor.values)
        if total > MAX_PARAMETER_ELEMENTS:
            raise LawGraphError(f"the law has more than {MAX_PARAMETER_ELEMENTS} parameter values")
        parameters[name] = tensor
    return parameters


def _constants(raw: Any) -> list[TensorData]:
    if not isinstance(raw, list) or len(raw) > MAX_CONSTANTS:
        raise LawGraphError(f"the graph needs a list of at most {MAX_CONSTANTS} constants")
    constants = [_tensor_data(item, floats_only=False) for item in raw]
    if sum(len(c.values) for c in constants) > MAX_CONSTANT_ELEMENTS:
        raise LawGraphError(
            f"the law's constant tensors hold more than {MAX_CONSTANT_ELEMENTS} values"
        )
    return constants


def _tensor_data(item: Any, floats_only: bool) -> TensorData:
    if not isinstance(item, dict):
        raise LawGraphError("a tensor of the graph is malformed")
    shape, values = item.get("shape"), item.get("values")
    dtype = item.get("dtype", "float64")
    if not (isinstance(shape, list) and all(type(n) is int and n >= 0 for n in shape)):
        raise LawGraphError("a tensor of the graph has a malformed shape")
    if not isinstance(values, list) or len(values) != math.prod(shape):
        raise LawGraphError("a tensor of the graph does not hold as many values as its shape")
    if dtype not in law_ops.DTYPES or (floats_only and dtype not in law_ops.FLOAT_DTYPES):
        raise LawGraphError("a tensor of the graph has a dtype that is not allowed")
    if any(n >= _INT64 for n in shape):
        raise LawGraphError("a tensor of the graph has a malformed shape")
    integral = dtype not in law_ops.FLOAT_DTYPES
    for value in values:
        if not isinstance(value, (int, float)) or (
            isinstance(value, float) and not math.isfinite(value)
        ):
            raise LawGraphError("a tensor of the graph holds a value that is not a finite number")
        if integral and (isinstance(value, float) or not -_INT64 <= value < _INT64):
            raise LawGraphError(f"a {dtype} tensor of the graph holds a value out of its type")
        if dtype == "bool" and value not in (0, 1):
            raise LawGraphError("a bool tensor of the graph holds a value other than 0 or 1")
    return TensorData(tuple(shape), tuple(values), dtype)
