"""Assembling the report of one run folder: the findings and figures first, then the pages.

The report leads with what a reader judges the run by (:mod:`.findings`), then the search's
pictures, and ends with the records (settings, isolation, raw feedback) folded away.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path

from sga_agent.registry import load_task
from sga_agent.report import pictures, plots
from sga_agent.report.data import Run, read_run
from sga_agent.report.findings import TOP, Findings, distinct, find
from sga_agent.report.render import Code, Image, Section, Table, Text, write
from sga_agent.task import STATUSES


def _loss(value: float | None) -> str:
    return f"{value:.4g}" if value is not None and math.isfinite(value) else "inf"


def _times(ratio: float) -> str:
    return f"{ratio:.3g}x" if ratio < 1e4 else f"{ratio:.1e}x".replace("e+", "e")


def loss_line(findings: Findings) -> str:
    """The best loss with the seed's and the true law's, as ratios."""
    best, seed = findings.best, findings.seed
    if best is None:
        return "- best loss: none scored"
    line = f"- best loss: **{_loss(best.loss)}** ({best.id})"
    if best.id == (seed.id if seed else None):
        line += ", the seed's: no candidate did better"
    elif findings.seed_over_best is not None and seed is not None:
        line += f", **{_times(findings.seed_over_best)} below** the seed's {_loss(seed.loss)}"
    assessment = findings.assessment
    if assessment is not None and assessment.truth_loss is not None:
        line += f"; the true law's: {_loss(assessment.truth_loss)}"
        if findings.best_over_truth is not None:
            line += f" (the best is **{_times(findings.best_over_truth)} above** it)"
    return line


def free_run_line(findings: Findings, simulate: bool) -> str | None:
    """The free-run error in body sizes (None for a task without a free run)."""
    assessment = findings.assessment
    run = assessment.free_run if assessment else None
    if run is None:
        if assessment is not None and assessment.truth and not simulate:
            return "- free run: skipped (`--no-motion`)"
        return None
    if run.unstable:
        return f"- free run of the best law: unstable ({run.unstable})"
    return (
        f"- free run of the best law (from the initial state, no teacher forcing, "
        f"{run.steps} steps): RMS position error **{100 * run.final_error:.3g}%** of the body "
        f"size at the end, {100 * run.mean_error:.3g}% on average (body size "
        f"{run.body_size:.3g} m)"
    )


def summary_section(run: Run, findings: Findings, simulate: bool) -> Section:
    """What a reader needs in ten seconds: the losses, the truth, the law, the free run."""
    assessment = findings.assessment
    lines = [f"- task: `{run.task}`"]
    if assessment is not None and assessment.truth:
        lines.append(f"- ground truth: {assessment.truth}")
    lines.append(loss_line(findings))
    free = free_run_line(findings, simulate)
    if free:
        lines.append(free)
    if findings.assessment_error:
        lines.append(f"- the task could not assess the best solution: {findings.assessment_error}")
    duration = f" in {findings.duration_s / 60:.1f} min" if findings.duration_s else ""
    ok = sum(c.status == "ok" for c in run.candidates)
    proposer = run.config.get("proposer")
    lines.append(
        f"- {len(run.candidates)} evaluations ({ok} ok){duration}, proposer `{proposer}`, "
        f"{run.tokens} tokens, ${run.cost_usd:.4f}"
    )
    if run.summary and run.summary.get("stopped"):
        lines.append(f"- stopped: {run.summary['stopped']}")
    blocks: list = [Text("\n".join(lines))]
    if findings.molecules:
        blocks += [Text("Top molecules (distinct SMILES), property on the QM9 scale:"),
                   molecules_table(findings)]  # fmt: skip
    elif findings.best is not None and findings.best_code:
        fitted = bool(findings.best.parameters)
        blocks.append(Text("The best solution, its fitted constants written in:" if fitted
                           else "The best solution (nothing fitted):"))  # fmt: skip
        blocks.append(Code(findings.best_code, "python"))
        derived = assessment.derived if assessment else {}
        if derived:
            blocks.append(Text("What its fitted parameters amount to (computed from the "
                               "captured graph):\n" + "\n".join(
                                   f"- `{text}` = {value:.4g}" for text, value in derived.items()
                               )))  # fmt: skip
    return Section("Summary", blocks)


def molecules_table(findings: Findings) -> Table:
    """Rank, SMILES, the normalized property and its value in Hartree and eV, the target, the
    distance to it and the loss of each top molecule."""
    rows = []
    for rank, m in enumerate(findings.molecules, 1):
        scale = "-" if m["hartree"] is None else f"{m['hartree']:+.4f} Ha ({m['ev']:+.2f} eV)"
        rows.append([
            str(rank), m["candidate"], m["smiles"], f"{m['normalized']:+.3f}", scale,
            f"{m['target']:+g}", f"{m['distance']:.3g}", _loss(m["loss"]),
        ])  # fmt: skip
    name = findings.molecules[0]["property"]
    header = ["rank", "candidate", "SMILES", f"{name}, normalized", f"{name}, QM9 scale",
              "target", "distance", "loss"]  # fmt: skip
    return Table(header, rows)


def outcomes_table(run: Run) -> Table:
    counts = plots.outcome_counts(run)
    rows = [[str(i), *(str(counts[i][s]) for s in STATUSES), str(sum(counts[i].values()))]
            for i in counts]  # fmt: skip
    return Table(["iteration", *STATUSES, "total"], rows)


def task_section(
    run: Run, findings: Findings, folder: Path, motion: bool, say: Callable[[str], None]
) -> Section | None:
    """The task-specific pictures; None for a task without any. Failures become a note."""
    family, best = pictures.task_family(run.task), findings.best
    if family == "constitutive":
        title = "Free run: the observation vs the best law"
        if not motion:
            return Section(title, [Text("Skipped (`--no-motion`).")])
        free = findings.assessment.free_run if findings.assessment else None
        if best is None or free is None or free.positions is None:
            why = "no candidate was scored" if best is None else "no free run of the best law"
            return Section(title, [Text(f"Skipped: {why}.")])
        say("drawing the free run")
        png, gif = pictures.plot_motion(run, best, free, folder)
        return Section(title, [
            Text(f"Particle positions (x-y projection) of the observation and of {best.id} with "
                 "its fitted parameters, simulated from the initial state without teacher "
                 "forcing (the fit restarts every segment from the observed state; this does "
                 "not)."),
            Image(png.name, "observation vs the best law, free run"),
            Image(gif.name, "animation"),
        ])  # fmt: skip
    if family == "molecules":
        title = f"Top {TOP} molecules"
        say("drawing the top molecules")
        try:
            png = pictures.plot_molecules(distinct(run, None), folder / "molecules.png")
        except Exception as error:  # a SMILES RDKit cannot read only loses this picture
            return Section(title, [Text(f"Skipped: the depiction failed ({error!r}).")])
        return Section(title, [Image(png.name, "top molecules")])
    return None


def records_sections(run: Run, findings: Findings) -> list[Section]:
    """The folded records at the end: settings, isolation, the best solution's feedback."""
    config = run.config
    settings = [[key, json.dumps(config.get(key))] for key in (
        "proposer", "preset", "iterations", "exploit", "explore", "top_k", "bilevel", "epochs",
        "workers", "seed", "task_options",
    )]  # fmt: skip
    sections = [Section("Settings", [Table(["setting", "value"], settings)], collapsed=True)]
    if run.sandbox:
        rows = [[key, str(value)] for key, value in run.sandbox.items()]
        isolation: list = [Table(["aspect", "record"], rows)]
    else:
        isolation = [Text("No isolation record (`sandbox` event) in events.jsonl.")]
    sections.append(Section("Isolation of the evaluation workers", isolation, collapsed=True))
    best = findings.best
    if best is not None:
        sections.append(Section(f"Feedback of the best solution ({best.id}), as proposers saw it", [
            Text(f"Fitted parameters: {json.dumps(best.parameters)}"), Code(best.feedback),
        ], collapsed=True))  # fmt: skip
    return sections


