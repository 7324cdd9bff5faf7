"""Live progress of a search and its final table (rich)."""

from __future__ import annotations

import json
import math
from typing import Any

import click
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.syntax import Syntax
from rich.table import Table

from sga_agent.config import SearchConfig
from sga_agent.run_store import RunStore
from sga_agent.search import SearchResult


class SearchProgress:
    """A progress bar over every candidate of the run, with the best loss and the spend."""

    def __init__(self, console: Console, config: SearchConfig) -> None:
        self.progress = Progress(
            TextColumn("[bold]{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("{task.fields[status]}"),
            TimeElapsedColumn(),
            console=console,
        )
        total = 1 + config.iterations * config.offspring
        self.bar = self.progress.add_task("seed", total=total, status="")
        self.best = math.inf
        self.iteration = 0

    def __enter__(self) -> SearchProgress:
        self.progress.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.progress.stop()

    def __call__(self, event: dict[str, Any]) -> None:
        totals = event["totals"]
        kind = event["type"]
        if kind == "evaluation":
            loss = float(event["evaluation"]["loss"])  # "inf" for invalid candidates
            self.best = min(self.best, loss)
            self.progress.advance(self.bar)
        elif kind == "iteration_done":
            self.iteration = event["iteration"]
        elif kind == "proposal_missing":
            self.progress.advance(self.bar)
        best = f"{self.best:.4g}" if math.isfinite(self.best) else "-"
        self.progress.update(
            self.bar,
            description=f"iteration {self.iteration}" if self.iteration else "seed",
            status=(
                f"best {best}  valid {totals.valid}  invalid {totals.invalid}  "
                f"tokens {totals.tokens}  ${totals.cost_usd:.4f}"
            ),
        )


def print_result(console: Console, store: RunStore, result: SearchResult, as_json: bool) -> None:
    """The top-K table (or the run summary as JSON)."""
    summary = json.loads((store.path / "summary.json").read_text(encoding="utf-8"))
    summary["run"] = str(store.path)
    if as_json:
        click.echo(json.dumps(summary))
        return
    table = Table("rank", "candidate", "loss", title=f"top {len(result.top)}")
    for rank, entry in enumerate(result.top, 1):
        loss = f"{entry.loss:.6g}" if math.isfinite(entry.loss) else "invalid"
        table.add_row(str(rank), entry.candidate, loss)
    console.print(table)
    best = result.best
    if best is not None and best.valid:
        path = store.path / "candidates" / best.candidate / "code.py"
        console.print(f"best: {best.candidate}, loss {best.loss:.6g} ({path})")
        console.print(Syntax(best.code, "python", theme="ansi_dark", word_wrap=True))
    totals = result.totals
    console.print(
        f"{totals.evaluations} evaluations ({totals.valid} valid, {totals.invalid} invalid), "
        f"{totals.tokens} tokens, ${totals.cost_usd:.4f}"
        + (f"; stopped: {result.stopped}" if result.stopped else "")
    )
    console.print(f"run folder: {store.path}")
