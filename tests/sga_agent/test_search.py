"""The search loop with test doubles for the model and the evaluator (no Taichi, no sandbox).

The doubles: a scripted proposer, and an evaluator whose loss is the number a law's code
returns, so the ranking is known in advance.
"""

from __future__ import annotations

import contextlib
import json
import re
import threading
import time
from concurrent.futures import Future, InvalidStateError
from dataclasses import dataclass

import pytest

from sga_agent.config import ConfigError, SearchConfig
from sga_agent.proposers.base import Proposal, ProposalRequest, ProposerError
from sga_agent.proposers.builtin import BuiltinAdapter
from sga_agent.proposers.replay import ReplayProposer
from sga_agent.run_store import RunStore
from sga_agent.search import Search, slots_of
from sga_agent.task import Evaluation, Parent, PromptParts

LAW = """```python
import torch
import torch.nn as nn


class Physics(nn.Module):
    label = "a law of its own form: loss {value}"

    def __init__(self, scale: float = 1.0):
        super().__init__()
        self.scale = nn.Parameter(torch.tensor(scale))

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        return F * {value}
```"""


class FakeTask:
    name = "fake"
    description = "a task whose loss is written in the code"
    kind = "equation"

    def seed_solution(self) -> str:
        return LAW.format(value=100.0).strip("`").removeprefix("python\n")

    def prompt_parts(self) -> PromptParts:
        return PromptParts("a tester", "find a small number", "class Physics: ...", "rules")


class LossInCode:
    """Evaluator double: the loss is the number after 'loss' in the code; counts calls."""

    def __init__(self) -> None:
        self.calls: list[str] = []

    def submit(self, task, solution, settings) -> Future[Evaluation]:
        self.calls.append(solution)
        future: Future[Evaluation] = Future()
        loss = float(re.search(r"loss ([-\d.e+]+)", solution).group(1))
        future.set_result(Evaluation(True, loss, f"feedback for loss {loss}"))
        return future


class Scripted:
    """Proposer double: answers from a list, in order, having read the prompt as a model
    would; records temperatures."""

    name = "scripted"

    def __init__(self, answers: list[str]) -> None:
        self.answers = list(answers)
        self.temperatures: list[float] = []

    def propose(self, request: ProposalRequest) -> list[Proposal]:
        assert request.messages()[-1]["role"] == "user"
        n, temperature = request.n, request.temperature
        self.temperatures += [temperature] * n
        if not self.answers:
            raise ProposerError("no more scripted answers")
        taken, self.answers = self.answers[:n], self.answers[n:]
        return [Proposal(text, "scripted", temperature, 10, 5, 0.001) for text in taken]


def config(**overrides) -> SearchConfig:
    values = {"task": "fake", "proposer": "scripted", "iterations": 2, "top_k": 2,
              "exploit": 1, "explore": 2, "workers": 1}  # fmt: skip
    values.update(overrides)
    return SearchConfig.from_settings(**values)


def run(tmp_path, answers, **overrides):
    cfg = config(**overrides)
    store = RunStore.create(tmp_path, cfg, {})
    evaluator = LossInCode()
    proposer = Scripted(answers)
    result = Search(cfg, FakeTask(), proposer, evaluator, store).run()
    return result, store, evaluator, proposer


