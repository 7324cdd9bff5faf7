"""Capturing a proposed law as data: run its code once, record what ``forward`` computes.

This is the only place where a law's code runs, and it must run only in the sandboxed capture
process (:mod:`sga_agent.capture_server`). ``Physics()`` is built, then ``forward`` is traced
with ``make_fx`` on symbolic fake tensors: every ATen operation it performs on F (batch size
symbolic, so the graph holds for any number of particles) and on its parameters becomes a node
of a :mod:`~tasks.constitutive.law_graph` document (this module imports neither it nor
Taichi). Python control flow is executed during the trace, so loops unroll and branches on
Python values are taken once; a branch on a tensor's value cannot be traced and is refused with
a hint (use ``torch.where``). Every refusal of the law's code names its line, the cause and the
fix (:mod:`~tasks.constitutive.law_errors`): an error the law also raises on real tensors is
told as those raise it, with real sizes rather than the trace's symbolic ones.

Nothing here is trusted by whoever reads the result: the fit checks the document again.
"""

from __future__ import annotations

import operator
import re
from typing import Any

import torch
from torch import fx
from torch.fx.experimental.proxy_tensor import make_fx

from tasks.constitutive import law_ops
from tasks.constitutive.law_code import LawCodeError, describe_error, load_law
from tasks.constitutive.law_errors import explain, explain_at, quote_line, stack_line

#: Particles in the traced batch (any size > 1 gives the same symbolic graph), and in the
#: batch the recorded graph is checked on besides.
TRACE_BATCH, CHECK_BATCH = 5, 7
#: Operators of the Python ``operator`` module, by function, for the graph's names.
_OPERATORS = {function: name for name, function in law_ops.PYTHON_OPS.items()}
#: Errors that only a trace raises: a tensor's value read out, or a NumPy conversion.
_TRACE_ONLY = re.compile(
    r"data-dependent|Data dependent|DataDependent|unallocated storage|item\(\)"
    r"|_local_scalar_dense|numpy|__array__",
    re.IGNORECASE,
)


#: Captured when a capture server starts, so that tracing has loaded everything it needs before
#: any confined capture (which may be unable to read files to import more).
WARM_UP_LAW = """
import math
import torch
import torch.nn as nn
import torch.nn.functional as nnf


class Physics(nn.Module):
    def __init__(self, log_scale: float = 0.0, weights: tuple = (0.5, 0.5)):
        super().__init__()
        self.log_scale = nn.Parameter(torch.tensor(log_scale))
        self.weights = nn.Parameter(torch.tensor(weights))
        self.register_buffer("offset", torch.zeros(3))

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        U, sigma, Vh = torch.linalg.svd(F)
        U2, S2, V2 = torch.svd(F)
        eps = torch.log(sigma.abs().clamp(min=1e-2)) + self.offset
        norm = torch.linalg.norm(eps - eps.mean(-1, keepdim=True), dim=-1, keepdim=True)
        J = torch.linalg.det(F).clamp(min=1e-6).view(-1, 1, 1)
        eye = torch.eye(3, dtype=F.dtype).expand_as(F)
        w = torch.softmax(torch.stack([self.weights[0], self.weights[1]]), dim=0)
        shear = torch.where(norm > 0.1, nnf.relu(norm - 0.1) / norm, torch.zeros_like(norm))
        shear = shear + torch.sigmoid(norm) * torch.tanh(norm) * math.pi
        rotated = U @ torch.diag_embed(torch.exp(eps - shear * eps)) @ Vh
        inverse = torch.linalg.inv(F.transpose(1, 2) @ F + eye)
        mixed = torch.einsum("bij,bjk->bik", rotated, inverse).reshape(-1, 9).reshape(-1, 3, 3)
        trace = torch.diagonal(mixed, dim1=-2, dim2=-1).sum(-1).view(-1, 1, 1)
        parts = torch.cat([U2, S2.unsqueeze(-1), V2], dim=-1)[..., :3]
        return torch.exp(self.log_scale) * (w[0] * mixed + w[1] * J.pow(1 / 3) * eye) + (
            1e-9 * trace * parts.square().sum(-1, keepdim=True).sqrt().min(dim=-1, keepdim=True)[0]
        )
"""


