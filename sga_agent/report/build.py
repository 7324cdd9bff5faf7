"""Assembling the report of one run folder: the findings and figures first, then the pages.

The report leads with what a reader judges the run by (:mod:`.findings`), then the search's
pictures and its candidates one by one (:mod:`.candidates`), and ends with the records
(settings, isolation, raw feedback) folded away.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from collections.abc import Callable, Iterable
from pathlib import Path

from sga_agent.config import flat_settings
from sga_agent.registry import load_task
from sga_agent.report import plots
from sga_agent.report.candidates import candidates_section
from sga_agent.report.data import Candidate, Run, Screen, read_run
from sga_agent.report.findings import TOP, Findings, distinct, find
from sga_agent.report.front import front_section
from sga_agent.report.render import Code, Image, Section, Table, Text, write
from sga_agent.task import STATUSES, ReportView, TaskBase
from sga_agent.wording import counted, times_below


def _loss(value: float | None) -> str:
    return f"{value:.4g}" if value is not None and math.isfinite(value) else "inf"


def loss_line(findings: Findings) -> str:
    """The best loss with the seed's and the true law's, as ratios."""
    best, seed = findings.best, findings.seed
    if best is None:
        return "- best loss: none scored"
    line = f"- best loss: **{_loss(best.loss)}** ({best.id})"
    if best.id == (seed.id if seed else None):
        line += ", the seed's: no candidate did better"
    elif findings.seed_over_best is not None and seed is not None:
        line += f", **{times_below(findings.seed_over_best)}** the seed's {_loss(seed.loss)}"
    assessment = findings.assessment
    if assessment is not None and assessment.truth_loss is not None:
        line += f"; the true law's: {_loss(assessment.truth_loss)}"
        if findings.best_over_truth is not None:
            line += f" (the best is **{times_below(1 / findings.best_over_truth)}** it)"
    return line


def by_status(what: str, records: Iterable[Candidate | Screen]) -> str:
    """``"N whats (n1 ok, n2 unstable)"`` (``what`` in the singular: "1 screen (1 ok)") as the
    search's end screen counts ``records``: repeats of earlier code left out, the most frequent
    status first, ties in the given order (the order the run recorded them)."""
    statuses = Counter(record.status for record in records if not record.repeat)
    parts = ", ".join(f"{count} {status}" for status, count in statuses.most_common())
    return f"{counted(sum(statuses.values()), what)} ({parts})"


def counts_line(run: Run) -> str:
    """The full fits by status, then a multi-fidelity search's screens, in the end screen's
    words: ``"7 evaluations (7 ok) after 24 screens (19 ok, 5 unstable)"``."""
    text = by_status("evaluation", plots.evaluated_in_order(run))
    screens = [candidate.screen for candidate in run.screens() if candidate.screen is not None]
    if screens:
        recorded = sorted(screens, key=lambda screen: (screen.time is None, screen.time or 0.0))
        text += " after " + by_status("screen", recorded)
    return text


def screens_line(run: Run) -> str:
    """How a multi-fidelity search screened its candidates and how many screens it promoted to
    a full fit, as a list item ("" for a run without screens)."""
    screened = [c for c in run.screens() if c.screen is not None and not c.screen.repeat]
    if not screened:
        return ""
    fidelity = (run.config.get("loop") or {}).get("screen_fidelity")
    short = f" ({fidelity:g} of a full fit)" if isinstance(fidelity, int | float) else ""
    promoted = sum(candidate.promoted for candidate in screened)
    return (f"- screens: candidates were screened by a short fit{short}, whose loss compares "
            f"only with other screens'; **{promoted} of the {len(screened)} screens** were "
            "promoted to a full fit (the Candidates table's screen column names them)")  # fmt: skip


def summary_section(
    run: Run, findings: Findings, task: TaskBase | None, view: ReportView
) -> Section:
    """What a reader needs in ten seconds: the losses, the truth, the law, and what the task
    adds (its free run, its table of the top molecules)."""
    assessment = findings.assessment
    lines = [f"- task: `{run.task}`"]
    if assessment is not None and assessment.truth:
        lines.append(f"- ground truth: {assessment.truth}")
    lines.append(loss_line(findings))
    if assessment is not None and assessment.verdict:
        lines.append(f"- **verdict**: {assessment.verdict}")
    if findings.forms is not None:
        lines.append(f"- **identifiability**: {findings.forms.sentence}")
    elif findings.forms_error:
        lines.append(f"- the task could not compare the forms that fit: {findings.forms_error}")
    if task is not None:
        lines += task.summary_lines(view)
    if findings.changed:
        lines.append("- **changed since the run started** (this report names what the run "
                     "recorded then): " + "; ".join(findings.changed))  # fmt: skip
    if findings.assessment_error:
        lines.append(f"- the task could not assess the best solution: {findings.assessment_error}")
    duration = f" in {findings.duration_s / 60:.1f} min" if findings.duration_s else ""
    proposer = run.config.get("proposer")
    lines.append(
        f"- {counts_line(run)}{duration}, proposer `{proposer}`, "
        f"{run.tokens} tokens, ${run.cost_usd:.4f}"
    )
    if screens := screens_line(run):
        lines.append(screens)
    if run.summary and run.summary.get("stopped"):
        lines.append(f"- stopped: {run.summary['stopped']}")
    blocks: list = [Text("\n".join(lines))]
    own = task.summary_blocks(view) if task is not None else []
    if own:
        blocks += own
    elif findings.best is not None and findings.best_code:
        fitted = bool(findings.best.parameters)
        blocks.append(Text("The best solution, its fitted constants written in:" if fitted
                           else "The best solution (nothing fitted):"))  # fmt: skip
        blocks.append(Code(findings.best_code, "python"))
        if findings.best_formula:
            blocks.append(Text(f"As a formula: `{findings.best_formula}`"))
        if findings.simplified is not None:
            blocks += [Text(f"Simplified: {findings.simplified.sentence}."),
                       Code(findings.simplified.solution, "python")]  # fmt: skip
            if findings.simplified.formula:
                blocks.append(Text(f"As a formula: `{findings.simplified.formula}`"))
        elif findings.simplified_error:
            blocks.append(Text(f"The task could not simplify it: {findings.simplified_error}"))
        derived = assessment.derived if assessment else {}
        if derived:
            blocks.append(Text("What its fitted parameters amount to (computed from the "
                               "captured graph):\n" + "\n".join(
                                   f"- `{text}` = {value:.4g}" for text, value in derived.items()
                               )))  # fmt: skip
    return Section("Summary", blocks)


def outcomes_table(run: Run) -> Table:
    """The full fits of each iteration by outcome."""
    counts = plots.outcome_counts(run)
    rows = [[str(i), *(str(counts[i][s]) for s in STATUSES), str(sum(counts[i].values()))]
            for i in counts]  # fmt: skip
    return Table(["iteration", *STATUSES, "total"], rows)


def screens_table(run: Run) -> Table:
    """The screens of each iteration that made any, by outcome, and how many were promoted to
    a full fit."""
    counts = plots.outcome_counts(run, screens=True)
    promoted = plots.promoted_counts(run)
    rows = [[str(i), *(str(counts[i][s]) for s in STATUSES), str(sum(counts[i].values())),
             str(promoted[i])] for i in counts if any(counts[i].values())]  # fmt: skip
    return Table(["iteration", *STATUSES, "screens", "promoted"], rows)


def outcomes_section(run: Run, figure: Path) -> Section:
    """The outcomes chart with the full fits' table, and for a multi-fidelity search the
    screens' table."""
    if not run.screens():
        chart = Image(figure.name, "outcomes per iteration")
        return Section("Outcomes per iteration", [chart, outcomes_table(run)])
    return Section("Outcomes per iteration", [
        Text("Each iteration's screens (hatched, left) and full fits (plain, right) by outcome; "
             "a candidate repeating earlier code counts here too."),
        Image(figure.name, "screens and full fits per iteration, by outcome"),
        Text("Full fits:"), outcomes_table(run),
        Text("Screens, and how many of them were promoted to a full fit:"), screens_table(run),
    ])  # fmt: skip


