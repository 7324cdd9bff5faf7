"""What a constitutive task knows about a run's best law, for summaries and reports.

Trusted: nothing here loads or runs candidate code. The true law is the task's own ground
truth (its taichi_mpm material, written in torch by :func:`bridges.laws.from_material`); the
best law is rebuilt from the graph the capture recorded (:func:`fitted_law`), with its fitted
values loaded, and run freely on the training scene and on the held-out one
(:mod:`tasks.constitutive.held_out`). The true law's loss is cached beside the cached ground
truth.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from typing import Any

import torch

import taichi_mpm as tm
from bridges import laws as torch_laws
from bridges.rollout import Rollout, trajectory_loss
from bridges.step import torch_dtype
from sga_agent.task import Assessment, CandidateRecord, Simplified
from tasks.constitutive.evaluation import (
    check_precision,
    ensure_runtime,
    ground_truth,
    task_rollout,
)
from tasks.constitutive.free_run import FreeRun
from tasks.constitutive.free_sim import fitted_law, free_run_in
from tasks.constitutive.ground_truth import cache_dir, cache_key
from tasks.constitutive.held_out import held_out_error
from tasks.constitutive.law_graph import LawGraph, LawGraphError, _target, captured_graph
from tasks.constitutive.options import ConstitutiveOptions
from tasks.constitutive.simplify import simplify
from tasks.constitutive.specs import ConstitutiveSpec
from tasks.constitutive.verdict import verdict

#: The verdict when the truth has changed since the run started.
STALE = ("not judged: the ground truth is not the one the run was measured against (it changed "
         "since the run started), so nothing was simulated")  # fmt: skip


def truth_loss(spec: ConstitutiveSpec, options: ConstitutiveOptions) -> float:
    """The loss of the true law at its true values, scored as every candidate is (teacher
    forcing every ``reset_every`` steps, no fitting); cached beside the ground truth."""
    ensure_runtime(options.precision or "float32")
    observed = ground_truth(spec, options.steps)
    scene = tm.paper_scene(steps=observed.positions.shape[0] - 1)
    key = cache_key(spec.material(), scene, spec.reset_every)
    path = cache_dir() / "ground_truth" / f"{spec.name}-{key}.truth-loss.json"
    try:
        return float(json.loads(path.read_text())["loss"])
    except (OSError, KeyError, ValueError, TypeError):
        pass  # not computed yet (or unreadable): compute it again
    plastic, elastic = torch_laws.from_material(spec.material(), torch_dtype())
    loss = scored_loss(spec, Rollout(scene, plastic.requires_grad_(False),
                                     elastic.requires_grad_(False)), options)  # fmt: skip
    partial = path.with_suffix(f".{os.getpid()}.tmp")
    partial.write_text(json.dumps({"loss": loss}) + "\n")
    partial.replace(path)
    return loss


def scored_loss(spec: ConstitutiveSpec, rollout: Rollout, options: ConstitutiveOptions) -> float:
    """The loss of ``rollout``'s laws as every candidate is scored (teacher forcing every
    ``reset_every`` steps of the observation, no fitting)."""
    observed = ground_truth(spec, options.steps)
    return trajectory_loss(rollout, observed.positions, observed.states, spec.reset_every,
                           backward=False, batch=len(observed.states["x"])).loss  # fmt: skip


def simplified(
    spec: ConstitutiveSpec, candidate: CandidateRecord, options: ConstitutiveOptions
) -> Simplified | None:
    """The candidate's law with the terms the observation does not need dropped
    (:func:`tasks.constitutive.simplify.simplify`), each drop scored on its captured graph
    at its fitted values; the floor is the true law's own loss."""
    graph = captured_graph(candidate.artifacts())
    if graph is None:
        return None
    ensure_runtime(options.precision or "float32")
    scene = tm.paper_scene(steps=ground_truth(spec, options.steps).positions.shape[0] - 1)

    def loss_of(parameters: dict[str, float]) -> float:
        law = fitted_law(graph, parameters, torch_dtype())
        return scored_loss(spec, task_rollout(spec, law, scene), options)

    return simplify(candidate.code, spec.searched, candidate.parameters, loss_of,
                    truth_loss(spec, options))  # fmt: skip


