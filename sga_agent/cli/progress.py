"""Live progress of a search and its final screen (rich); progress as plain lines where the
console is no terminal."""

from __future__ import annotations

import datetime
import json
import math
import threading
import time
from collections import Counter
from collections.abc import Callable
from typing import Any

import click
from rich.console import Console, Group
from rich.live import Live
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    ProgressColumn,
    TaskID,
    TextColumn,
    TimeElapsedColumn,
)
from rich.progress import Task as RichTask
from rich.table import Column, Table
from rich.text import Text

from sga_agent import events as ev
from sga_agent.causes import cause_of, top_causes
from sga_agent.config import UNTIL_BUDGET, SearchConfig
from sga_agent.natural_units import natural_values_of
from sga_agent.run_store import Recorded, RunStore
from sga_agent.runner import BUILTIN, REPLAY_PREFIX
from sga_agent.search import SEED, SearchResult
from sga_agent.task import Evaluation, FitProgress, Task, as_task, solution_with_parameters
from sga_agent.wording import counted, times_below

#: Causes of failure the final screen names, the most frequent first.
CAUSES = 3


def uses_a_model(config: SearchConfig) -> bool:
    """Whether the run's proposer is an LLM (so tokens and money are worth showing)."""
    return not config.proposer.startswith((BUILTIN, REPLAY_PREFIX))


def _loss(value: float) -> str:
    return f"{value:.4g}" if math.isfinite(value) else "-"


#: Seconds between two checks of whether a plain line of progress is due.
TICK_S = 0.5
#: Seconds between two plain lines of a search's progress, at most while something changes,
#: and at least while nothing does.
PLAIN_EVERY_S = 5.0
#: Seconds of a command in which no plain line of progress is printed: a command done sooner
#: prints what it printed without progress.
PLAIN_GRACE_S = 5.0
#: The activity line's words for each phase of a search.
_PHASES = {
    "seed": "seed fit",
    "proposing": "proposing",
    "screens": "screens",
    "fits": "full fits",
    "assessing": "assessing",
}
#: The phases that run a batch of evaluations.
_BATCHES = ("screens", "fits")


def note_text(note: FitProgress) -> str:
    """A progress note in words: "fitting: epoch 3/31, loss 1.2e-05", or its stage alone
    ("warming up") when it counts no epochs."""
    if note.epoch is None or note.epochs is None:
        return note.stage
    text = f"{note.stage}: epoch {note.epoch}/{note.epochs}"
    return text if note.loss is None else f"{text}, loss {note.loss:.4g}"


def clock(seconds: float) -> str:
    """``seconds`` as rich's elapsed time shows it: "0:01:05"."""
    return str(datetime.timedelta(seconds=int(seconds)))


class Count(MofNCompleteColumn):
    """Done out of all ("12/31"); nothing for a task of unknown length."""

    def render(self, task: RichTask) -> Text:
        return Text("") if task.total is None else super().render(task)


class Ellipsized(ProgressColumn):
    """A task's ``status`` field on one line, cut with an ellipsis where the line ends (the
    other columns of its line must not wrap: then only this one gives way)."""

    def render(self, task: RichTask) -> Text:
        return Text(task.fields.get("status", ""), no_wrap=True, overflow="ellipsis")


