"""The grid's results: the final best loss of each cell, summarised per task and method.

``table.md`` and ``table.csv`` hold, per task (row) and method (column), the mean and the
sample standard deviation of the final loss over the seeds; ``ranks.csv`` each method's rank
per task and its mean rank. A method ranks by how many seeds found a valid solution (more is
better), then by the mean loss over those seeds; ties share the mean of their ranks.
"""

from __future__ import annotations

import csv
import math
import statistics
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from sga_agent.benchmark.grid import Cell, cell_run, summary_of

TABLE_MD, TABLE_CSV, RANKS_CSV = "table.md", "table.csv", "ranks.csv"


@dataclass(frozen=True)
class Score:
    """The final losses of one method on one task: those of the seeds that finished with a
    valid solution, out of ``seeds`` planned."""

    losses: tuple[float, ...]
    seeds: int

    @property
    def n(self) -> int:
        return len(self.losses)

    @property
    def mean(self) -> float:
        return statistics.fmean(self.losses) if self.losses else math.nan

    @property
    def std(self) -> float:
        """Sample standard deviation; NaN for fewer than two losses."""
        return statistics.stdev(self.losses) if self.n > 1 else math.nan


#: task -> method label -> value, in the grid's order.
Grid = dict[str, dict[str, Score]]
Ranks = dict[str, dict[str, float]]


def final_loss(cell: Cell) -> float | None:
    """The best valid loss of the cell's finished run; None if unfinished or nothing valid."""
    store = cell_run(cell)
    summary = summary_of(store) if store is not None else None
    best = (summary or {}).get("best") or {}
    return float(best["loss"]) if best.get("valid") else None


def collect(cells: Sequence[Cell]) -> Grid:
    """Every (task, method) score of the grid, read from the cells' summaries."""
    losses: dict[str, dict[str, list[float]]] = {}
    seeds: dict[tuple[str, str], int] = {}
    for cell in cells:
        row = losses.setdefault(cell.task, {}).setdefault(cell.method.label, [])
        seeds[cell.task, cell.method.label] = seeds.get((cell.task, cell.method.label), 0) + 1
        loss = final_loss(cell)
        if loss is not None:
            row.append(loss)
    return {
        task: {label: Score(tuple(values), seeds[task, label]) for label, values in row.items()}
        for task, row in losses.items()
    }


def rank(grid: Grid) -> Ranks:
    """Each method's rank per task (1 = best; see the module docstring)."""
    ranks: Ranks = {}
    for task, row in grid.items():
        keys = {
            label: (-score.n, score.mean if score.n else math.inf) for label, score in row.items()
        }
        ordered = sorted(keys.values())
        ranks[task] = {
            label: statistics.fmean(i + 1 for i, other in enumerate(ordered) if other == key)
            for label, key in keys.items()
        }
    return ranks


def mean_ranks(ranks: Ranks) -> dict[str, float]:
    """Each method's rank averaged over the tasks."""
    labels = list(next(iter(ranks.values()), {}))
    return {label: statistics.fmean(row[label] for row in ranks.values()) for label in labels}


def number(value: float) -> str:
    """A loss for people: three significant digits in scientific notation ("5.24e-5")."""
    if value == 0:
        return "0"
    mantissa, exponent = f"{value:.2e}".split("e")
    return f"{mantissa}e{int(exponent)}"


def _cell_text(score: Score, best: bool) -> str:
    if not score.n:
        return "no valid result"
    text = number(score.mean) + (f" ± {number(score.std)}" if score.n > 1 else "")
    text = f"**{text}**" if best else text
    return text + (f" ({score.n}/{score.seeds} seeds)" if score.n < score.seeds else "")


def markdown(grid: Grid, ranks: Ranks) -> str:
    """The loss table and the rank table, as Markdown."""
    labels = list(next(iter(grid.values())))
    lines = [
        "Final best loss per task (lower is better): mean ± sample standard deviation over "
        "the seeds; **bold**: the best method of the task; (k/n seeds): only k of n seeds "
        "finished with a valid solution.",
        "",
        "| task | seeds | " + " | ".join(labels) + " |",
        "|---|---|" + "---|" * len(labels),
    ]
    for task, row in grid.items():
        top = min(ranks[task].values())
        seeds = max(score.seeds for score in row.values())
        cells = [_cell_text(row[label], ranks[task][label] == top) for label in labels]
        lines.append(f"| {task} | {seeds} | " + " | ".join(cells) + " |")
    means = mean_ranks(ranks)
    lines += [
        "",
        "Rank per task (1 = best; ties share the mean rank):",
        "",
        "| method | " + " | ".join(grid) + " | mean rank |",
        "|---|" + "---|" * (len(grid) + 1),
    ]
    for label in labels:
        per_task = [f"{ranks[task][label]:g}" for task in grid]
        lines.append(f"| {label} | " + " | ".join(per_task) + f" | {means[label]:.2f} |")
    return "\n".join(lines) + "\n"


def _csv_number(value: float) -> str:
    return "" if math.isnan(value) else repr(value)


def write_tables(grid: Grid, ranks: Ranks, out: Path) -> list[Path]:
    """Write ``table.md``, ``table.csv`` and ``ranks.csv`` into ``out``; their paths."""
    out.mkdir(parents=True, exist_ok=True)
    labels = list(next(iter(grid.values())))
    (out / TABLE_MD).write_text(markdown(grid, ranks), encoding="utf-8")
    with open(out / TABLE_CSV, "w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        header = ["task", "seeds"]
        for label in labels:
            header += [f"{label} mean", f"{label} std", f"{label} n"]
        writer.writerow(header)
        for task, row in grid.items():
            values: list[str] = [task, str(max(score.seeds for score in row.values()))]
            for label in labels:
                score = row[label]
                values += [_csv_number(score.mean), _csv_number(score.std), str(score.n)]
            writer.writerow(values)
    means = mean_ranks(ranks)
    with open(out / RANKS_CSV, "w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow(["method", *grid, "mean rank"])
        for label in labels:
            writer.writerow([label, *(f"{ranks[task][label]:g}" for task in grid), means[label]])
    return [out / TABLE_MD, out / TABLE_CSV, out / RANKS_CSV]
