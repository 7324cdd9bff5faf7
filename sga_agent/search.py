"""The outer loop of the bilevel search (Algorithm 1 of the paper).

Evaluate the task's seed; then, each iteration, show the model the top-K solutions (worst
first, best last; one per form, so the K are K different laws where that many exist) and what
went wrong in the last iteration, ask for ``exploit`` offspring at the low temperature and
``explore`` at the high one, read each answer as a person would (:mod:`sga_agent.reading`),
evaluate them in sandboxed workers (identical code once) and push them onto the heap. Every
model answer and every finished evaluation is an event in the run store before anything else
happens, and both are looked up there first, so a killed run resumes without asking the model
again or re-evaluating what was finished. A model that cannot be asked stops the search, once
the answers already received are evaluated.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
import math
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Future, as_completed
from dataclasses import dataclass, field
from typing import Any, Protocol

from sga_agent import events as ev
from sga_agent.config import ConfigError, LoopConfig, SearchConfig
from sga_agent.failures import Outcome, failures_text
from sga_agent.fingerprint import fingerprint, form_fingerprint
from sga_agent.heap import Entry, SolutionHeap
from sga_agent.parsing import check_candidate, parse_response
from sga_agent.prompting import Shown, count_tokens, fit_to_budget
from sga_agent.proposers.base import Messages, Proposal, ProposalRequest, Proposer, ProposerError
from sga_agent.reading import read_answer, split_reasoning
from sga_agent.run_store import SEED, RunStore
from sga_agent.task import (
    CodeRejected,
    Evaluation,
    EvaluationSettings,
    FitProgress,
    Parent,
    Task,
    options_type,
)

__all__ = [
    "SEED", "Evaluator", "Search", "SearchResult", "Totals", "kth_best", "promoted", "slots_of",
]  # fmt: skip


class Evaluator(Protocol):
    """Evaluates solutions of a task concurrently (the sandbox pool, or a test double).

    A multi-fidelity search passes ``captured`` (a keyword, only then) for a promoted
    candidate: the data its screen captured, fitted again without a capture. An evaluator
    whose ``submit`` takes a keyword ``progress`` is given, with each evaluation, a callable
    to tell its progress notes (:class:`~sga_agent.task.FitProgress`; any thread), which the
    search shows as :class:`~sga_agent.events.FitProgressed` events; one without it works as
    before. An evaluator with a ``terminate()`` method is stopped with it when the wall-time
    budget runs out while evaluations run (the search then ends; their futures' results are
    not recorded); one without it is waited for.
    """

    def submit(
        self,
        task: str,
        solution: str,
        settings: EvaluationSettings,
        captured: dict[str, Any] | None = None,
    ) -> Future[Evaluation]: ...


@dataclass
class Totals:
    """Tokens, money, evaluations (full fits and screens) and wall seconds spent so far;
    ``screened`` counts the screens, ``valid`` and ``invalid`` the full evaluations."""

    tokens: int = 0
    cost_usd: float = 0.0
    evaluations: int = 0
    seconds: float = 0.0
    valid: int = 0
    invalid: int = 0
    screened: int = 0


@dataclass
class SearchResult:
    """The heap, what was spent, and why the run ended."""

    heap: SolutionHeap
    totals: Totals
    stopped: str = ""  # "" when every iteration ran, else the budget that stopped it
    top: list[Entry] = field(default_factory=list)
    #: Candidates whose evaluations the time budget stopped (unrecorded: a resume runs them).
    interrupted: list[str] = field(default_factory=list)

    @property
    def best(self) -> Entry | None:
        return self.heap.best()


class Search:
    """One run of the search; see the module docstring.

    Parameters
    ----------
    config : SearchConfig
        Its loop, budgets and evaluation settings; its task options must be of the task's
        ``options_type``.
    task : Task
        The task object (only its kind, seed, prompt parts and solution checks are used here;
        evaluation happens in the evaluator's workers).
    proposer : Proposer
        Asked for the answers this run has not recorded yet: a model (which reads the prompt),
        a task's LLM-free proposer (the top-K parents) or a recorded run (the slots' ids).
    evaluator : Evaluator
    store : RunStore
    on_event : callable, optional
        Called with every event (progress display), recorded or only shown (see
        :mod:`sga_agent.events`); the progress notes of running evaluations come from the
        evaluator's threads.
    started : float, optional
        The :func:`time.monotonic` instant this session's wall time counts from (default: the
        construction; the command line passes its process's start, so that a time budget
        covers the start-up).
    """

    def __init__(
        self,
        config: SearchConfig,
        task: Task,
        proposer: Proposer,
        evaluator: Evaluator,
        store: RunStore,
        on_event: Callable[[dict[str, Any]], None] | None = None,
        started: float | None = None,
    ) -> None:
        wanted = options_type(task)
        if not isinstance(config.task_options, wanted):
            raise ConfigError(
                f"task {config.task!r} takes options of type {wanted.__name__}, the config "
                f"holds {type(config.task_options).__name__}: build them with the task's "
                "options_type (sga_agent.options.parse_options reads them from text)"
            )
        self.config = config
        self.loop = config.loop
        self.task = task
        self.proposer = proposer
        self.evaluator = evaluator
        self._reports_progress = _takes_progress(evaluator)
        self.store = store
        self.on_event = on_event or (lambda event: None)
        recorded = store.recorded()
        self._answers = recorded.proposals
        self._evaluations = recorded.evaluations
        self._screens = recorded.screens
        self._fingerprints: dict[str, tuple[str, Evaluation]] = {}
        self._screen_fingerprints: dict[str, tuple[str, Evaluation]] = {}
        self._screened_losses: dict[str, float] = {}  # fingerprint -> valid screen's loss
        self._captured: dict[str, Any] = {}  # fingerprint -> a promoted screen's captured data
        self._fixes: dict[str, list[str]] = {}  # candidate -> slips fixed on reading its answer
        self._codes: dict[str, str] = {}  # candidate -> the code read from its answer
        self._forms: dict[str, str] = {}  # form fingerprint -> the first candidate of that form
        self._same_form: dict[str, str] = {}  # candidate -> the earlier one of its form
        self._template = task.prompt_parts().template
        self.heap = SolutionHeap(config.loop.parsimony)
        self.totals = Totals(seconds=recorded.seconds)
        self._seconds_before = recorded.seconds  # the run's earlier sessions
        self._started = time.monotonic() if started is None else started
        self._kept_for_end = config.budgets.kept_for_end()
        self.settings: EvaluationSettings = config.evaluation_settings()
        self._deadline = ""  # the time budget, once it stopped running evaluations
        self._interrupted: list[str] = []  # the candidates whose evaluations it stopped

    # ------------------------------------------------------------------ the loop

    def run(self) -> SearchResult:
        """Run to the end or to a budget.

        Raises
        ------
        ProposerError
            The proposer could not be asked (no API key, nothing at the address, an unknown
            model, or a provider that gave up after its retries); the answers received before
            are evaluated and the run stays resumable, without a summary.
        """
        start_up = round(time.monotonic() - self._started, 2)  # before the loop: the set-up
        self._emit(ev.SearchStarted(bool(self._evaluations), start_up or None))
        self._evaluate_all([(SEED, self.task.seed_solution(), None)])
        stopped = ""
        for iteration in range(1, self.loop.iterations + 1):
            stopped = self._budget_reached()
            if stopped:
                break
            self._emit(ev.IterationStarted(iteration))
            spent = (self.totals.tokens, self.totals.cost_usd)
            answers, failure = self._answers_for(iteration, self._shown())
            stopped = self._evaluate_iteration(
                [
                    (candidate, *self._extract(candidate, proposal))
                    for candidate, proposal in answers
                ]
            )
            if failure is not None:
                raise failure  # the answers in hand are evaluated: the run resumes from here
            top = [entry.summary() for entry in self.heap.top(self.loop.top_k)]
            self.store.save_heap(iteration, top)
            tokens = self.totals.tokens - spent[0]
            self._emit(ev.IterationDone(iteration, top, tokens, self.totals.cost_usd - spent[1]))
            if stopped:
                break
        self._budget_reached()  # the run's seconds up to its end, not to the last check
        result = SearchResult(
            self.heap, self.totals, stopped, self.heap.top(self.loop.top_k), self._interrupted
        )
        self.store.save_summary(self._summary(result))
        self._emit(ev.RunFinished(stopped))
        return result

    # ------------------------------------------------------------------ proposals

    def _shown(self) -> list[Entry]:
        """The solutions the next prompt shows: the best valid one of each law, K at most
        (the same code, or the same loss, counts once; for an equation task, whose numbers
        are starting values of a fit, so does the same code with other numbers)."""
        return self.heap.distinct_top(self.loop.top_k, self._form)

    def _form(self, code: str) -> str:
        """What makes two solutions one: their form for an equation task (its numbers are
        where the fit starts), their whole code for an entity task (its numbers are it)."""
        return form_fingerprint(code) if self.task.kind == "equation" else fingerprint(code)

    def _answers_for(
        self, iteration: int, shown: list[Entry]
    ) -> tuple[list[tuple[str, dict[str, Any]]], ProposerError | None]:
        """(candidate, proposal dict) of every slot that has an answer, recorded or new, and
        the proposer's error that stopped the asking (None if none).

        The prompt shows ``shown`` (the top-K, one per law) and the last iteration's
        failures; it is built only if the proposer reads it. A proposer that does not (an
        LLM-free one) breeds from the heap's top-K as it stands. Each answer records the ids
        of the solutions it was shown, or bred from, worst first (``parents``).
        """
        slots = slots_of(self.loop, iteration)
        missing: dict[float, list[str]] = {}
        for candidate, temperature in slots:
            if candidate not in self._answers:
                missing.setdefault(temperature, []).append(candidate)
        prompt = functools.cache(functools.partial(self._messages, shown, iteration))
        top = self.heap.top(self.loop.top_k)  # what a proposer without a prompt breeds from
        parents = [Parent(entry.code, entry.loss, entry.parameters) for entry in top]
        failure = None
        for temperature, candidates in missing.items():
            if self._budget_reached():
                break
            seed = (self.config.seed * 1_000_003 + iteration) * 1009 + round(temperature * 100)
            tried = [self._answers[c]["text"] for c in sorted(self._answers)]
            opening = self.loop.explore_in(iteration) > self.loop.explore
            request = ProposalRequest(
                candidates, temperature, seed, parents, prompt, tried,
                opening=opening and temperature == self.loop.explore_temperature,
            )  # fmt: skip
            try:
                new = list(self.proposer.propose(request))[: request.n]
            except ProposerError as error:
                self._emit(ev.ProposerFailed(str(error), error.transient))
                failure = error
                break
            read = shown if request.built_messages is not None else top
            for candidate, proposal in zip(candidates, new, strict=False):
                data = {**proposal.to_dict(), "parents": [e.candidate for e in reversed(read)]}
                self._answers[candidate] = data
                self.store.save_proposal(candidate, request.built_messages, data)
                self._save_answer(candidate, proposal)
                self._emit(ev.ProposalReceived(candidate, data))
            for candidate in candidates[len(new) :]:
                self._emit(ev.ProposalMissing(candidate))
        answers = []
        for candidate, _ in slots:
            if candidate in self._answers:
                data = self._answers[candidate]
                self.totals.tokens += int(data.get("prompt_tokens", 0)) + int(
                    data.get("completion_tokens", 0)
                )
                self.totals.cost_usd += float(data.get("cost_usd", 0.0))
                answers.append((candidate, data))
        return answers, failure

    def _save_answer(self, candidate: str, proposal: Proposal) -> None:
        """The answer's analysis, plan and reasoning (the provider's and its ``<think>``
        part), each as a file of the candidate's folder."""
        thought, visible = split_reasoning(proposal.text)
        sections = parse_response(visible).sections
        reasoning = "\n\n".join(part for part in (proposal.reasoning, thought) if part)
        self.store.save_answer_parts(
            candidate,
            {"analysis": sections.get("analysis", ""), "plan": sections.get("plan", ""),
             "reasoning": reasoning.strip()},
        )  # fmt: skip

    def _messages(self, shown: list[Entry], iteration: int) -> Messages:
        """The prompt showing ``shown`` and what went wrong in the iteration before
        ``iteration``, within the prompt's token budget."""
        history = [Shown(entry.code, entry.feedback, entry.loss) for entry in shown]
        messages, _ = fit_to_budget(
            self.task.kind,
            self.task.prompt_parts(),
            history,
            self._failures(iteration - 1),
            self.config.model.prompt_tokens,
            count_tokens(self.config.proposer),
        )
        return messages

    def _failures(self, iteration: int) -> str:
        """The failure section for ``iteration``'s answers (:mod:`sga_agent.failures`)."""
        prefix = f"{iteration:02d}-"
        outcomes = []
        for candidate in sorted(self._answers):
            if not candidate.startswith(prefix):
                continue
            record = self._evaluations.get(candidate) or self._screens.get(candidate)
            if record is None:
                continue
            code = self._codes.get(candidate, self._answers[candidate].get("text", ""))
            fixes = record.extras.get("read_as") or []
            outcomes.append(Outcome(candidate, code, record.to_dict(), fixes))
        earlier = {entry.candidate: entry.loss for entry in self.heap.entries if entry.valid}
        return failures_text(outcomes, earlier)

    def _extract(self, candidate: str, proposal: dict[str, Any]) -> tuple[str, Evaluation | None]:
        """The answer's code, read as a person would (its slips fixed and recorded), and an
        invalid evaluation when it cannot be run."""
        reading = read_answer(
            proposal["text"], self.task.kind, self._template, proposal.get("finish_reason", "")
        )
        if reading.fixes:
            self._fixes[candidate] = reading.fixes
        if reading.code is None:
            return proposal["text"], Evaluation.invalid(reading.problem)
        self._codes[candidate] = reading.code
        try:
            check_candidate(reading.code, self.task)
        except CodeRejected as error:
            return reading.code, Evaluation.invalid(f"the code was rejected before it ran: {error}")
        return reading.code, None

    # ------------------------------------------------------------------ evaluations

    def _evaluate_iteration(self, candidates: list[tuple[str, str, Evaluation | None]]) -> str:
        """Evaluate an iteration's candidates: all in full, or (multi-fidelity) screen them
        and evaluate in full the promoted ones; returns the budget that stopped it, if any."""
        if self.loop.fidelity == "full":
            return self._evaluate_all(candidates)
        stopped, promoted = self._screen_all(candidates)
        if stopped:
            return stopped
        return self._evaluate_all([entry for entry in candidates if entry[0] in promoted])

    def _screen_all(
        self, candidates: list[tuple[str, str, Evaluation | None]]
    ) -> tuple[str, set[str]]:
        """Screen (or look up the screen of) every candidate that has none and no full
        evaluation; the budget that stopped it ("" if none) and the candidates the full
        evaluation gets: the rejected (recorded as such), those evaluated in full without a
        screen (the same code earlier) and the best ``promote`` share of the valid screens,
        counting identical code once, that beat the ``promote_rank``-th (default K-th) best
        valid screen of the earlier iterations (:func:`promoted`): a resumed run promotes the
        same.
        Each screen is stored the moment it finishes; the promoted screens' captured data is
        kept for their full fit."""
        settings = dataclasses.replace(self.settings, fidelity=self.loop.screen_fidelity)
        passed: set[str] = set()
        screened: list[tuple[str, str]] = []  # (candidate, fingerprint)
        pending: dict[Future[Evaluation], tuple[str, str]] = {}  # -> (candidate, code)
        submitted: set[str] = set()
        stopped = ""
        for candidate, code, rejection in candidates:
            key = fingerprint(code)
            evaluated = candidate in self._evaluations or key in self._fingerprints
            if rejection is None:
                self._note_form(candidate, code)
            if rejection is not None or (evaluated and candidate not in self._screens):
                passed.add(candidate)  # a screened one stays in the ranking (a resume)
                continue
            if candidate in self._screens:  # recorded by an earlier session of the run
                screen = self._screens[candidate]
                self._screen_fingerprints.setdefault(key, (candidate, screen))
                self._count_screen(screen)
            elif key not in self._screen_fingerprints and key not in submitted:
                stopped = self._submission_refused(len(submitted))
                if stopped:
                    break
                submitted.add(key)
                pending[self._submit(candidate, code, settings)] = (candidate, code)
            screened.append((candidate, key))
        codes = {candidate: code for candidate, code, _ in candidates}
        self._started_fits(pending, settings)
        for future in self._finished(pending, settings.fidelity):
            candidate, code = pending[future]
            evaluation = future.result()
            key = fingerprint(code)
            self._screen_fingerprints.setdefault(key, (candidate, evaluation))
            self._captured[key] = evaluation.artifacts.get("captured")
            self._store_screen(candidate, code, evaluation)
        screened = [(c, key) for c, key in screened
                    if c in self._screens or key in self._screen_fingerprints]  # fmt: skip
        for candidate, key in screened:
            if candidate not in self._screens:  # the same code as an earlier candidate
                first, evaluation = self._screen_fingerprints[key]
                copy = Evaluation.from_dict(evaluation.to_dict())
                copy.extras["duplicate_of"] = first
                self._store_screen(candidate, codes[candidate], copy)
        screens = [(key, self._screens[candidate]) for candidate, key in screened]
        rank = self.loop.promote_rank or self.loop.top_k
        bar = kth_best(list(self._screened_losses.values()), rank)
        keys = promoted(screens, self.loop.promote, bar)
        for key, screen in screens:
            if screen.valid:
                self._screened_losses.setdefault(key, screen.loss)
        self._captured = {key: data for key, data in self._captured.items() if key in keys}
        return stopped or self._deadline, passed | {c for c, key in screened if key in keys}

    def _store_screen(self, candidate: str, code: str, evaluation: Evaluation) -> None:
        """Write a finished screen to the run store (its event last: the commit point)."""
        evaluation = self._marked(candidate, evaluation)
        self._screens[candidate] = evaluation
        self.store.save_screen(candidate, code, evaluation)
        self._count_screen(evaluation)
        event = {k: v for k, v in evaluation.to_dict().items() if k != "artifacts"}
        self._emit(ev.CandidateScreened(candidate, self.loop.screen_fidelity, event))

    def _count_screen(self, screen: Evaluation) -> None:
        """Count a screen (not a copy for identical code) as an evaluation."""
        fresh = "duplicate_of" not in screen.extras
        self.totals.evaluations += fresh
        self.totals.screened += fresh

    def _evaluate_all(self, candidates: list[tuple[str, str, Evaluation | None]]) -> str:
        """Evaluate (or look up) every candidate; returns the budget that stopped it, if any.

        ``candidates`` are (id, code, rejection): a rejected one (no code, failed static
        checks) is recorded as it is. The rest are submitted together. Each evaluation is
        stored the moment it finishes (a kill loses none that finished); the heap then takes
        them in the candidates' order, so a run and its resume rank ties alike. A candidate
        whose normalized code was seen before takes that evaluation instead.
        """
        submitted: set[str] = set()  # fingerprints
        pending: dict[Future[Evaluation], tuple[str, str]] = {}  # -> (candidate, code)
        order: list[tuple[str, str, str]] = []
        stopped = ""
        for candidate, code, rejection in candidates:
            key = fingerprint(code)
            known = candidate in self._evaluations or key in self._fingerprints
            if rejection is None:
                self._note_form(candidate, code)
            if rejection is not None:
                if candidate not in self._evaluations:
                    self._store(candidate, code, rejection)
            elif not known and key not in submitted:
                stopped = self._submission_refused(len(submitted))
                if stopped:
                    break
                submitted.add(key)
                captured = self._captured.pop(key, None)
                pending[self._submit(candidate, code, self.settings, captured)] = (candidate, code)
            order.append((candidate, code, key))
        self._started_fits(pending, self.settings)
        for future in self._finished(pending, 1.0):
            self._store(*pending[future], future.result())
        for candidate, code, key in order:
            if candidate not in self._evaluations and key not in self._fingerprints:
                continue  # stopped at the deadline: a resume evaluates it
            if candidate not in self._evaluations:  # the same code as an earlier candidate
                first, evaluation = self._fingerprints[key]
                copy = Evaluation.from_dict(evaluation.to_dict())
                copy.extras["duplicate_of"] = first
                self._store(candidate, code, copy)
            self._push(candidate, code, key, self._evaluations[candidate])
        return stopped or self._deadline

    def _finished(
        self, pending: dict[Future[Evaluation], tuple[str, str]], fidelity: float
    ) -> Iterator[Future[Evaluation]]:
        """``pending``'s futures as they finish. When the wall-time budget runs out first and
        the evaluator can be stopped (``terminate``), the running evaluations are stopped,
        told as :class:`~sga_agent.events.EvaluationsStopped` and never yielded: nothing of
        them is recorded, so a resume evaluates them again; ``_deadline`` then names the
        budget."""
        left = self._seconds_left()
        stop = getattr(self.evaluator, "terminate", None)
        if left is None or stop is None or not pending:
            yield from as_completed(pending)
            return
        finishing = as_completed(pending, timeout=left)
        yielded = set()
        while True:
            try:
                future = next(finishing)
            except StopIteration:
                return
            except TimeoutError:
                break
            yielded.add(future)
            yield future
        done = [future for future in pending if future.done() and future not in yielded]
        running = [candidate for future, (candidate, _) in pending.items() if not future.done()]
        # (running or queued behind the running ones: neither finished)
        stop()
        self._deadline = self.config.budgets.reached("max_seconds")
        self._interrupted += running
        self._emit(ev.EvaluationsStopped(running, fidelity, "the wall-time budget ran out"))
        yield from done

    def _seconds_left(self) -> float | None:
        """Wall seconds left of the run's time budget (None: no time budget), at least 0."""
        limit = self.config.budgets.max_seconds
        if limit is None:
            return None
        self._budget_reached()
        return max(limit - self._kept_for_end - self.totals.seconds, 0.0)

    def _submit(
        self,
        candidate: str,
        code: str,
        settings: EvaluationSettings,
        captured: dict[str, Any] | None = None,
    ) -> Future[Evaluation]:
        """Submit the evaluation of ``candidate``'s ``code`` with ``settings``: fitted again
        from its screen's ``captured`` data where that is at hand, else captured anew; its
        progress notes are shown where the evaluator tells them."""
        extra: dict[str, Any] = {} if captured is None else {"captured": captured}
        if self._reports_progress:
            extra["progress"] = functools.partial(self._progressed, candidate)
        return self.evaluator.submit(self.config.task, code, settings, **extra)

    def _progressed(self, candidate: str, note: FitProgress) -> None:
        """Show a progress note of ``candidate``'s running evaluation (never recorded)."""
        self._show(ev.FitProgressed(candidate, note.to_dict()))

    def _started_fits(
        self, pending: dict[Future[Evaluation], tuple[str, str]], settings: EvaluationSettings
    ) -> None:
        """Show which candidates were just submitted (never recorded), if any were."""
        if pending:
            candidates = [candidate for candidate, _ in pending.values()]
            self._show(ev.FitsStarted(candidates, settings.fidelity))

    def _note_form(self, candidate: str, code: str) -> None:
        """Remember the first candidate of ``code``'s form; a later one of the same form (the
        same law with other constants) is marked ``same_form_as`` it when stored. Only for an
        equation task: an entity's numbers are the entity."""
        if self.task.kind != "equation":
            return
        first = self._forms.setdefault(form_fingerprint(code), candidate)
        if first != candidate:
            self._same_form[candidate] = first

    def _marked(self, candidate: str, evaluation: Evaluation) -> Evaluation:
        """``evaluation`` with what the search knows of its answer in its extras: the slips
        fixed on reading it (``read_as``) and the earlier candidate of its form."""
        extras = dict(evaluation.extras)
        if self._fixes.get(candidate):
            extras["read_as"] = self._fixes[candidate]
        first = self._same_form.get(candidate)
        if first and "duplicate_of" not in extras:
            extras["same_form_as"] = first
        return dataclasses.replace(evaluation, extras=extras)

    def _store(self, candidate: str, code: str, evaluation: Evaluation) -> None:
        """Write a finished evaluation to the run store (its event last: the commit point)."""
        evaluation = self._marked(candidate, evaluation)
        self._evaluations[candidate] = evaluation
        self.store.save_evaluation(candidate, code, evaluation)
        event = {k: v for k, v in evaluation.to_dict().items() if k != "artifacts"}
        self._emit(ev.CandidateEvaluated(candidate, event))

    def _push(self, candidate: str, code: str, key: str, evaluation: Evaluation) -> None:
        """Count the evaluation and push it onto the heap.

        ``key`` is the code's fingerprint: later identical code takes this evaluation.
        """
        self._fingerprints.setdefault(key, (candidate, evaluation))
        self.totals.evaluations += "duplicate_of" not in evaluation.extras
        if evaluation.valid:
            self.totals.valid += 1
        else:
            self.totals.invalid += 1
        self.heap.push(
            candidate, code, evaluation.loss, evaluation.feedback, evaluation.valid,
            evaluation.parameters,
        )  # fmt: skip

    # ------------------------------------------------------------------ bookkeeping

    def _budget_reached(self) -> str:
        """The budget the run has reached ("" if none), the end's share of the time budget
        counted as spent."""
        self.totals.seconds = self._seconds_before + time.monotonic() - self._started
        return self.config.budgets.exceeded(self.totals, kept=self._kept_for_end)

    def _submission_refused(self, submitted: int) -> str:
        """The budget that forbids submitting one more evaluation, with ``submitted`` of this
        batch still running ("" if none): evaluations and wall time only (the answers at
        hand are paid for already)."""
        self._budget_reached()
        spent = dataclasses.replace(self.totals, evaluations=self.totals.evaluations + submitted)
        limits = ("max_evaluations", "max_seconds")
        return self.config.budgets.exceeded(spent, limits, kept=self._kept_for_end)

    def _emit(self, event: ev.Event) -> None:
        """Record ``event``, then show it."""
        self.store.append(event.to_dict())
        self._show(event)

    def _show(self, event: ev.Event) -> None:
        """Show ``event`` (as its dict, with the totals) to ``on_event``."""
        self.on_event({**event.to_dict(), "totals": self.totals})

    def _summary(self, result: SearchResult) -> dict[str, Any]:
        best = result.best
        return {
            "task": self.config.task,
            "stopped": result.stopped,
            "best": None if best is None else best.summary(),
            "top": [entry.summary() for entry in result.top],
            "tokens": result.totals.tokens,
            "cost_usd": result.totals.cost_usd,
            "evaluations": result.totals.evaluations,
            "valid": result.totals.valid,
            "invalid": result.totals.invalid,
            "screened": result.totals.screened,
            "interrupted": result.interrupted,
        }