def test_algorithm_ranks_dedupes_and_records(tmp_path):
    answers = [LAW.format(value=v) for v in (5.0, 3.0, 5.0)] + [
        "no code here",
        "```python\nimport os\nos.system('ls')\n```",
        LAW.format(value=1.0),
    ]
    result, store, evaluator, proposer = run(tmp_path, answers)
    assert proposer.temperatures == [0.5, 1.0, 1.0, 0.5, 1.0, 1.0]
    assert [round(e.loss, 3) for e in result.top] == [1.0, 3.0]
    assert result.best.candidate == "02-explore-01"
    # 100 (seed), 5, 3, 1 evaluated; the second 5.0 is a duplicate: not evaluated again
    assert len(evaluator.calls) == 4
    duplicate = json.loads((store.path / "candidates/01-explore-01/evaluation.json").read_text())
    assert duplicate["extras"]["duplicate_of"] == "01-exploit-00"
    rejected = json.loads((store.path / "candidates/02-exploit-00/evaluation.json").read_text())
    assert rejected["status"] == "invalid" and "code block" in rejected["reason"]
    hostile = json.loads((store.path / "candidates/02-explore-00/evaluation.json").read_text())
    assert hostile["status"] == "invalid" and "os" in hostile["reason"]
    for name in ("messages.json", "response.txt", "proposal.json", "code.py", "feedback.txt"):
        assert (store.path / "candidates/01-exploit-00" / name).is_file()
    assert (store.path / "heap/iteration-02.json").is_file()
    summary = json.loads((store.path / "summary.json").read_text())
    assert summary["best"]["candidate"] == "02-explore-01"
    assert result.totals.tokens == 6 * 15 and result.totals.cost_usd == pytest.approx(0.006)


def test_prompt_shows_top_k_worst_first(tmp_path):
    answers = [LAW.format(value=v) for v in (5.0, 3.0, 7.0, 1.0, 2.0, 4.0)]
    result, store, *_ = run(tmp_path, answers)
    messages = json.loads((store.path / "candidates/02-exploit-00/messages.json").read_text())
    user = messages[-1]["content"]
    assert user.index("loss 5.0") < user.index("loss 3.0")  # worst first, best last
    assert "loss 7.0" not in user and "loss 100.0" not in user  # only the top 2


def test_budget_stops_cleanly(tmp_path):
    answers = [LAW.format(value=v) for v in range(10, 20)]
    result, store, evaluator, _ = run(tmp_path, answers, max_evaluations=3)
    assert result.stopped == "max_evaluations=3 reached"
    assert len(evaluator.calls) == 3
    assert json.loads((store.path / "summary.json").read_text())["stopped"] == result.stopped


class SlowLossInCode(LossInCode):
    """LossInCode whose every evaluation takes ``seconds`` of wall time (at submission)."""

    def __init__(self, seconds: float) -> None:
        super().__init__()
        self.seconds = seconds

    def submit(self, task, solution, settings) -> Future[Evaluation]:
        time.sleep(self.seconds)
        return super().submit(task, solution, settings)


def test_time_budget_starts_no_evaluation_after_it(tmp_path):
    answers = [LAW.format(value=v) for v in range(10, 20)]
    run(tmp_path / "warm", answers[:3], iterations=1)  # imports, so that the budget is the wait
    cfg = config(max_seconds=0.6)
    store = RunStore.create(tmp_path, cfg, {})
    evaluator = SlowLossInCode(0.4)
    result = Search(cfg, FakeTask(), Scripted(answers), evaluator, store).run()
    # the seed ends at 0.4 s; the first offspring starts before 0.6 s, the next one would not
    assert result.stopped == "max_seconds=0.6 reached"
    assert len(evaluator.calls) == 2
    assert result.totals.seconds >= 0.6
    assert json.loads((store.path / "summary.json").read_text())["stopped"] == result.stopped


def test_a_resumed_run_counts_the_time_its_earlier_sessions_took(tmp_path):
    store = RunStore.create(tmp_path, config(), {})
    sessions = [(1000.0, "search_started"), (1100.0, "iteration_started"),
                (2000.0, "search_started"), (2050.0, "iteration_started")]  # fmt: skip
    with open(store.path / "events.jsonl", "a") as log:
        for moment, kind in sessions:
            log.write(json.dumps({"time": moment, "type": kind}) + "\n")
    assert store.recorded().seconds == 150.0
    cfg = config(max_seconds=120)
    result = Search(cfg, FakeTask(), Scripted([]), LossInCode(), store).run()
    assert result.stopped == "max_seconds=120 reached"  # only the seed was evaluated