def free_run(
    spec: ConstitutiveSpec, graph: Any, parameters: dict[str, float], options: ConstitutiveOptions
) -> FreeRun:
    """The law of ``graph`` with its fitted ``parameters``, simulated through the training
    scene from its initial state without teacher forcing, against the observation (see
    :func:`~tasks.constitutive.free_sim.free_run_in`)."""
    ensure_runtime(options.precision or "float32")
    law = fitted_law(graph, parameters, torch_dtype())
    observed = ground_truth(spec, options.steps).positions
    return free_run_in(spec, law, tm.paper_scene(steps=observed.shape[0] - 1), observed)


# ------------------------------------------------------------------ readable parameters

#: Operations that turn a parameter into the value a law uses (exp of a log, sigmoid of a logit).
TRANSFORMS = frozenset({"exp", "exp2", "expm1", "sigmoid", "softplus", "tanh", "pow", "sqrt",
                        "square", "log", "log1p", "abs", "reciprocal", "relu"})  # fmt: skip
_INFIX = {"add": "+", "sub": "-", "mul": "*", "div": "/", "truediv": "/", "pow": "**"}
_TRANSPARENT = frozenset({"_to_copy", "alias", "clone", "view", "reshape", "squeeze",
                          "unsqueeze", "detach", "lift_fresh_copy", "to"})  # fmt: skip
MAX_DERIVED = 12


def derived_values(graph: Any, parameters: dict[str, float]) -> dict[str, float]:
    """Values the law computes from one scalar parameter alone through a transform, such as
    ``exp(log_E)`` or ``0.49 * sigmoid(nu_logit)``, with the fitted ``parameters``.

    Read from the captured graph and computed with its own operations (the law's code is
    not run): the largest expressions of one parameter and constants that are one of
    :data:`TRANSFORMS`, possibly scaled by constants. Empty for a graph that cannot be read.
    """
    try:
        checked = LawGraph.from_json(graph)
        names = list(checked.parameters)
        law = fitted_law(graph, parameters, torch.float64)
    except LawGraphError:
        return {}
    values = dict(law.named_parameters())
    inputs = {
        "param": [values[name] for name in names],
        "constant": [getattr(law.graph_constants, f"c{i}") for i in range(len(checked.constants))],
    }
    nodes: list[_Node | None] = []
    for op, args, kwargs in checked.nodes:
        nodes.append(_evaluate(op, args, kwargs, inputs, nodes, names))
    covered = {  # readable nodes inside a larger readable expression of the same parameter
        ref
        for index, (_, args, kwargs) in enumerate(checked.nodes)
        if nodes[index] is not None and nodes[index].readable
        for ref in _node_refs([args, kwargs])
    }
    found: dict[str, float] = {}
    for index, node in enumerate(nodes):
        if node is None or not node.readable or index in covered or node.value.numel() != 1:
            continue
        value = float(node.value)
        if math.isfinite(value) and len(found) < MAX_DERIVED:
            found[node.text] = value
    return found


class _Node:
    """A graph value that depends on one parameter (and constants) only; ``readable`` when it
    is a transform of it (``exp(p)``), or such a value scaled by a constant (``0.49 *
    sigmoid(p)``), not when a constant is added (``1 + exp(p)`` is the law's business)."""

    def __init__(self, value: torch.Tensor, text: str, parameter: str, readable: bool):
        self.value, self.text, self.parameter, self.readable = value, text, parameter, readable


def _node_refs(value: Any) -> list[int]:
    if isinstance(value, list):
        return [ref for item in value for ref in _node_refs(item)]
    if isinstance(value, dict):
        if set(value) == {"node"}:
            return [value["node"]]
        return [ref for item in value.values() for ref in _node_refs(item)]
    return []


