"""Live progress of a search and its final screen (rich)."""

from __future__ import annotations

import json
import math
from collections import Counter
from typing import Any

import click
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from sga_agent import events as ev
from sga_agent.causes import cause_of, top_causes
from sga_agent.config import UNTIL_BUDGET, SearchConfig
from sga_agent.run_store import Recorded, RunStore
from sga_agent.runner import BUILTIN, REPLAY_PREFIX
from sga_agent.search import SEED, SearchResult
from sga_agent.task import Evaluation, Task, as_task, solution_with_parameters

#: Causes of failure the final screen names, the most frequent first.
CAUSES = 3


def uses_a_model(config: SearchConfig) -> bool:
    """Whether the run's proposer is an LLM (so tokens and money are worth showing)."""
    return not config.proposer.startswith((BUILTIN, REPLAY_PREFIX))


def _loss(value: float) -> str:
    return f"{value:.4g}" if math.isfinite(value) else "-"


class SearchProgress:
    """A progress bar over every candidate of the run: the iteration running, candidates done
    out of all, the time, then the best loss, how many failed and (with a model) the spend.

    The count and the clock come before the status text, so that a narrow terminal cuts the
    status, not them. A resumed run starts from what its folder holds.
    """

    def __init__(
        self, console: Console, config: SearchConfig, recorded: Recorded | None = None
    ) -> None:
        self.progress = Progress(
            TextColumn("[bold]{task.description}"),
            BarColumn(bar_width=16),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            TextColumn("{task.fields[status]}"),
            console=console,
        )
        self.config = config
        self.spend = uses_a_model(config)
        recorded = recorded or Recorded()
        done = list(recorded.evaluations.values())
        self.best = min((e.loss for e in done if e.valid), default=math.inf)
        self.failed = sum(not e.valid for e in done)
        self.screened = set(recorded.screens)  # candidates done once screened (multi-fidelity)
        self.bounded = config.loop.iterations < UNTIL_BUDGET  # else the time budget ends it
        total = 1 + config.loop.iterations * config.loop.offspring if self.bounded else None
        description = "resuming" if done else "seed"
        completed = len(recorded.evaluations.keys() | recorded.screens.keys())
        self.bar = self.progress.add_task(
            description, total=total, completed=completed, status=self._status(None)
        )

    def __enter__(self) -> SearchProgress:
        self.progress.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.progress.stop()

    def __call__(self, event: dict[str, Any]) -> None:
        kind = event["type"]
        if kind == ev.CandidateEvaluated.type:
            evaluation = event["evaluation"]
            if evaluation["valid"]:
                self.best = min(self.best, float(evaluation["loss"]))
            else:
                self.failed += 1
            if event.get("candidate") not in self.screened:  # a screened one counted already
                self.progress.advance(self.bar)
        elif kind == ev.CandidateScreened.type:
            self.screened.add(event["candidate"])
            self.progress.advance(self.bar)
        elif kind == ev.ProposalMissing.type:
            self.failed += 1
            self.progress.advance(self.bar)
        elif kind == ev.IterationStarted.type:
            description = f"iteration {event['iteration']}"
            if self.bounded:
                description += f"/{self.config.loop.iterations}"
            self.progress.update(self.bar, description=description)
        elif kind == ev.RunFinished.type:
            self.progress.update(self.bar, description="done")
        self.progress.update(self.bar, status=self._status(event.get("totals")))

    def _status(self, totals: Any) -> str:
        status = f"best {_loss(self.best)}  failed {self.failed}"
        if self.spend and totals is not None:
            status += f"  {totals.tokens} tokens  ${totals.cost_usd:.3f}"
        return status