def test_the_time_before_the_search_counts_in_its_budget_and_its_record(tmp_path):
    """A session given the instant its program started (``started``) counts the start-up:
    in the budget, in the run's seconds and in what a resume reads back."""
    cfg = config(max_seconds=120)
    store = RunStore.create(tmp_path, cfg, {})
    started = time.monotonic() - 130.0  # a start-up longer than the budget
    result = Search(cfg, FakeTask(), Scripted([]), LossInCode(), store, started=started).run()
    assert result.stopped == "max_seconds=120 reached"  # only the seed was evaluated
    assert result.totals.seconds >= 130.0
    events = [json.loads(line) for line in (store.path / "events.jsonl").read_text().splitlines()]
    (begun,) = [event for event in events if event["type"] == "search_started"]
    assert begun["start_up"] >= 130.0
    assert store.recorded().seconds == pytest.approx(result.totals.seconds, abs=0.5)


def test_resume_reuses_answers_and_evaluations(tmp_path):
    answers = [LAW.format(value=v) for v in (5.0, 3.0, 7.0, 1.0, 2.0, 4.0)]
    full, full_store, *_ = run(tmp_path / "full", answers)
    # a run killed after the fourth evaluation event: cut its log there
    cfg = config()
    store = RunStore.create(tmp_path / "killed", cfg, {})
    lines = (full_store.path / "events.jsonl").read_text().splitlines()
    evaluations = [i for i, line in enumerate(lines) if '"type": "evaluation"' in line]
    kept = lines[1 : evaluations[3] + 1]
    with open(store.path / "events.jsonl", "a") as log:
        log.write("\n".join(kept) + "\n" + '{"type": "evaluation", "cand')  # torn last line
    evaluator = LossInCode()
    proposer = Scripted(answers[3:])  # only the second iteration is asked again
    resumed = Search(cfg, FakeTask(), proposer, evaluator, store).run()
    assert [(e.candidate, e.loss) for e in resumed.heap.top(10)] == [
        (e.candidate, e.loss) for e in full.heap.top(10)
    ]
    assert len(evaluator.calls) == 3  # only the answers of iteration 2
    # the torn line stays alone: every event written after it is read back
    torn, *after = (store.path / "events.jsonl").read_text().splitlines()[len(kept) + 1 :]
    assert torn == '{"type": "evaluation", "cand'
    assert len(store.events()) == 1 + len(kept) + len(after)
    assert store.recorded().finished


class FinishesBackwards(LossInCode):
    """Evaluator double whose evaluations finish last-submitted first: an evaluation is only
    finished once the one submitted after it is in the run store."""

    def __init__(self, store: RunStore, batches: list[int]) -> None:
        super().__init__()
        self.store, self.batches, self.pending = store, list(batches), []

    def submit(self, task, solution, settings) -> Future[Evaluation]:
        finished = super().submit(task, solution, settings)
        future: Future[Evaluation] = Future()
        self.pending.append((future, finished.result()))
        if len(self.pending) == self.batches[0]:
            self.batches.pop(0)
            threading.Thread(target=self._finish_backwards, daemon=True).start()
        return future

    def _finish_backwards(self) -> None:
        pending, self.pending = self.pending, []
        for future, evaluation in reversed(pending):
            stored = len(self._stored())
            future.set_result(evaluation)
            deadline = time.time() + 10
            while len(self._stored()) == stored and time.time() < deadline:
                time.sleep(0.01)

    def _stored(self) -> list[str]:
        return [e["candidate"] for e in self.store.events() if e["type"] == "evaluation"]


