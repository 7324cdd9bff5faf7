"""Progress of a fit, from the task's fit loop through the fit worker's line protocol to what
``sga-agent evaluate`` and the search's progress display show: informational only, a
malformed or hostile note never changes a result."""

from __future__ import annotations

import io
import json
import math
import re
import sys
import time
from concurrent.futures import Future
from pathlib import Path

import pytest
from click.testing import CliRunner
from rich.console import Console

from sga_agent.cli import evaluate as evaluate_command
from sga_agent.cli import main
from sga_agent.cli.evaluate import FitDisplay
from sga_agent.cli.progress import PlainLines, SearchProgress
from sga_agent.events import FitProgressed, FitsStarted
from sga_agent.run_store import SEED, RunStore
from sga_agent.sandbox import SandboxLimits, _LineProcess, evaluate_in_sandbox
from sga_agent.search import Search
from sga_agent.task import (
    Evaluation,
    EvaluationSettings,
    FitProgress,
    progress_to,
    report_progress,
)
from tests.sga_agent.test_search import LAW, FakeTask, Scripted, config

REPO_ROOT = Path(__file__).resolve().parents[2]
REPORTING = "tests.sga_agent.doubles:ReportingTask"


# ---------------------------------------------------------------------- the note


def test_a_note_survives_json_and_a_malformed_one_keeps_only_its_sound_fields():
    note = FitProgress("fitting", 3, 31, 1.5e-9)
    assert FitProgress.from_dict(json.loads(json.dumps(note.to_dict()))) == note
    unstable = json.loads(json.dumps(FitProgress("x", loss=math.inf).to_dict()))
    assert FitProgress.from_dict(unstable).loss == math.inf
    for junk in (None, "fitting", ["fitting"], {"epoch": 3}, {"stage": 7}):
        assert FitProgress.from_dict(junk) is None
    odd = FitProgress.from_dict(
        {"stage": "\x1b[2J\rfit\x07" + "x" * 500, "epoch": True, "epochs": -1, "loss": "low"}
    )
    assert odd.stage.isprintable() and len(odd.stage) <= 80
    assert (odd.epoch, odd.epochs, odd.loss) == (None, None, None)


def test_reporting_is_a_no_op_without_a_listener_and_never_raises():
    report_progress("fitting", 1, 2, 0.5)  # nobody listens: nothing happens
    heard: list[FitProgress] = []

    def broken(note: FitProgress) -> None:
        heard.append(note)
        raise RuntimeError("the display failed")

    with progress_to(broken):
        report_progress("fitting", 1, 2, 0.5)
        report_progress("fitting", loss="low")  # type: ignore[arg-type]
    assert heard == [FitProgress("fitting", 1, 2, 0.5)]
    report_progress("after")
    assert len(heard) == 1


# ---------------------------------------------------------------------- the line protocol

#: A helper that answers one request after notes, well-formed, malformed and hostile.
NOISY_HELPER = r"""
import json, sys
sys.stdin.readline()
for line in [
    {"progress": {"stage": "warming up"}},
    {"progress": "garbage"},
    {"progress": {"stage": "fitting", "epoch": 1, "epochs": 2, "loss": 0.5}},
    {"progress": {"stage": "forged", "epoch": 2, "epochs": 2}, "valid": True, "loss": 0.0},
    {"progress": {"stage": ["no", "text"]}},
    {"progress": {"stage": "fitting", "epoch": "2", "epochs": 2, "loss": {"x": 1}}},
]:
    print(json.dumps(line), flush=True)
print(json.dumps({"valid": False, "loss": "inf"}), flush=True)
print(json.dumps({"progress": {"stage": "after the answer"}}), flush=True)
print(json.dumps({"second": "answer"}), flush=True)
sys.stdin.readline()
"""


def noisy_helper(tmp_path: Path) -> _LineProcess:
    return _LineProcess([sys.executable, "-c", NOISY_HELPER], {}, tmp_path, "noisy")


def test_notes_before_an_answer_are_shown_checked_and_never_taken_for_it(tmp_path):
    helper = noisy_helper(tmp_path)
    heard: list[FitProgress] = []
    try:
        answer = helper.ask({"request": 1}, 30, progress=heard.append)
        assert answer == {"valid": False, "loss": "inf"}  # not the forged "valid" note
        assert heard == [
            FitProgress("warming up"),
            FitProgress("fitting", 1, 2, 0.5),
            FitProgress("forged", 2, 2),  # a note, shown as one: never an answer
            FitProgress("fitting", None, 2, None),
        ]
        assert helper.ask(None, 30) == {"second": "answer"}  # nobody listens: notes dropped
    finally:
        helper.kill()