class PlainLines:
    """Progress as plain lines, for a console that is no terminal (a pipe, a log file), where a
    live display would show nothing before it ends.

    Nothing is printed in the first ``grace_s`` seconds (a command done by then prints what it
    would without progress); then the current state (``state()``). After that :meth:`say`
    prints a line at once; after :meth:`changed` the state is printed once ``every_s``
    seconds have passed since the last line; and the state is printed again after ``quiet_s``
    seconds without a line, so that the output is never silent for long while work goes on.
    Thread-safe: ``state`` is called with this object's lock held, so a lock it takes must not
    be held by whoever calls :meth:`say` or :meth:`changed`.
    """

    def __init__(
        self,
        console: Console,
        state: Callable[[], str],
        every_s: float,
        quiet_s: float,
        grace_s: float = PLAIN_GRACE_S,
    ) -> None:
        self.console, self.state = console, state
        self.every_s, self.quiet_s, self.grace_s = every_s, quiet_s, grace_s
        self._lock = threading.Lock()
        self._started = self._last = time.monotonic()
        self._pending = False
        self._stopped = threading.Event()
        self._thread = threading.Thread(target=self._tick, name="sga-progress", daemon=True)

    def start(self) -> None:
        self._started = self._last = time.monotonic()
        self._thread.start()

    def stop(self) -> None:
        """Stop the clock; a change not printed yet is printed now (the last state), unless
        nothing was printed yet."""
        self._stopped.set()
        if self._thread.is_alive():
            self._thread.join()
        with self._lock:
            if self._pending and not self._quiet():
                self._print(self.state())

    def say(self, line: str) -> None:
        """Print ``line`` now (after the grace period: else it is told in the first state)."""
        with self._lock:
            if self._quiet():
                self._pending = True
            else:
                self._print(line)

    def changed(self) -> None:
        """The state has changed: print it now if the last line is old enough, else soon."""
        with self._lock:
            self._pending = True
            if not self._quiet() and time.monotonic() - self._last >= self.every_s:
                self._print(self.state())

    def _quiet(self) -> bool:
        """Whether the grace period lasts."""
        return time.monotonic() - self._started < self.grace_s

    def _tick(self) -> None:
        while not self._stopped.wait(TICK_S):
            with self._lock:
                if self._quiet():
                    continue
                quiet = time.monotonic() - self._last
                first = self._last == self._started  # the grace period has just ended
                if first or (self._pending and quiet >= self.every_s) or quiet >= self.quiet_s:
                    self._print(self.state())

    def _print(self, line: str) -> None:
        self.console.print(line, markup=False, highlight=False, soft_wrap=True)
        self._last, self._pending = time.monotonic(), False