def test_each_evaluation_is_stored_when_it_finishes(tmp_path):
    """A kill while one evaluation runs loses none of those that finished after it started."""
    answers = [LAW.format(value=v) for v in (5.0, 3.0, 7.0)]
    cfg = config(iterations=1)
    store = RunStore.create(tmp_path, cfg, {})
    evaluator = FinishesBackwards(store, batches=[1, 3])  # the seed, then iteration 1
    proposer = Scripted(answers)
    search = Search(cfg, FakeTask(), proposer, evaluator, store)
    search.run()
    stored = [e["candidate"] for e in store.events() if e["type"] == "evaluation"]
    assert stored == ["00-seed", "01-explore-01", "01-explore-00", "01-exploit-00"]
    heap = [entry.candidate for entry in search.heap.top(10)]
    assert heap == ["01-explore-00", "01-exploit-00", "01-explore-01", "00-seed"]


def test_replay_needs_no_model(tmp_path):
    answers = [LAW.format(value=v) for v in (5.0, 3.0, 7.0, 1.0, 2.0, 4.0)]
    full, full_store, *_ = run(tmp_path / "full", answers)
    cfg = config(proposer=f"replay:{full_store.path}")
    store = RunStore.create(tmp_path / "replay", cfg, {})
    replay = Search(cfg, FakeTask(), ReplayProposer(full_store.path), LossInCode(), store).run()
    assert [(e.candidate, e.loss) for e in replay.heap.top(10)] == [
        (e.candidate, e.loss) for e in full.heap.top(10)
    ]
    assert replay.totals.tokens == full.totals.tokens and store.recorded().finished
    # the replayed answers are this run's own now: it resumes without the recorded run
    assert store.recorded().proposals == full_store.recorded().proposals
    assert not (store.path / "candidates/01-exploit-00/messages.json").exists()


def test_a_replay_recorded_before_replayed_answers_were_stored_resumes(tmp_path):
    """An older replayed run logged evaluations but no proposals: its resume asks the replayed
    run again and evaluates only what was not finished."""
    answers = [LAW.format(value=v) for v in (5.0, 3.0, 7.0, 1.0, 2.0, 4.0)]
    full, full_store, *_ = run(tmp_path / "full", answers)
    cfg = config(proposer=f"replay:{full_store.path}")
    store = RunStore.create(tmp_path / "replay", cfg, {})
    for event in full_store.events():
        if event["type"] == "evaluation" and event["candidate"] < "02":
            store.append({k: v for k, v in event.items() if k != "time"})
    evaluator = LossInCode()
    resumed = Search(cfg, FakeTask(), ReplayProposer(full_store.path), evaluator, store).run()
    assert len(evaluator.calls) == 3  # iteration 2's three answers
    assert [(e.candidate, e.loss) for e in resumed.heap.top(10)] == [
        (e.candidate, e.loss) for e in full.heap.top(10)
    ]


def test_a_replay_without_an_answer_records_the_slots_as_missing_and_goes_on(tmp_path):
    answers = [LAW.format(value=v) for v in (5.0, 3.0, 7.0)]
    short, short_store, *_ = run(tmp_path / "short", answers, iterations=1)
    cfg = config(proposer=f"replay:{short_store.path}")  # two iterations
    store = RunStore.create(tmp_path / "replay", cfg, {})
    replay = Search(cfg, FakeTask(), ReplayProposer(short_store.path), LossInCode(), store).run()
    assert replay.best.loss == 3.0
    assert not [e for e in store.events() if e["type"] == "proposer_error"]
    missing = [e["candidate"] for e in store.events() if e["type"] == "proposal_missing"]
    assert missing == ["02-exploit-00", "02-explore-00", "02-explore-01"]


class Halving:
    """A task's built-in proposer double: halves the best parent's number; never reads a prompt."""

    name = "builtin:halving"

    def __init__(self) -> None:
        self.calls: list[tuple[list[Parent], float, int, int]] = []

    def propose_from(self, parents, temperature, n, seed):
        self.calls.append((list(parents), temperature, n, seed))
        best = float(re.search(r"loss ([-\d.e+]+)", parents[-1].code).group(1))
        return [LAW.format(value=best / (2 + i)) for i in range(n + 1)]  # one too many