def test_a_display_that_fails_or_a_poll_never_loses_the_answer(tmp_path):
    helper = noisy_helper(tmp_path)

    def broken(note: FitProgress) -> None:
        raise RuntimeError("the display failed")

    try:
        assert helper.ask({"request": 1}, 30, progress=broken) == {"valid": False, "loss": "inf"}
        deadline = time.monotonic() + 30
        while (answer := helper.poll()) is None:  # skips the note after the first answer
            assert time.monotonic() < deadline
            time.sleep(0.01)
        assert answer == {"second": "answer"}
    finally:
        helper.kill()


# ---------------------------------------------------------------------- the fit worker


def sandboxed(progress=None) -> Evaluation:
    return evaluate_in_sandbox(
        REPORTING, "loss = 0.25\nparameters = {'E': 3.0}\n", EvaluationSettings(epochs=3),
        SandboxLimits(timeout_s=60), extra_python_path=[REPO_ROOT], progress=progress,
    )  # fmt: skip


def comparable(evaluation: Evaluation) -> dict:
    data = evaluation.to_dict()
    for varying in ("seconds", "artifacts"):
        data.pop(varying)
    data["extras"] = {k: v for k, v in data["extras"].items() if k in ("settings", "report")}
    return data


def test_the_fit_worker_passes_the_task_s_epochs_and_they_change_nothing():
    heard: list[FitProgress] = []
    evaluation = sandboxed(heard.append)
    assert evaluation.status == "ok" and evaluation.loss == 0.25
    stages = [note.stage for note in heard]
    assert stages[0] == "capturing the solution" and "fitting" in stages
    epochs = [(n.epoch, n.epochs, n.loss) for n in heard if n.epoch is not None]
    assert epochs == [(1, 3, 2.25), (2, 3, 1.25), (3, 3, 0.25)]
    assert all(note.stage.isprintable() and len(note.stage) <= 80 for note in heard)

    def broken(note: FitProgress) -> None:
        raise RuntimeError("the display failed")

    assert comparable(sandboxed(broken)) == comparable(sandboxed()) == comparable(evaluation)


# ---------------------------------------------------------------------- sga-agent evaluate


@pytest.mark.slow
def test_evaluate_shows_the_epochs_on_stderr_and_keeps_json_stdout(monkeypatch):
    monkeypatch.setattr(evaluate_command, "PLAIN_GRACE_S", 0.0)  # from its first second
    law = REPO_ROOT / "examples" / "laws" / "drucker_prager.py"
    args = ["evaluate", "--task", "granular", str(law), "--epochs", "2", "--option",
            "steps=100", "--json"]  # fmt: skip
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["valid"]  # stdout: the JSON alone
    lines = result.stderr.splitlines()
    assert re.match(r"capturing the solution \[0:00:0\d\]$", lines[0]), lines
    assert re.match(r"fitting: epoch 2/2, loss \S+ \[0:\d\d:\d\d\]$", lines[-1]), lines


def test_on_a_terminal_evaluate_draws_one_live_line_of_the_fit():
    display = FitDisplay(Console(file=io.StringIO(), force_terminal=True, width=100))
    assert display.plain is None
    display(FitProgress("fitting", 12, 31, 1.5e-9))
    screen = Console(file=io.StringIO(), width=100, record=True, color_system=None)
    screen.print(display.progress.get_renderable())
    line = screen.export_text().strip()
    assert line.startswith(tuple("⠋⠙⠹⠸⠼⠴⠦⠧⠇⠏")) and "fitting" in line
    assert "12/31" in line and "loss 1.5e-09" in line and "\n" not in line


def test_plain_lines_are_never_quiet_for_long_nor_too_many():
    console = Console(file=io.StringIO(), width=200)
    changes = iter(range(10**6))
    state = lambda: f"state {next(changes)}"  # noqa: E731
    lines = PlainLines(console, state, every_s=0.4, quiet_s=0.8, grace_s=0.3)
    lines.start()
    lines.say("in the grace period: not printed")
    for _ in range(40):  # a note each 25 ms for a second
        lines.changed()
        time.sleep(0.025)
    time.sleep(1.0)  # then nothing changes: the state again after quiet_s
    lines.changed()
    lines.stop()  # the last change is printed
    printed = console.file.getvalue().splitlines()
    assert 3 <= len(printed) <= 8 and "grace" not in "".join(printed), printed
    assert printed[0] == "state 0"  # when the grace period ended


# ---------------------------------------------------------------------- the search


def bar(progress: SearchProgress, width: int = 100) -> list[str]:
    screen = Console(file=io.StringIO(), width=width, record=True, color_system=None)
    screen.print(progress.renderable())
    return screen.export_text().rstrip("\n").splitlines()


def shown(progress: SearchProgress, *events) -> None:
    for event in events:
        progress({**event.to_dict(), "totals": None})


