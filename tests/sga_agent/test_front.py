"""The report's loss-versus-size front (sga_agent.report.front)."""

from __future__ import annotations

import math

import pytest
from click.testing import CliRunner

from sga_agent.cli import main
from sga_agent.report.data import Candidate
from sga_agent.report.front import front
from tests.sga_agent.test_report import run_through_the_runner
from tests.sga_agent.test_search import FakeTask


def solutions(*pairs: tuple[int, float]) -> list[tuple[Candidate, int]]:
    return [(Candidate(f"c{i}", "ok", loss), size) for i, (size, loss) in enumerate(pairs)]


def test_the_front_keeps_each_size_s_best_when_it_beats_every_smaller_one():
    members = front(solutions((5, 1e-3), (3, 1e-2), (5, 1e-4), (8, 2e-4), (9, 1e-6), (3, 5e-2)))
    assert [(m.size, m.candidate.loss) for m in members] == [(3, 1e-2), (5, 1e-4), (9, 1e-6)]
    assert members[0].score is None
    assert members[1].score == pytest.approx(math.log(100) / 2)  # two units for two decades
    assert members[2].score == pytest.approx(math.log(100) / 4)


class SizedTask(FakeTask):
    """The fake task, its solutions sized by the loss written in them (larger laws fit
    better; two of size 6)."""

    size_label = "units of the fake"
    SIZES = {100.0: 1, 7.0: 3, 5.0: 4, 4.0: 6, 3.0: 6, 2.0: 8, 1.0: 9}

    def solution_size(self, candidate):
        return self.SIZES[candidate.loss]


def test_a_task_with_sizes_gets_the_front_in_its_report(tmp_path, monkeypatch):
    from sga_agent.task import as_task

    store, _ = run_through_the_runner(tmp_path, monkeypatch, SizedTask(),
                                      (5.0, 3.0, 7.0, 1.0, 2.0, 4.0))  # fmt: skip
    monkeypatch.setattr("sga_agent.report.build.load_or_none", lambda name: as_task(SizedTask()))
    result = CliRunner().invoke(main, ["report", str(store.path), "--no-motion"])
    assert result.exit_code == 0, result.output
    md = (store.path / "report" / "report.md").read_text()
    section = md.split("## Loss against size")[1].split("\n## ")[0]
    assert "(units of the fake)" in section and "![loss against size](front.png)" in section
    rows = [line for line in section.splitlines() if line.startswith("| ") and "---" not in line]
    scores = [math.log(100 / 7) / 2, math.log(7 / 5), math.log(5 / 3) / 2, math.log(3 / 2) / 2,
              math.log(2)]  # fmt: skip
    assert [row.split(" | ")[:3] for row in rows[1:]] == [
        ["| 1", "100", ""], *([f"| {size}", loss, f"{score:.3g}"] for size, loss, score in zip(
            (3, 4, 6, 8, 9), ("7", "5", "3", "2", "1"), scores, strict=True))]
    assert (store.path / "report" / "front.png").stat().st_size > 0