class SearchProgress:
    """A progress bar over every candidate of the run: the iteration running, candidates done
    out of all, the time, then the best loss, how many failed and (with a model) the spend.
    Below it, a line for what runs now and since when: the seed's fit with its epochs, the
    proposals asked for, an iteration's screens or full fits (done out of all, and how far
    each running one has come), the assessment of the best solution at the end.

    The count and the clock come before the status text, so that a narrow terminal cuts the
    status, not them. A resumed run starts from what its folder holds. On a console that is no
    terminal the same is told in plain lines (:class:`PlainLines`, none in the first
    :data:`PLAIN_GRACE_S` seconds): each finished evaluation and iteration at once, what runs
    every :data:`PLAIN_EVERY_S` seconds; the bar as it ends.
    ``assessing`` is what the search's end does before it returns (the task's
    ``describe_assessment``), said when it starts.
    """

    def __init__(
        self,
        console: Console,
        config: SearchConfig,
        recorded: Recorded | None = None,
        assessing: str = "",
    ) -> None:
        self.progress = Progress(
            TextColumn("[bold]{task.description}"),
            BarColumn(bar_width=16),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            TextColumn("{task.fields[status]}"),
            console=console,
        )
        self.activity = Progress(
            TextColumn("  {task.description}", table_column=Column(no_wrap=True)),
            BarColumn(bar_width=16, table_column=Column(no_wrap=True)),
            Count(table_column=Column(no_wrap=True)),
            TimeElapsedColumn(table_column=Column(no_wrap=True)),
            Ellipsized(),
            console=console,
        )
        self.config = config
        self.assessing = assessing
        self.spend = uses_a_model(config)
        recorded = recorded or Recorded()
        done = list(recorded.evaluations.values())
        self.best = min((e.loss for e in done if e.valid), default=math.inf)
        self.failed = sum(not e.valid for e in done)
        self.screened = set(recorded.screens)  # candidates done once screened (multi-fidelity)
        self.bounded = config.loop.iterations < UNTIL_BUDGET  # else the time budget ends it
        total = config.loop.candidates if self.bounded else None
        description = "resuming" if done else "seed"
        completed = len(recorded.evaluations.keys() | recorded.screens.keys())
        self.bar = self.progress.add_task(
            description, total=total, completed=completed, status=self._status(None)
        )
        self._lock = threading.Lock()  # the state below: events come from several threads
        self._phase = ""  # what the activity line shows: "" (nothing), see _PHASES
        self._row: TaskID | None = None  # the activity line
        self._batch: list[str] = []  # the candidates of the running fits or screens
        self._finished: set[str] = set()  # those of them that have finished
        self._notes: dict[str, FitProgress] = {}  # the latest note of each running one
        self._proposals = 0  # answers received in the running iteration
        self._asked = config.loop.offspring  # answers the running iteration asks for
        self._started = time.monotonic()
        self.live = Live(console=console, get_renderable=self.renderable)
        self.plain = None if console.is_terminal else PlainLines(
            console, self.plain_state, PLAIN_EVERY_S, PLAIN_EVERY_S
        )  # fmt: skip

    def __enter__(self) -> SearchProgress:
        self._started = time.monotonic()
        if self.plain is not None:
            self.plain.start()
        else:
            self.live.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        with self._lock:
            self._begin("")  # what ran is over: the bar alone stays on the screen
        if self.plain is not None:
            self.plain.stop()
            self.live.console.print(self.progress)  # the bar at the end, as a live one leaves it
        else:
            self.live.stop()

    def renderable(self) -> Group:
        """The bar and, while something runs, the activity line below it."""
        return Group(self.progress.get_renderable(), self.activity.get_renderable())

    def __call__(self, event: dict[str, Any]) -> None:
        with self._lock:
            line = self._take(event)
            self._show_activity()
            assessing = event["type"] == ev.RunFinished.type and self._phase == "assessing"
        self.progress.update(self.bar, status=self._status(event.get("totals")))
        if self.plain is not None:
            for text in [line, self.assessing if assessing else ""]:
                if text:
                    self.plain.say(text)
            if not line:
                self.plain.changed()
        elif assessing:  # above the bar: it may take minutes
            self.live.console.print(self.assessing, markup=False, highlight=False)

    def _take(self, event: dict[str, Any]) -> str:
        """Count ``event`` in; the plain line it is worth at once ("" for none)."""
        kind = event["type"]
        candidate = event.get("candidate", "")
        if kind == ev.FitProgressed.type:
            note = FitProgress.from_dict(event.get("note"))
            if note is not None:
                self._notes[candidate] = note
            return ""
        if kind == ev.FitsStarted.type:
            self._batch, self._finished = list(event["candidates"]), set()
            self._notes = {c: n for c, n in self._notes.items() if c in self._batch}
            seed = self._batch == [SEED]
            self._begin("seed" if seed else "screens" if event["fidelity"] < 1 else "fits")
            return ""
        if kind in (ev.CandidateEvaluated.type, ev.CandidateScreened.type):
            self._finish(candidate)
        if kind == ev.CandidateEvaluated.type:
            evaluation = event["evaluation"]
            if evaluation["valid"]:
                self.best = min(self.best, float(evaluation["loss"]))
            else:
                self.failed += 1
            if candidate not in self.screened:  # a screened one counted already
                self.progress.advance(self.bar)
            outcome = f"loss {float(evaluation['loss']):.4g}" if evaluation["valid"] else (
                evaluation.get("status", "invalid")
            )  # fmt: skip
            return f"{candidate or 'a candidate'}: {outcome} ({self._tally()})"
        if kind == ev.CandidateScreened.type:
            self.screened.add(candidate)
            self.progress.advance(self.bar)
        elif kind in (ev.ProposalReceived.type, ev.ProposalMissing.type):
            self._proposals += 1
            if kind == ev.ProposalMissing.type:
                self.failed += 1
                self.progress.advance(self.bar)
        elif kind == ev.IterationStarted.type:
            description = f"iteration {event['iteration']}"
            if self.bounded:
                description += f"/{self.config.loop.iterations}"
            self.progress.update(self.bar, description=description)
            self._proposals = 0
            self._asked = self.config.loop.offspring_in(event["iteration"])
            self._begin("proposing")
            return f"{description} ({self._tally()})"
        elif kind == ev.RunFinished.type:
            self.progress.update(self.bar, description="done")
            self._begin("assessing" if self.assessing and math.isfinite(self.best) else "")
            return f"done ({self._tally()})"
        return ""

    def _finish(self, candidate: str) -> None:
        """``candidate``'s evaluation (or screen) has ended: the running batch is over once
        all of it has."""
        self._notes.pop(candidate, None)
        if candidate in self._batch:
            self._finished.add(candidate)
            if len(self._finished) == len(self._batch) and self._phase in ("seed", *_BATCHES):
                self._begin("")

    def _begin(self, phase: str) -> None:
        """Show ``phase`` on the activity line, its clock from zero ("": no line)."""
        self._phase = phase
        if self._row is not None:
            self.activity.remove_task(self._row)
            self._row = None
        if phase:
            total = len(self._batch) if phase in ("screens", "fits") else None
            self._row = self.activity.add_task(_PHASES[phase], total=total, status="")

    def _show_activity(self) -> None:
        """Bring the activity line up to date with the notes."""
        if self._row is None:
            return
        completed, total, status = self._activity()
        self.activity.update(self._row, completed=completed, total=total, status=status)

    def _activity(self) -> tuple[int, int | None, str]:
        """The activity line's count (done, out of all or None) and its status text."""
        if self._phase == "seed":
            note = self._notes.get(SEED)
            if note is None:
                return 0, None, ""
            if note.epoch is None or note.epochs is None:
                return 0, None, note.stage
            loss = "" if note.loss is None else f", loss {note.loss:.4g}"
            return note.epoch, note.epochs, note.stage + loss
        if self._phase in _BATCHES:
            running = [f"{c} {note_text(self._notes[c])}" for c in self._batch
                       if c in self._notes and c not in self._finished]  # fmt: skip
            return len(self._finished), len(self._batch), "; ".join(running)
        if self._phase == "proposing":
            return self._proposals, self._asked, ""
        return 0, None, self.assessing if self._phase == "assessing" else ""

    def plain_state(self) -> str:
        """The state as one plain line: what runs, else the counts; the run's clock last."""
        with self._lock:
            what = self.progress.tasks[0].description
            if self._phase == "seed" and SEED in self._notes:
                what = f"seed fit: {note_text(self._notes[SEED])}"
            elif self._phase in _BATCHES:
                completed, total, status = self._activity()
                what += f": {_PHASES[self._phase]} {completed}/{total} done"
                what += f"; {status}" if status else ""
            elif self._phase == "proposing":
                what += f": proposing ({self._proposals}/{self._asked} answers)"
            elif self._phase == "assessing":
                what += "; assessing the best solution"
            return f"{what} ({self._tally()}) [{clock(time.monotonic() - self._started)}]"

    def _tally(self) -> str:
        """Evaluated out of all, the best loss and the failures, in words."""
        task = self.progress.tasks[0]
        done = f"{task.completed:g}" + ("" if task.total is None else f"/{task.total:g}")
        return f"{done} candidates, best {_loss(self.best)}, failed {self.failed}"

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
    """The final screen: the top-K table, the best solution against the seed, what the task
    says of it (a molecule's property), its fitted values in natural units, the best solution
    itself (a law with its fitted constants), the counts by status, the most frequent causes
    of failure and the report command (or the run summary as JSON, the causes under
    "causes")."""
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
    table = Table("rank", "candidate", "loss", "vs the seed's", title=f"top {len(result.top)}")
    for rank, entry in enumerate(result.top, 1):
        loss = f"{entry.loss:.6g}" if math.isfinite(entry.loss) else "invalid"
        table.add_row(str(rank), entry.candidate, loss, _ratio(seed, entry.loss))
    console.print(table)
    best = result.best
    if best is not None and best.valid:
        console.print(_comparison(best.candidate, best.loss, seed))
        findings = summary.get("findings") or {}
        verdict = [f"verdict: {findings['verdict']}"] if findings.get("verdict") else []
        for line in [*_truth_lines(findings), *verdict]:
            console.print(line)
        if (forms := findings.get("identifiability")) and forms.get("sentence"):
            # one line however long: it ends with a scene file's path, which must not break
            console.print(f"identifiability: {forms['sentence']}", soft_wrap=True)
        elif findings.get("deferred"):
            console.print(f"identifiability: {findings['deferred']}", soft_wrap=True)
        for line in as_task(task).screen_lines(findings):
            console.print(line)
        if natural := natural_values_of(task, best.code, best.parameters):
            console.print("fitted, in natural units: " + "; ".join(map(str, natural.values())))
        if findings.get("best_formula"):
            console.print(f"as a formula: {findings['best_formula']}", soft_wrap=True)
        console.print(_solution_label(task, bool(best.parameters)))
        code = solution_with_parameters(task, best.code, best.parameters)
        console.out(code, highlight=False)  # as written: never wrapped, so it can be copied
        if simple := findings.get("simplified"):
            console.print(f"simplified: {simple['sentence']}:")
            console.out(simple["solution"], highlight=False)
            if simple.get("formula"):
                console.print(f"as a formula: {simple['formula']}", soft_wrap=True)
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
        parts.append("1 of another cause" if rest == 1 else f"{rest} of other causes")
    return f"failures: {failed} of {counted(len(outcomes), 'answer')}: " + "; ".join(parts)