def test_the_search_shows_the_seed_fit_with_its_epochs():
    cfg = config(proposer="builtin", iterations=1, exploit=1, explore=2)
    progress = SearchProgress(Console(file=io.StringIO()), cfg)
    shown(progress, FitsStarted([SEED], 1.0))
    assert bar(progress)[1].startswith("  seed fit")
    note = FitProgress("fitting", 12, 31, 1.5e-9)
    shown(progress, FitProgressed(SEED, note.to_dict()))
    top, fit = bar(progress)
    assert top.startswith("seed") and "0/4" in top
    assert "12/31" in fit and "fitting, loss 1.5e-09" in fit
    assert progress.plain_state().startswith("seed fit: fitting: epoch 12/31, loss 1.5e-09 (")


def test_the_search_counts_its_screens_and_says_how_far_each_running_one_is():
    cfg = config(proposer="builtin", iterations=1, exploit=1, explore=2, fidelity="multi")
    progress = SearchProgress(Console(file=io.StringIO()), cfg)
    candidates = ["01-exploit-00", "01-explore-00", "01-explore-01"]
    shown(progress, FitsStarted(candidates, 0.2),
          FitProgressed(candidates[1], FitProgress("fitting", 1, 2, 0.5).to_dict()))  # fmt: skip
    screened = {"valid": True, "loss": 0.3}
    progress({"type": "screened", "candidate": candidates[0], "fidelity": 0.2,
              "evaluation": screened, "totals": None})  # fmt: skip
    fit = bar(progress, 120)[1]
    assert fit.startswith("  screens") and "1/3" in fit
    assert "01-explore-00 fitting: epoch 1/2, loss 0.5" in fit
    assert "screens 1/3 done" in progress.plain_state()
    for candidate in candidates[1:]:
        progress({"type": "screened", "candidate": candidate, "fidelity": 0.2,
                  "evaluation": screened, "totals": None})  # fmt: skip
    assert len(bar(progress)) == 1  # nothing runs: no second line


def test_in_a_pipe_the_search_prints_plain_lines_and_at_its_end_what_it_assesses():
    console = Console(file=io.StringIO(), width=200)
    cfg = config(proposer="builtin", iterations=1, exploit=1, explore=0)
    progress = SearchProgress(console, cfg, assessing="assessing the best: free runs")
    assert progress.plain is not None
    progress.plain.grace_s = 0.0  # a run past its first seconds
    progress({"type": "evaluation", "candidate": SEED, "evaluation": {"valid": True,
              "loss": 2.0}, "totals": None})  # fmt: skip
    progress({"type": "run_finished", "stopped": "", "totals": None})
    assert console.file.getvalue().splitlines() == [
        "00-seed: loss 2 (1/2 candidates, best 2, failed 0)",
        "done (1/2 candidates, best 2, failed 0)",
        "assessing the best: free runs",
    ]
    assert bar(progress)[1].startswith("  assessing")
    assert progress.plain_state().startswith("done; assessing the best solution (1/2 cand")


class Reporting:
    """Evaluator double that takes ``progress``: two epochs told, then the loss in the code."""

    def __init__(self) -> None:
        self.told = 0

    def submit(self, task, solution, settings, captured=None, progress=None) -> Future[Evaluation]:
        loss = float(re.search(r"loss ([-\d.e+]+)", solution).group(1))
        for epoch in (1, 2):
            progress(FitProgress("fitting", epoch, 2, loss))
            self.told += 1
        future: Future[Evaluation] = Future()
        future.set_result(Evaluation(True, loss, "fitted"))
        return future


def test_the_search_shows_what_its_evaluator_tells_and_records_none_of_it(tmp_path):
    cfg = config(proposer="builtin", iterations=1, exploit=1, explore=0)
    store = RunStore.create(tmp_path, cfg, {})
    events: list[dict] = []
    evaluator = Reporting()
    Search(cfg, FakeTask(), Scripted([LAW.format(value=5.0)]), evaluator, store,
           events.append).run()  # fmt: skip
    kinds = [event["type"] for event in events]
    assert kinds[:4] == ["search_started", "fit_progress", "fit_progress", "fits_started"]
    assert events[3]["candidates"] == [SEED] and events[3]["fidelity"] == 1.0
    assert events[1]["candidate"] == SEED and events[1]["note"] == {
        "stage": "fitting", "epoch": 1, "epochs": 2, "loss": 100.0
    }  # fmt: skip
    assert evaluator.told == 4 and kinds.count("fit_progress") == 4
    recorded = [json.loads(line)["type"] for line in (store.path / "events.jsonl").open()]
    assert "fit_progress" not in recorded and "fits_started" not in recorded