class LawCaptureError(LawCodeError):
    """The law runs but cannot be captured as a graph; the message says what to change."""


def capture_law(code: str) -> dict[str, Any]:
    """Execute ``code``, trace ``Physics().forward`` and return the law's graph document."""
    law = load_law(code, torch.float64)
    named = [(name, p.detach()) for name, p in law.named_parameters()]
    names = [name for name, _ in named]

    def forward(F: torch.Tensor, *values: torch.Tensor) -> torch.Tensor:
        return torch.func.functional_call(law, dict(zip(names, values, strict=True)), (F,))

    F = _sample_deformation_gradients()
    values = [value for _, value in named]
    try:
        traced = _trace(forward, F, values, lines=False)
    except LawCodeError:
        raise
    except Exception as error:
        raise LawCaptureError(_explain(error, code, law, F)) from None
    try:
        document = serialize(traced, named, code)  # refuses operations not allowed first
    except LawCaptureError:  # traced again with each node's line, to name it in the refusal
        document = serialize(_trace(forward, F, values, lines=True), named, code)
    _check_faithful(traced, forward, F, values)
    return document


def _trace(
    forward: Any, F: torch.Tensor, values: list[torch.Tensor], lines: bool
) -> fx.GraphModule:
    """``forward`` traced on symbolic fake tensors; with ``lines``, each node records the
    stack it was made in (a tenth of a second more: only a refusal needs it)."""
    with torch.no_grad():
        return make_fx(
            torch.func.functionalize(forward),
            tracing_mode="symbolic",
            _allow_non_fake_inputs=True,  # tensors held by the module become constants
            record_stack_traces=lines,
        )(F, *values)


def _check_faithful(
    traced: fx.GraphModule, forward: Any, F: torch.Tensor, values: list[torch.Tensor]
) -> None:
    """Refuse a graph that computes something else than the law ``forward(F, *values)``: on
    the traced batch, on one of another size (a size fixed at the trace breaks there) and with
    other parameter values (a value read out of a parameter through NumPy during the trace
    becomes a constant, silently, which may even equal the value it was read from)."""
    shifted = [value * 1.25 + 0.125 for value in values]
    cases = [(F, values), (_sample_deformation_gradients(CHECK_BATCH), values), (F, shifted)]
    for batch, parameters in cases:
        try:
            with torch.no_grad():
                expected = forward(batch, *parameters)
        except Exception:
            return  # the law itself fails on these F: the fit will say how, on the real ones
        try:
            with torch.no_grad():
                actual = traced(batch, *parameters)
        except Exception as error:
            raise LawCaptureError(
                f"the recorded law fails on {len(batch)} particles ({describe_error(error)}): "
                "write it for any number of particles B (reshape with -1, not a fixed size)"
            ) from None
        faithful = isinstance(expected, torch.Tensor) and torch.allclose(
            actual, expected, rtol=1e-6, atol=1e-9, equal_nan=True
        )
        if not faithful:
            raise LawCaptureError(
                "the recorded law computes something else than the code: it reads values out "
                "of tensors (NumPy, float(), .item() or .tolist()) or depends on the number of "
                "particles; use torch operations on tensors only"
            )