def test_a_builtin_proposer_gets_the_parents_and_no_prompt_is_built(tmp_path, monkeypatch):
    import sga_agent.search

    def no_prompt(*args):
        raise AssertionError("a prompt was built for a proposer that does not read it")

    monkeypatch.setattr(sga_agent.search, "fit_to_budget", no_prompt)
    cfg = config(iterations=1)
    store = RunStore.create(tmp_path, cfg, {})
    builtin = Halving()
    adapter = BuiltinAdapter(builtin)
    assert adapter.name == "builtin:halving"
    result = Search(cfg, FakeTask(), adapter, LossInCode(), store).run()
    assert [call[1:3] for call in builtin.calls] == [(0.5, 1), (1.0, 2)]
    assert builtin.calls[0][0][-1].loss == 100.0  # the seed, the only parent
    assert len({call[3] for call in builtin.calls}) == 2  # a seed per batch
    assert result.best.loss == 100.0 / 3
    assert not list(store.path.glob("candidates/*/messages.json"))
    proposal = json.loads((store.path / "candidates/01-exploit-00/proposal.json").read_text())
    assert proposal["model"] == "builtin:halving" and proposal["temperature"] == 0.5


class Remembering(Halving):
    """A built-in proposer double that takes the run's earlier answers (``tried=``)."""

    name = "builtin:remembering"

    def __init__(self) -> None:
        super().__init__()
        self.tried: list[list[str]] = []

    def propose_from(self, parents, temperature, n, seed, tried=()):
        self.tried.append(list(tried))
        return super().propose_from(parents, temperature, n, seed)


def test_a_builtin_proposer_that_takes_tried_gets_every_earlier_answer(tmp_path):
    """Oldest first, the current iteration's earlier batch included; a resumed run rebuilds
    them from its store, so it asks with the same list the original did."""
    cfg = config(iterations=2)
    store = RunStore.create(tmp_path / "full", cfg, {})
    builtin = Remembering()
    Search(cfg, FakeTask(), BuiltinAdapter(builtin), LossInCode(), store).run()
    answers = {p.parent.name: p.read_text()
               for p in store.path.glob("candidates/*/response.txt")}  # fmt: skip
    assert [len(t) for t in builtin.tried] == [0, 1, 3, 4]
    assert builtin.tried[-1] == [answers[c] for c in sorted(answers)[:4]]
    # killed before the last batch was asked for: cut the log at its first proposal
    lines = (store.path / "events.jsonl").read_text().splitlines()
    cut = next(i for i, line in enumerate(lines)
               if '"type": "proposal"' in line and '"02-explore-00"' in line)  # fmt: skip
    killed = RunStore.create(tmp_path / "killed", cfg, {})
    with open(killed.path / "events.jsonl", "a") as log:
        log.write("\n".join(lines[1:cut]) + "\n")
    again = Remembering()
    Search(cfg, FakeTask(), BuiltinAdapter(again), LossInCode(), killed).run()
    assert again.tried == [builtin.tried[-1]]


def test_a_builtin_proposer_without_tried_is_called_as_before(tmp_path):
    cfg = config(iterations=2)
    store = RunStore.create(tmp_path, cfg, {})
    Search(cfg, FakeTask(), BuiltinAdapter(Halving()), LossInCode(), store).run()
    assert len(list(store.path.glob("candidates/*/response.txt"))) == 6


class Opening(Halving):
    """A built-in proposer double that is told whether a batch is the search's opening."""

    name = "builtin:opening"

    def __init__(self) -> None:
        super().__init__()
        self.openings: list[tuple[float, int, bool]] = []

    def propose_from(self, parents, temperature, n, seed, opening=False):
        self.openings.append((temperature, n, opening))
        return super().propose_from(parents, temperature, n, seed)