def _evaluate(op, args, kwargs, inputs, nodes, names) -> _Node | None:
    """The node as a :class:`_Node`, or None when it depends on F, on two parameters or on
    nothing trainable (or cannot be evaluated alone)."""
    parameters: set[str] = set()
    readable_operand = False

    def resolve(value: Any) -> tuple[Any, str]:
        nonlocal readable_operand
        if isinstance(value, list):
            pairs = [resolve(item) for item in value]
            return [p[0] for p in pairs], "[" + ", ".join(p[1] for p in pairs) + "]"
        if isinstance(value, dict) and len(value) == 1:
            ((kind, payload),) = value.items()
            if kind == "input":
                raise _Skip
            if kind == "param":
                parameters.add(names[payload])
                return inputs["param"][payload], names[payload]
            if kind == "constant":
                tensor = inputs["constant"][payload]
                return tensor, f"{float(tensor):.4g}" if tensor.numel() == 1 else "const"
            if kind == "node":
                source = nodes[payload]
                if source is None:
                    raise _Skip
                parameters.add(source.parameter)
                readable_operand = readable_operand or source.readable
                return source.value, source.text
            if kind == "float":
                return float(payload), payload
            raise _Skip  # dtypes, devices, modes: not a scalar expression
        return value, f"{value:.4g}" if isinstance(value, float) else repr(value)

    try:
        resolved = [resolve(arg) for arg in args]
        if any(not isinstance(value, str | int | float | bool | None) for value in kwargs.values()):
            raise _Skip
        if len(parameters) != 1:
            raise _Skip
        with torch.no_grad():
            value = _target(op)(*(r[0] for r in resolved), **kwargs)
    except (_Skip, LawGraphError, RuntimeError, TypeError, ValueError, IndexError):
        return None
    if not isinstance(value, torch.Tensor):
        value = torch.tensor(value, dtype=torch.float64)
    name = op.split(".")[1]
    texts = [r[1] for r in resolved]
    if name in _TRANSPARENT and texts:
        text = texts[0]
    elif name in _INFIX and len(texts) == 2:
        text = f"({texts[0]} {_INFIX[name]} {texts[1]})"
    elif name == "rsub" and len(texts) == 2:
        text = f"({texts[1]} - {texts[0]})"
    elif name == "neg" and len(texts) == 1:
        text = f"-{texts[0]}"
    else:
        text = f"{name}({', '.join(texts)})"
    scaled = name in ("mul", "div", "truediv", "neg") and readable_operand
    readable = name in TRANSFORMS or scaled or (name in _TRANSPARENT and readable_operand)
    return _Node(value, text, parameters.pop(), readable)


class _Skip(Exception):
    """The node is not an expression of one parameter."""


def assess(
    spec: ConstitutiveSpec,
    artifacts: dict[str, Any] | None,
    parameters: dict[str, float],
    options: ConstitutiveOptions,
    simulate: bool,
    recorded: Mapping[str, Any] | None = None,
) -> Assessment:
    """The ground truth's name and loss, the best law's readable values, its free runs on the
    training and the held-out scene, and the verdict on them.

    ``recorded`` is what the run recorded at its start (:func:`provenance`); when its truth is
    not the task's now, that truth is named and nothing is simulated (the cached observations
    are another material's).
    """
    check_precision(options.precision)
    graph = captured_graph(artifacts)
    if recorded is not None and recorded.get("truth", spec.truth_name) != spec.truth_name:
        return Assessment(truth=str(recorded["truth"]), verdict=STALE)
    found = Assessment(truth=spec.truth_name, truth_loss=truth_loss(spec, options))
    if graph is None:
        return found
    found.derived = derived_values(graph, parameters)
    if simulate:
        found.free_run = free_run(spec, graph, parameters, options)
        found.held_out = held_out_error(spec, graph, parameters, options)
        found.verdict = verdict(found.held_out, found.free_run)
    return found