def _solution_label(task: Task, fitted: bool) -> str:
    """What the best solution printed below is, by the task's kind: a law's code (with its
    fitted constants written in), or an entity (a molecule) as it was proposed."""
    if as_task(task).kind == "entity":
        return "as proposed, before its optimization:" if fitted else "the best solution:"
    return "its code, with the fitted constants written in:" if fitted else "its code:"


def _ratio(seed: Evaluation | None, loss: float, reference: str = "") -> str:
    """How many times ``loss`` is below (or above) the seed's: "38.9x below", "2.00x above";
    "-" without a valid seed or loss."""
    if seed is None or not seed.valid or not math.isfinite(loss) or loss <= 0:
        return "-"
    return times_below(seed.loss / loss, reference)


def _comparison(candidate: str, loss: float, seed: Evaluation | None) -> str:
    """One line: the best loss, the seed's and their ratio."""
    line = f"best: {candidate}, loss {loss:.4g}"
    if candidate == SEED:
        return line + " (the seed: no candidate did better)"
    if seed is None or not seed.valid:
        return line + " (the seed had no valid loss)"
    reference = f"the seed's {seed.loss:.4g}"
    return line + ", " + _ratio(seed, loss, reference)


def _truth_lines(findings: dict[str, Any]) -> list[str]:
    """The ground truth with its loss against the best, as the report's summary states it."""
    if not findings.get("truth"):
        return []
    line = f"ground truth: {findings['truth']}"
    if findings.get("truth_loss") is not None:
        line += f"; its loss {findings['truth_loss']:.4g}"
        if findings.get("best_over_truth") is not None:
            line += ", " + times_below(findings["best_over_truth"], "the best's")
    return [line]


def _counts(evaluations: Any, screens: Any, result: SearchResult, spend: bool) -> str:
    """Full evaluations by status (duplicates of earlier code not counted), then the screens of
    a multi-fidelity search by status, then the spend."""
    text = _by_status("evaluation", evaluations)
    if screens := list(screens):
        text += " after " + _by_status("screen", screens)
    if spend:
        text += f", {counted(result.totals.tokens, 'token')}, ${result.totals.cost_usd:.4f}"
    if result.stopped:
        text += f"; stopped: {result.stopped}"
    if result.interrupted:
        text += (f" ({counted(len(result.interrupted), 'evaluation')} not finished then, "
                 "left for `sga-agent resume` with a larger --time-budget)")  # fmt: skip
    return text


def _by_status(what: str, evaluations: Any) -> str:
    """``"N whats (n1 ok, n2 unstable)"`` (``what`` in the singular: "1 screen (1 ok)"),
    copies of earlier code not counted."""
    statuses = Counter(e.status for e in evaluations if "duplicate_of" not in e.extras)
    parts = ", ".join(f"{count} {status}" for status, count in statuses.most_common())
    return f"{counted(sum(statuses.values()), what)} ({parts})"