def records_sections(run: Run, findings: Findings) -> list[Section]:
    """The folded records at the end: settings, isolation, the best solution's feedback."""
    config = flat_settings(run.config)
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


def load_or_none(name: str) -> TaskBase | None:
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
    if task is not None and run.best is not None and task.describe_assessment(motion):
        say(task.describe_assessment(motion))
    findings = find(run, task, simulate=motion)  # the options: the run's, typed by the task
    label = task.loss_label if task is not None else "loss"
    top = distinct(run, task)
    view = ReportView(run.task, findings.best, top, findings.assessment, folder, motion, say)
    say("plotting the losses")
    figures = [
        plots.plot_zigzag(run, folder / "zigzag.png", label),
        plots.plot_progress(run, folder / "progress.png", label),
        plots.plot_best_loss(run, folder / "best_loss.png", label),
        plots.plot_curves(top, folder / "curves.png", label),
        plots.plot_outcomes(run, folder / "outcomes.png"),
    ]
    sections = [summary_section(run, findings, task, view)]
    own = task.report_sections(view) if task is not None else []
    for extra in [*own, front_section(run, task, folder, label)]:
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
        outcomes_section(run, figures[4]),
        candidates_section(run, folder),
        *records_sections(run, findings),
    ]  # fmt: skip
    pages = write(folder, f"Search report: {run.path.name}", sections)
    return [*pages, *figures], findings