def test_the_opening_is_the_first_iteration_s_wider_explore_batch_and_only_it(tmp_path):
    cfg = config(iterations=2, opening=5)
    assert [len(slots_of(cfg.loop, i)) for i in (1, 2)] == [6, 3]
    assert cfg.loop.candidates == 1 + 6 + 3
    store = RunStore.create(tmp_path, cfg, {})
    builtin = Opening()
    Search(cfg, FakeTask(), BuiltinAdapter(builtin), LossInCode(), store).run()
    assert builtin.openings == [(0.5, 1, False), (1.0, 5, True), (0.5, 1, False), (1.0, 2, False)]
    assert len(list(store.path.glob("candidates/*/response.txt"))) == 9
    # an opening no wider than --explore changes nothing
    assert [len(slots_of(config(opening=2).loop, i)) for i in (1, 2)] == [3, 3]


class RunsUntilStopped(LossInCode):
    """Evaluator double: a law of loss 7 runs until ``terminate``, which ends it invalid as a
    killed pool ends its running evaluations (or for 10 s, then finishes); the others finish
    at once."""

    def __init__(self) -> None:
        super().__init__()
        self.running: list[Future[Evaluation]] = []
        self.terminated = False

    def submit(self, task, solution, settings) -> Future[Evaluation]:
        if "loss 7.0" not in solution:
            return super().submit(task, solution, settings)
        self.calls.append(solution)
        future: Future[Evaluation] = Future()
        self.running.append(future)
        threading.Timer(10.0, self._end, (future, Evaluation(True, 7.0, "finished"))).start()
        return future

    def terminate(self) -> None:
        self.terminated = True
        for future in self.running:
            self._end(future, Evaluation.invalid("the pool was stopped", status="error"))

    @staticmethod
    def _end(future: Future[Evaluation], evaluation: Evaluation) -> None:
        with contextlib.suppress(InvalidStateError):
            future.set_result(evaluation)


def test_the_time_budget_stops_the_evaluations_running_at_it_and_a_resume_evaluates_them(
    tmp_path,
):
    """At the wall-time budget the evaluation still running is stopped (not waited for), told
    as an event and not recorded; those finished are kept; a resume with a larger budget
    evaluates the stopped one."""
    answers = [LAW.format(value=v) for v in (3.0, 7.0, 2.0, 1.5, 1.25, 1.125)]
    run(tmp_path / "warm", answers[:3], iterations=1)  # imports, so that the budget is the wait
    cfg = config(iterations=2, max_seconds=1.0)
    store = RunStore.create(tmp_path, cfg, {})
    evaluator = RunsUntilStopped()
    started = time.monotonic()
    result = Search(cfg, FakeTask(), Scripted(answers), evaluator, store).run()
    assert time.monotonic() - started < 5 and evaluator.terminated
    assert result.stopped == "max_seconds=1.0 reached" and result.interrupted == ["01-explore-00"]
    # spent, with the end's share: the runner then leaves the comparison of forms
    assert result.totals.seconds + cfg.budgets.kept_for_end() >= 1.0
    assert json.loads((store.path / "summary.json").read_text())["interrupted"] == ["01-explore-00"]
    events = [json.loads(line) for line in (store.path / "events.jsonl").read_text().splitlines()]
    stops = [event for event in events if event["type"] == "evaluations_stopped"]
    assert [(e["candidates"], e["fidelity"]) for e in stops] == [(["01-explore-00"], 1.0)]
    assert not (store.path / "candidates/01-explore-00/evaluation.json").exists()
    kept = {e["candidate"]: e["evaluation"]["loss"] for e in events if e["type"] == "evaluation"}
    assert kept == {"00-seed": 100.0, "01-exploit-00": 3.0, "01-explore-01": 2.0}
    assert result.best.loss == 2.0
    # a resume with a larger budget evaluates the stopped candidate, asks for the rest
    again = Search(config(iterations=2, max_seconds=60.0), FakeTask(), Scripted(answers[3:]),
                   LossInCode(), RunStore.open(store.path)).run()  # fmt: skip
    assert again.stopped == "" and again.best.loss == 1.125
    resumed = json.loads((store.path / "candidates/01-explore-00/evaluation.json").read_text())
    assert resumed["loss"] == 7.0