def serialize(
    traced: fx.GraphModule, parameters: list[tuple[str, torch.Tensor]], code: str = ""
) -> dict:
    """The graph document of a traced ``forward(F, *parameters)``; a refusal quotes the line
    of the law's ``code`` that made the refused node, where the trace recorded it."""
    placeholders = [node for node in traced.graph.nodes if node.op == "placeholder"]
    refs: dict[fx.Node, dict[str, int]] = {placeholders[0]: {"input": 0}}
    refs.update({node: {"param": k} for k, node in enumerate(placeholders[1:])})
    constants: list[dict[str, Any]] = []
    nodes: list[dict[str, Any]] = []
    output: Any = None

    def encode(value: Any) -> Any:
        if isinstance(value, fx.Node):
            return refs[value]
        if isinstance(value, (list, tuple)):
            return [encode(item) for item in value]
        if isinstance(value, bool) or value is None or isinstance(value, int):
            return value
        if isinstance(value, float):
            return value if value == value and abs(value) != float("inf") else {"float": str(value)}
        if isinstance(value, str):
            return {"str": value}  # an einsum equation, a rounding mode: checked by the fit
        if isinstance(value, torch.dtype):
            return {"dtype": str(value).removeprefix("torch.")}
        if isinstance(value, torch.device):
            return {"device": value.type}
        if isinstance(value, torch.layout):
            return {"layout": str(value).removeprefix("torch.")}
        if isinstance(value, torch.memory_format):
            return {"memory_format": str(value).removeprefix("torch.")}
        raise LawCaptureError(f"the law passes a {type(value).__name__} to a tensor operation")

    for node in traced.graph.nodes:
        if node.op == "get_attr":
            tensor = getattr(traced, node.target)
            refs[node] = {"constant": len(constants)}
            constants.append(_tensor_document(tensor))
        elif node.op == "call_function":
            op = _op_name(node.target)
            line = stack_line(node.meta.get("stack_trace"))
            if op == "aten._local_scalar_dense.default":  # .item(), float(), int() of a tensor
                reading = RuntimeError(f"{op} (data-dependent)")
                raise LawCaptureError(explain_at(reading, line, code, raised=False))
            if not law_ops.is_allowed(op):
                where = quote_line(code, line)
                raise LawCaptureError(
                    f"the law calls {op}, which is not allowed: {law_ops.HINT}"
                    + (f". At {where}" if where else "")
                )
            refs[node] = {"node": len(nodes)}
            kwargs = {key: encode(value) for key, value in node.kwargs.items()}
            nodes.append({"op": op, "args": encode(node.args), "kwargs": kwargs})
        elif node.op == "output":
            result = node.args[0]
            if isinstance(result, (list, tuple)):
                if len(result) != 1:
                    raise LawCaptureError("forward must return one tensor")
                result = result[0]
            output = encode(result)
    return {
        "format": law_ops.GRAPH_FORMAT,
        "parameters": [{"name": name, **_tensor_document(value)} for name, value in parameters],
        "constants": constants,
        "nodes": nodes,
        "output": output,
    }


def _op_name(target: Any) -> str:
    if isinstance(target, torch._ops.OpOverload):
        return f"{target.namespace}.{target._opname}.{target._overloadname}"
    if target in _OPERATORS:
        return _OPERATORS[target]
    if target is operator.getitem:
        return "operator.getitem"
    return getattr(target, "__name__", type(target).__name__)


def _tensor_document(tensor: torch.Tensor) -> dict[str, Any]:
    dtype = str(tensor.dtype).removeprefix("torch.")
    if dtype not in law_ops.DTYPES:
        raise LawCaptureError(f"the law holds a tensor of dtype {dtype}, which is not allowed")
    return {
        "dtype": dtype,
        "shape": list(tensor.shape),
        "values": tensor.detach().reshape(-1).tolist(),
    }


def _sample_deformation_gradients(batch: int = TRACE_BATCH) -> torch.Tensor:
    generator = torch.Generator().manual_seed(batch)
    noise = torch.randn(batch, 3, 3, dtype=torch.float64, generator=generator)
    return torch.eye(3, dtype=torch.float64) + 0.05 * noise


def _explain(error: Exception, code: str, law: torch.nn.Module, F: torch.Tensor) -> str:
    """Why the trace failed. An error the law also raises when run on real tensors is that
    one, whose message names real sizes (the trace's names symbolic ones, like s96); an error
    of the trace only is a tensor's value read out (or a NumPy conversion)."""
    if not _TRACE_ONLY.search(f"{type(error).__name__}: {error}"):
        try:
            with torch.no_grad():
                law(F)
        except Exception as eager:
            error = eager
    return f"the law could not be captured: {explain(error, code)}"
