"""Assembling the report of one run folder: figures first, then the Markdown and HTML pages."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path

from sga_agent.report import pictures, plots
from sga_agent.report.data import Run, read_run
from sga_agent.report.render import Code, Image, Section, Table, Text, write
from sga_agent.task import STATUSES

TOP = 3


def _loss(value: float) -> str:
    return f"{value:.4g}" if math.isfinite(value) else "inf"


def summary_section(run: Run) -> Section:
    config, best = run.config, run.best
    settings = ", ".join(f"{key}={config.get(key)}" for key in (
        "iterations", "exploit", "explore", "top_k", "bilevel", "epochs", "workers", "seed",
    ))  # fmt: skip
    options = config.get("task_options") or {}
    lines = [
        f"- task: `{run.task}`",
        f"- proposer: `{config.get('proposer')}` (preset `{config.get('preset')}`)",
        f"- settings: {settings}" + (f"; task options {json.dumps(options)}" if options else ""),
        "- best loss: " + (f"**{_loss(best.loss)}** ({best.id})" if best else "none scored"),
        f"- evaluations: {len(run.candidates)} candidates, "
        f"{sum(c.status == 'ok' for c in run.candidates)} ok",
        f"- tokens: {run.tokens}; cost: ${run.cost_usd:.4f}",
    ]
    if run.summary and run.summary.get("stopped"):
        lines.append(f"- stopped: {run.summary['stopped']}")
    blocks: list = [Text("\n".join(lines))]
    if run.sandbox:
        rows = [[key, str(value)] for key, value in run.sandbox.items()]
        blocks += [Text("Isolation of the evaluation workers:"), Table(["aspect", "record"], rows)]
    else:
        blocks.append(Text("No isolation record (`sandbox` event) in events.jsonl."))
    return Section("Summary", blocks)


def outcomes_table(run: Run) -> Table:
    counts = plots.outcome_counts(run)
    rows = [[str(i), *(str(counts[i][s]) for s in STATUSES), str(sum(counts[i].values()))]
            for i in counts]  # fmt: skip
    return Table(["iteration", *STATUSES, "total"], rows)


def task_section(
    run: Run, folder: Path, motion: bool, say: Callable[[str], None]
) -> Section | None:
    """The task-specific pictures; None for a task without any. Failures become a note."""
    family, best = pictures.task_family(run.task), run.best
    if family == "constitutive":
        title = "Motion: ground truth vs the best law"
        if not motion:
            return Section(title, [Text("Skipped (`--no-motion`).")])
        if best is None:
            return Section(title, [Text("Skipped: no candidate was scored.")])
        say("simulating the best law for the motion pictures (the first run compiles "
            "Taichi's kernels: up to a minute)")  # fmt: skip
        try:
            png, gif = pictures.plot_motion(run, best, folder)
        except Exception as error:  # any failure of the re-simulation only loses this picture
            return Section(title, [Text(f"Skipped: the re-simulation failed ({error!r}).")])
        return Section(title, [
            Text(f"Particle positions (x-y projection) of the observation and of {best.id} with "
                 "its fitted parameters, simulated freely from the first step in float32."),
            Image(png.name, "ground truth vs best law"), Image(gif.name, "animation"),
        ])  # fmt: skip
    if family == "molecules":
        title = f"Top {TOP} molecules"
        top = run.ranked()[:TOP]
        say("drawing the top molecules")
        try:
            png = pictures.plot_molecules(top, folder / "molecules.png")
        except Exception as error:  # a SMILES RDKit cannot read only loses this picture
            return Section(title, [Text(f"Skipped: the depiction failed ({error!r}).")])
        return Section(title, [Image(png.name, "top molecules")])
    return None


def build_report(
    run_dir: Path,
    out: Path | None = None,
    motion: bool = True,
    say: Callable[[str], None] = lambda text: None,
) -> list[Path]:
    """Write the report of the run in ``run_dir`` into ``out`` (default ``run_dir/report``);
    ``say`` is told what each slow step is doing before it starts.

    Returns the paths written: ``report.md``, ``report.html`` and the figures.
    """
    say(f"reading the run in {run_dir}")
    run = read_run(run_dir)
    folder = Path(out) if out is not None else run.path / "report"
    folder.mkdir(parents=True, exist_ok=True)
    label = pictures.loss_label(run.task)
    top = run.ranked()[:TOP]
    say("plotting the losses")
    figures = [
        plots.plot_best_loss(run, folder / "best_loss.png", label),
        plots.plot_outcomes(run, folder / "outcomes.png"),
        plots.plot_curves(top, folder / "curves.png", label),
    ]
    best = run.best
    sections = [
        summary_section(run),
        Section("Best loss per iteration", [Image(figures[0].name, "best loss per iteration")]),
        Section("Outcomes per iteration",
                [Image(figures[1].name, "outcomes per iteration"), outcomes_table(run)]),
        Section(f"Inner-loop curves of the top {TOP} candidates", [
            Text(", ".join(f"{c.id} (loss {_loss(c.loss)})" for c in top) or "none scored"),
            Image(figures[2].name, "inner-loop curves"),
        ]),
        Section("Best solution", [
            Text(f"{best.id}, loss {_loss(best.loss)}, fitted parameters "
                 f"{json.dumps(best.parameters)}"),
            Code(best.code, "python"), Text("Feedback:"), Code(best.feedback),
        ] if best else [Text("No candidate was scored.")]),
    ]  # fmt: skip
    extra = task_section(run, folder, motion, say)
    if extra is not None:
        sections.append(extra)
        figures += [folder / b.file for b in extra.blocks if isinstance(b, Image)]
    pages = write(folder, f"Search report: {run.path.name}", sections)
    return [*pages, *figures]
