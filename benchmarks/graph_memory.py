"""What the autograd graph of one fitted step keeps, by operation, in bytes a particle.

A fit's memory beyond the process's start is mostly its graph: a batch of teacher-forced
segments keeps, for every step of every copy of the scene, what autograd saves for the reverse.
This builds a task's true law started 2x off as an evaluation builds it (captured, rebuilt from
its graph, compiled into Taichi kernels where ``law_kernels`` allows; other ``--option`` s as
``sga-agent evaluate`` takes them), runs one step of ``--copies`` stacked copies of the scene
from the observed state at a reset step (its input requiring a gradient, as inside a segment)
and walks the step's graph: every storage a node keeps is counted once, under the first node
found keeping it. It prints the bytes a particle and step by node, their sum, a 100-step
segment's graph and how many segments the fit runs at once (``graph_memory_mb`` and
``batch_particles``). Counting, not timing: it runs in one process, anywhere. Usage::

    python benchmarks/graph_memory.py [--tasks elastic plasticine] [--copies 5]
        [--option KEY=VALUE ...]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import torch

from sga_agent.cli.options import key_value_options

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from evaluate_speed import capture  # noqa: E402


@dataclass
class StepGraph:
    """Bytes a particle that one step's graph keeps, by autograd node type."""

    task: str
    particles: int
    number_bytes: int  # of one number in the running precision
    by_node: dict[str, float]
    segment_mib: float  # a segment's graph (reset_every steps of one copy)
    segments_at_once: int

    @property
    def total(self) -> float:
        return sum(self.by_node.values())


def kept_by_node(root: torch.autograd.graph.Node) -> dict[str, int]:
    """Bytes of the storages the graph under ``root`` keeps, each once, by the type of the
    first node found keeping it (depth first)."""
    seen: set[torch.autograd.graph.Node] = set()
    storages: set[int] = set()
    by_node: dict[str, int] = {}
    stack = [root]
    while stack:
        node = stack.pop()
        if node is None or node in seen:
            continue
        seen.add(node)
        for tensor in _saved_tensors(node):
            storage = tensor.untyped_storage()
            if storage.data_ptr() in storages:
                continue
            storages.add(storage.data_ptr())
            name = type(node).__name__
            by_node[name] = by_node.get(name, 0) + storage.nbytes()
        stack.extend(next_node for next_node, _ in node.next_functions)
    return by_node


def _saved_tensors(node: torch.autograd.graph.Node) -> list[torch.Tensor]:
    """The tensors a node keeps: a built-in node's ``_saved_*`` attributes, a custom
    function's ``saved_tensors``."""
    found: list = []
    for attribute in dir(node):
        if attribute.startswith("_saved_"):
            value = getattr(node, attribute, None)
            found.extend(value if isinstance(value, (tuple, list)) else [value])
    if hasattr(node, "saved_tensors"):
        found.extend(node.saved_tensors)
    return [tensor for tensor in found if isinstance(tensor, torch.Tensor)]


def measure(task: str, copies: int, raw_options: dict[str, str], folder: Path) -> StepGraph:
    """One step's graph of ``task``'s 2x-off true law on ``copies`` stacked scene copies."""
    import taichi_mpm as tm
    from bridges.linalg import stable_linalg
    from bridges.rollout import State
    from bridges.step import torch_dtype
    from sga_agent.options import parse_options
    from sga_agent.registry import load_task
    from tasks.constitutive.evaluation import (
        compile_law,
        ensure_runtime,
        ground_truth,
        task_rollout,
    )
    from tasks.constitutive.inner import InnerSettings, segments_at_once
    from tasks.constitutive.law_graph import build_law
    from tasks.constitutive.specs import SPECS

    graph = json.loads(capture(task, folder).read_text())
    options = parse_options(load_task(task).options_type, raw_options, task)
    spec = SPECS[task]
    ensure_runtime(options.precision or "float32")
    dtype = torch_dtype()
    law = build_law(graph["law"], dtype)
    observed = ground_truth(spec, options.steps)
    compile_law(law, observed, options)
    rollout = task_rollout(spec, law, tm.paper_scene(steps=observed.positions.shape[0] - 1))
    reset = min(1, len(observed.states["x"]) - 1)  # a deformed state where there is one
    start = State.stacked([State.from_arrays(observed.states, reset, dtype)] * copies)
    with torch.no_grad(), stable_linalg():
        previous = rollout.step(start, copies)
    previous = State(*(tensor.requires_grad_() for tensor in previous.tensors()))
    with stable_linalg():
        end = rollout.step(previous, copies)
    particles = copies * rollout.scene.num_particles
    by_node = {name: count / particles for name, count in kept_by_node(end.x.grad_fn).items()}
    settings = InnerSettings(reset_every=spec.reset_every, graph_memory_mb=options.graph_memory_mb,
                             batch_particles=options.batch_particles)  # fmt: skip
    segment_mib = sum(by_node.values()) * rollout.scene.num_particles * spec.reset_every / 2**20
    return StepGraph(task, particles, dtype.itemsize, by_node, segment_mib,
                     segments_at_once(rollout, observed, settings))  # fmt: skip


def report(measured: StepGraph, options: dict[str, str]) -> str:
    """The node table of one task and its summary line."""
    shown = ", ".join(f"{key}={value}" for key, value in options.items()) or "default options"
    lines = [f"{measured.task} ({shown}): one step of {measured.particles} particles",
             f"{'node':<32} bytes a particle"]  # fmt: skip
    lines += [f"{name:<32} {value:>8.1f}" for name, value in
              sorted(measured.by_node.items(), key=lambda item: -item[1])]  # fmt: skip
    numbers = measured.total / measured.number_bytes
    lines.append(f"{'total':<32} {measured.total:>8.1f}  ({numbers:.0f} numbers)")
    lines.append(f"a segment's graph: {measured.segment_mib:.1f} MiB; the fit runs "
                 f"{measured.segments_at_once} segments at once")  # fmt: skip
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", nargs="+", default=["elastic", "plasticine"])
    parser.add_argument("--copies", type=int, default=5, help="scene copies a step (default 5)")
    parser.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                        help="a task option, as sga-agent evaluate takes it")  # fmt: skip
    args = parser.parse_args(argv)
    try:
        options = key_value_options(args.option)
    except ValueError as error:
        raise SystemExit(f"--option: {error}") from None
    torch.set_num_threads(1)
    with tempfile.TemporaryDirectory() as folder:
        for task in args.tasks:
            print(report(measure(task, args.copies, options, Path(folder)), options), flush=True)


if __name__ == "__main__":
    main()