def _takes_progress(evaluator: Evaluator) -> bool:
    """Whether ``evaluator.submit`` takes a keyword ``progress`` (see :class:`Evaluator`)."""
    try:
        return "progress" in inspect.signature(evaluator.submit).parameters
    except (TypeError, ValueError):  # no signature to read: it is not told
        return False


def slots_of(loop: LoopConfig, iteration: int) -> list[tuple[str, float]]:
    """(candidate id, temperature) of ``iteration``'s answers: its exploit slots, then its
    explore slots (the first iteration's may be its wider opening)."""
    return [
        (f"{iteration:02d}-exploit-{j:02d}", loop.exploit_temperature) for j in range(loop.exploit)
    ] + [
        (f"{iteration:02d}-explore-{j:02d}", loop.explore_temperature)
        for j in range(loop.explore_in(iteration))
    ]


def promoted(screens: list[tuple[str, Evaluation]], share: float, bar: float) -> set[str]:
    """The fingerprints promoted to the full fit among ``screens`` (fingerprint, screen), in
    the candidates' order: the lowest screen losses of the valid ones, ``share`` of their
    distinct fingerprints rounded up (at least one when any is valid; ties go to the earlier),
    less those whose loss is not below ``bar``."""
    ranked: list[tuple[str, float]] = []
    for key, screen in sorted(
        ((key, screen) for key, screen in screens if screen.valid),
        key=lambda item: item[1].loss,  # sorted is stable: ties keep the candidates' order
    ):
        if key not in dict(ranked):
            ranked.append((key, screen.loss))
    return {key for key, loss in ranked[: math.ceil(share * len(ranked))] if loss < bar}


def kth_best(losses: list[float], k: int) -> float:
    """The k-th lowest of ``losses``; infinity while there are fewer than k."""
    return sorted(losses)[k - 1] if len(losses) >= k else math.inf
