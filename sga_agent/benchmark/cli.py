"""Command-line options and flow shared by ``benchmarks/backbones.py`` and
``benchmarks/presets.py``: plan the grid, run it, write the tables and the rank chart."""

from __future__ import annotations

import difflib
import os
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import click

from sga_agent.benchmark import chart, table
from sga_agent.benchmark.grid import GridError, Method, plan_cells, run_cells
from sga_agent.cli.options import task_options
from sga_agent.config import RUN_SETTINGS, SETTINGS, setting_field

#: Settings (flat names) the grid or its own options set, not ``--set``.
OWN_SETTINGS = {
    "task": "--tasks", "proposer": "the methods", "preset": "the methods", "seed": "--seeds",
    "task_options": "--option", "epochs": "--epochs", "api_base": "--api-base",
    "workers": "--workers",
}  # fmt: skip
TRUE, FALSE = ("true", "yes", "on", "1"), ("false", "no", "off", "0")


def split_list(ctx: click.Context, param: click.Parameter, value: str | None) -> list[str]:
    """Click callback: "a,b,c" -> ["a", "b", "c"] (blanks dropped)."""
    return [item.strip() for item in (value or "").split(",") if item.strip()]


def parse_seeds(ctx: click.Context, param: click.Parameter, value: str) -> list[int]:
    """Click callback: "0,1,2" -> [0, 1, 2]."""
    try:
        return [int(item) for item in split_list(ctx, param, value)]
    except ValueError:
        raise click.BadParameter(
            f"{value!r}: give integers separated by commas, e.g. 0,1,2", ctx, param
        ) from None


def _pairs(
    items: Sequence[str], example: str, ctx: click.Context, param: click.Parameter
) -> list[tuple[str, str]]:
    pairs = []
    for item in items:
        key, sep, raw = item.partition("=")
        if not sep or not key:
            raise click.BadParameter(f"{item!r} is not KEY=VALUE (e.g. {example})", ctx, param)
        pairs.append((key, raw))
    return pairs


def parse_settings(ctx: click.Context, param: click.Parameter, items: tuple[str, ...]):
    """Click callback: search settings KEY=VALUE (flat names), converted to their types."""
    types = {name: str(setting_field(name).type) for name in (*RUN_SETTINGS, *SETTINGS)}
    settings: dict[str, Any] = {}
    for key, raw in _pairs(items, "iterations=2", ctx, param):
        if key in OWN_SETTINGS:
            raise click.BadParameter(f"{key} is set by {OWN_SETTINGS[key]}, not --set", ctx, param)
        if key not in types:
            close = difflib.get_close_matches(key, types, n=1)
            hint = f" Did you mean {close[0]!r}?" if close else ""
            known = ", ".join(name for name in types if name not in OWN_SETTINGS)
            raise click.BadParameter(f"no search setting {key!r} (known: {known}).{hint}",
                                     ctx, param)  # fmt: skip
        settings[key] = _convert(key, raw, types[key], ctx, param)
    return settings


def _convert(key: str, raw: str, kind: str, ctx: click.Context, param: click.Parameter) -> Any:
    if "None" in kind and raw.lower() == "none":
        return None
    try:
        if kind.startswith("bool"):
            if raw.lower() not in TRUE + FALSE:
                raise ValueError
            return raw.lower() in TRUE
        if kind.startswith("int"):
            return int(raw)
        if kind.startswith("float"):
            return float(raw)
    except ValueError:
        raise click.BadParameter(f"{key}={raw!r}: {key} takes a {kind}", ctx, param) from None
    return raw


def default_parallel(workers: int) -> int:
    """Cells at once so that cells x sandbox workers do not exceed the CPU cores."""
    return max(1, (os.cpu_count() or 1) // workers)


def grid_options(default_out: str) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """The options every benchmark script takes, passed on as keyword arguments."""
    options = [
        click.option("--tasks", required=True, callback=split_list, metavar="A,B",
                     help="Registered tasks, comma-separated (see `sga-agent tasks`)."),
        click.option("--seeds", default="0", show_default=True, callback=parse_seeds,
                     metavar="0,1,2", help="Seeds, comma-separated: one run per seed."),
        click.option("--out-dir", "out", type=click.Path(file_okay=False, path_type=Path),
                     default=Path(default_out), show_default=True,
                     help="Output folder: cells in <task>/<method>/seed-<n>/, then the tables "
                     "and ranks.png. Running again skips finished cells, resumes the others."),
        click.option("--option", "task_options", multiple=True, callback=task_options,
                     metavar="KEY=VALUE", help="Task option for every cell whose task has "
                     "it, repeatable (e.g. steps=100)."),
        click.option("--epochs", type=click.IntRange(min=0),
                     help="Inner-optimization epochs (default: the task's)."),
        click.option("--set", "settings", multiple=True, callback=parse_settings,
                     metavar="KEY=VALUE", help="Any other search setting for every cell, "
                     "repeatable (e.g. iterations=2, explore=4, max_usd=5, timeout_s=600)."),
        click.option("--api-base", metavar="URL",
                     help="Base URL of an OpenAI-compatible server (local models)."),
        click.option("--workers", type=click.IntRange(min=1), default=1, show_default=True,
                     help="Sandbox workers of each cell (candidates evaluated at once)."),
        click.option("--parallel", type=click.IntRange(min=1),
                     help="Cells run at once [default: CPU cores / workers]."),
    ]  # fmt: skip

    def decorate(function: Callable[..., Any]) -> Callable[..., Any]:
        for option in reversed(options):
            function = option(function)
        return function

    return decorate


def run_benchmark(
    methods: Sequence[Method],
    *,
    tasks: Sequence[str],
    seeds: Sequence[int],
    out: Path,
    task_options: dict[str, str],
    epochs: int | None,
    settings: dict[str, Any],
    api_base: str | None,
    workers: int,
    parallel: int | None,
) -> None:
    """Plan and run the grid, then write and print its table; exit 1 if a cell failed."""
    shared = {**settings, "epochs": epochs, "api_base": api_base, "workers": workers}
    try:
        cells = plan_cells(tasks, methods, seeds, out, shared, task_options)
        failures = run_cells(cells, parallel or default_parallel(workers))
    except GridError as error:
        raise click.UsageError(str(error)) from error
    grid = table.collect(cells)
    ranks = table.rank(grid)
    paths = table.write_tables(grid, ranks, out)
    paths.append(chart.plot_ranks(ranks, out / "ranks.png"))
    click.echo(table.markdown(grid, ranks))
    for path in paths:
        click.echo(str(path))
    if failures:
        for cell, error in failures:
            click.echo(f"failed: {cell.name}: {error}", err=True)
        click.echo(f"{len(failures)} cells failed; run the same command again to resume them",
                   err=True)  # fmt: skip
        sys.exit(1)