class Failing(Scripted):
    """Proposer double: answers from a list, then fails (transiently or for good)."""

    def __init__(self, answers: list[str], transient: bool) -> None:
        super().__init__(answers)
        self.transient = transient

    def propose(self, request: ProposalRequest) -> list[Proposal]:
        if not self.answers:
            self.temperatures += [request.temperature] * request.n
            raise ProposerError("scripted failure", transient=self.transient)
        return super().propose(request)


def test_a_provider_that_gives_up_mid_run_stops_the_search_after_saving_what_it_evaluated(
    tmp_path,
):
    cfg = config()
    store = RunStore.create(tmp_path, cfg, {})
    proposer = Failing([LAW.format(value=2.0)], transient=True)
    with pytest.raises(ProposerError, match="scripted failure"):
        Search(cfg, FakeTask(), proposer, LossInCode(), store).run()
    (error,) = [event for event in store.events() if event["type"] == "proposer_error"]
    assert error["transient"] is True
    assert sorted(store.recorded().evaluations) == ["00-seed", "01-exploit-00"]
    assert not (store.path / "summary.json").exists()
    resumed = Search(cfg, FakeTask(), Scripted([LAW.format(value=1.0)] * 8), LossInCode(), store)
    assert resumed.run().best.loss == 1.0  # the resume asks again where it stopped


def test_a_hard_proposer_failure_stops_the_search_resumably(tmp_path):
    cfg = config()
    store = RunStore.create(tmp_path, cfg, {})
    proposer = Failing([], transient=False)
    with pytest.raises(ProposerError, match="scripted failure"):
        Search(cfg, FakeTask(), proposer, LossInCode(), store).run()
    assert proposer.temperatures == [0.5]  # the first batch, nothing after it
    (error,) = [event for event in store.events() if event["type"] == "proposer_error"]
    assert error["transient"] is False
    assert not (store.path / "summary.json").exists()
    assert not store.recorded().finished


@dataclass(frozen=True)
class Steps:
    """Options of a task double."""

    steps: int = 1


class FakeTaskWithOptions(FakeTask):
    options_type = Steps


class Recording(LossInCode):
    """Evaluator double that also keeps the settings each candidate was submitted with."""

    def __init__(self) -> None:
        super().__init__()
        self.settings: list = []

    def submit(self, task, solution, settings) -> Future[Evaluation]:
        self.settings.append(settings)
        return super().submit(task, solution, settings)


def test_the_config_s_options_object_is_what_every_evaluation_gets(tmp_path):
    options = Steps(steps=7)
    cfg = config(iterations=1, task_options=options, epochs=3, seed=5)
    store = RunStore.create(tmp_path, cfg, {})
    evaluator = Recording()
    Search(cfg, FakeTaskWithOptions(), Scripted([LAW.format(value=1.0)] * 3), evaluator,
           store).run()  # fmt: skip
    assert evaluator.settings and all(s.options is options for s in evaluator.settings)
    assert {(s.epochs, s.seed) for s in evaluator.settings} == {(3, 5)}
    no_fit = config(bilevel=False, epochs=3, task_options=options).evaluation_settings()
    assert no_fit.epochs == 0 and no_fit.options is options


def test_options_of_another_type_than_the_task_s_are_refused(tmp_path):
    cfg = config()  # NoOptions: a task without options
    store = RunStore.create(tmp_path, cfg, {})
    with pytest.raises(ConfigError, match="task 'fake' takes options of type Steps"):
        Search(cfg, FakeTaskWithOptions(), Scripted([]), LossInCode(), store)