def print_result(
    console: Console,
    store: RunStore,
    result: SearchResult,
    as_json: bool,
    task: Task,
    config: SearchConfig,
) -> None:
    """The final screen: the top-K table, the best solution against the seed, the best
    solution with its fitted constants, the counts by status, the most frequent causes of
    failure and the report command (or the run summary as JSON, the causes under "causes")."""
    summary = json.loads((store.path / "summary.json").read_text(encoding="utf-8"))
    summary["run"] = str(store.path)
    run = store.recorded()
    outcomes = answers(run)
    if as_json:
        summary["causes"] = [[cause, count] for cause, count in top_causes(outcomes, CAUSES)]
        click.echo(json.dumps(summary))
        return
    recorded = run.evaluations
    seed = recorded.get(SEED)
    table = Table("rank", "candidate", "loss", "x below the seed", title=f"top {len(result.top)}")
    for rank, entry in enumerate(result.top, 1):
        loss = f"{entry.loss:.6g}" if math.isfinite(entry.loss) else "invalid"
        table.add_row(str(rank), entry.candidate, loss, _ratio(seed, entry.loss))
    console.print(table)
    best = result.best
    if best is not None and best.valid:
        console.print(_comparison(best.candidate, best.loss, seed))
        findings = summary.get("findings") or {}
        verdict = [f"verdict: {findings['verdict']}"] if findings.get("verdict") else []
        for line in [*_truth_lines(findings), *verdict, *as_task(task).screen_lines(findings)]:
            console.print(line)
        if best.parameters:
            console.print("its code, with the fitted constants written in:")
        code = solution_with_parameters(task, best.code, best.parameters)
        console.out(code, highlight=False)  # as written: never wrapped, so it can be copied
    else:
        console.print("no valid solution was found")
    console.print(_counts(recorded.values(), run.screens.values(), result, uses_a_model(config)))
    if failures := failures_line(outcomes):
        console.print(failures)
    console.print(f"report: sga-agent report {store.path}", soft_wrap=True)


def answers(recorded: Recorded) -> list[dict[str, Any]]:
    """How each candidate after the seed ended, as an evaluation's fields: its full
    evaluation, else its screen (a multi-fidelity search's candidate never fitted fully)."""
    outcomes = {**recorded.screens, **recorded.evaluations}
    return [vars(e) for candidate, e in sorted(outcomes.items()) if candidate != SEED]


def failures_line(outcomes: list[dict[str, Any]]) -> str:
    """``"failures: F of N answers: n1 cause1; n2 cause2; ..."``, the :data:`CAUSES` most
    frequent causes (:func:`~sga_agent.causes.cause_of`) and how many others; "" for none."""
    failed = sum(bool(cause_of(outcome)) for outcome in outcomes)
    if not failed:
        return ""
    top = top_causes(outcomes, CAUSES)
    parts = [f"{count} {cause}" for cause, count in top]
    if rest := failed - sum(count for _, count in top):
        parts.append(f"{rest} of other causes")
    return f"failures: {failed} of {len(outcomes)} answers: " + "; ".join(parts)


def _ratio(seed: Evaluation | None, loss: float) -> str:
    if seed is None or not seed.valid or not math.isfinite(loss) or loss <= 0:
        return "-"
    ratio = seed.loss / loss
    return f"{ratio:.2f}" if ratio < 10 else f"{ratio:.3g}"


def _comparison(candidate: str, loss: float, seed: Evaluation | None) -> str:
    """One line: the best loss, the seed's and their ratio."""
    line = f"best: {candidate}, loss {loss:.4g}"
    if candidate == SEED:
        return line + " (the seed: no candidate did better)"
    if seed is None or not seed.valid:
        return line + " (the seed had no valid loss)"
    return line + f", {_ratio(seed, loss)}x below the seed's {seed.loss:.4g}"


def _truth_lines(findings: dict[str, Any]) -> list[str]:
    """The ground truth with its loss against the best, as the report's summary states it."""
    if not findings.get("truth"):
        return []
    line = f"ground truth: {findings['truth']}"
    if findings.get("truth_loss") is not None:
        line += f"; its loss {findings['truth_loss']:.4g}"
        if findings.get("best_over_truth") is not None:
            line += f", {findings['best_over_truth']:.3g}x below the best's"
    return [line]


def _counts(evaluations: Any, screens: Any, result: SearchResult, spend: bool) -> str:
    """Full evaluations by status (duplicates of earlier code not counted), then the screens of
    a multi-fidelity search by status, then the spend."""
    text = _by_status("evaluations", evaluations)
    if screens := list(screens):
        text += " after " + _by_status("screens", screens)
    if spend:
        text += f", {result.totals.tokens} tokens, ${result.totals.cost_usd:.4f}"
    if result.stopped:
        text += f"; stopped: {result.stopped}"
    return text


def _by_status(what: str, evaluations: Any) -> str:
    """``"N what (n1 ok, n2 unstable)"``, copies of earlier code not counted."""
    statuses = Counter(e.status for e in evaluations if "duplicate_of" not in e.extras)
    parts = ", ".join(f"{count} {status}" for status, count in statuses.most_common())
    return f"{sum(statuses.values())} {what} ({parts})"