def load_or_none(name: str) -> object | None:
    """The run's task, or None when it is not installed here (the report then goes without
    what only the task knows)."""
    try:
        return load_task(name)
    except Exception:  # an unknown or broken plugin must not stop the report
        return None


def build_report(
    run_dir: Path,
    out: Path | None = None,
    motion: bool = True,
    say: Callable[[str], None] = lambda text: None,
) -> tuple[list[Path], Findings]:
    """Write the report of the run in ``run_dir`` into ``out`` (default ``run_dir/report``);
    ``motion`` allows the free run of the best solution (a simulation); ``say`` is told what
    each slow step is doing before it starts.

    Returns the paths written (``report.md``, ``report.html``, the figures) and the findings.
    """
    say(f"reading the run in {run_dir}")
    run = read_run(run_dir)
    folder = Path(out) if out is not None else run.path / "report"
    folder.mkdir(parents=True, exist_ok=True)
    task = load_or_none(run.task)
    if getattr(task, "assess", None) is not None and run.best is not None:
        say("assessing the best solution: the true law's loss (cached after the first time)"
            + (" and the free run (the first run compiles Taichi's kernels: up to a minute)"
               if motion else ""))  # fmt: skip
    findings = find(run, task, simulate=motion)
    label = pictures.loss_label(run.task)
    top = distinct(run, task)
    say("plotting the losses")
    figures = [
        plots.plot_zigzag(run, folder / "zigzag.png", label),
        plots.plot_progress(run, folder / "progress.png", label),
        plots.plot_best_loss(run, folder / "best_loss.png", label),
        plots.plot_curves(top, folder / "curves.png", label),
        plots.plot_outcomes(run, folder / "outcomes.png"),
    ]
    sections = [summary_section(run, findings, motion)]
    extra = task_section(run, findings, folder, motion, say)
    if extra is not None:
        sections.append(extra)
        figures += [folder / b.file for b in extra.blocks if isinstance(b, Image)]
    sections += [
        Section("Bilevel optimisation", [
            Text("Each scored candidate's loss at the constants it was proposed with (open "
                 "circle: the inner loop's first epoch) and after its inner optimisation (dot), "
                 "in the order they were evaluated."),
            Image(figures[0].name, "loss before and after fitting each candidate"),
        ]),
        Section("Best loss against evaluations and wall time",
                [Image(figures[1].name, "best loss so far")]),
        Section("Best loss per iteration", [Image(figures[2].name, "best loss per iteration")]),
        Section(f"Inner-loop curves of the top {TOP} distinct solutions", [
            Text(", ".join(f"{c.id} (loss {_loss(c.loss)})" for c in top) or "none scored"),
            Image(figures[3].name, "inner-loop curves"),
        ]),
        Section("Outcomes per iteration",
                [Image(figures[4].name, "outcomes per iteration"), outcomes_table(run)]),
        *records_sections(run, findings),
    ]  # fmt: skip
    pages = write(folder, f"Search report: {run.path.name}", sections)
    return [*pages, *figures], findings
