"""The discovery benchmark's rows: each true law is a valid answer of its task, started where the
row says, with an observed row's known elastic law written in; and the table of the rows measured
on a commit and its descendants."""

import json
import re
import subprocess

import pytest
import torch

from sga_agent.parsing import check_candidate
from sga_agent.registry import load_task
from tasks.constitutive.law_code import load_law
from tests.benchmarks.scripts import load_benchmark

discovery = load_benchmark("discovery")


@pytest.mark.parametrize("name", list(discovery.ROWS))
def test_every_row_s_true_law_is_an_answer_started_at_the_row_s_values(name):
    row = discovery.ROWS[name]
    code = discovery.truth_code(row)
    check_candidate(code, load_task(row.task))
    law = load_law(code, torch.float64)
    for argument, value in row.start.items():
        assert getattr(law, argument).item() == pytest.approx(value)
    if row.elastic is not None and "E, NU" in code:
        E, nu = row.elastic
        assert re.search(rf"E, NU = {E!r}, {nu!r}", code)


def test_the_cohesive_row_observes_a_sand_with_cohesion_and_starts_at_twice_its_constants():
    row = discovery.ROWS["observed-cohesive"]
    assert row.observation[:2] == ("--material", "sand") and "cohesion=0.02" in row.observation
    assert row.start["cohesion"] == pytest.approx(2 * 0.02)


def _git(repo, *arguments) -> str:
    done = subprocess.run(["git", "-C", str(repo), "-c", "user.name=t", "-c", "user.email=t@t",
                           *arguments], capture_output=True, text=True, check=True)  # fmt: skip
    return done.stdout.strip()


def _result(commit: str) -> str:
    return json.dumps({
        "row": "granular", "seed": 0, "label": "current", "commit": commit, "best": 1e-11,
        "seed_loss": 1e-6, "truth": 1.1e-11, "fitted_truth": 1e-9, "held_out": 2e-4,
        "fitted_truth_held_out": 2.7e-3, "evaluations": 60, "seconds": 120.0, "load": [1.0, 1.5],
    })  # fmt: skip


def test_the_table_since_a_commit_keeps_its_rows_and_its_descendants_and_no_unknown_one(tmp_path):
    repo = tmp_path / "repo"
    repo.mkdir()
    _git(repo, "init", "-q")
    commits = []
    for n in (1, 2):
        (repo / "file").write_text(str(n))
        _git(repo, "add", "file")
        _git(repo, "commit", "-q", "-m", f"commit {n}")
        commits.append(_git(repo, "rev-parse", "--short=7", "HEAD"))
    first, second = commits
    unknown = next(c for c in ("1234567", "abcdef0") if not any(k.startswith(c) for k in commits))
    results = tmp_path / "discovery.jsonl"
    rows = [first, f"{first}-dirty", second, f"{second}-dirty", unknown, "unknown"]
    results.write_text("\n".join(_result(commit) for commit in rows) + "\n")

    def shown(**since) -> list[str]:
        lines = discovery.table(results, repo=repo, **since).splitlines()[2:]
        return [line.split(" | ")[3] for line in lines]

    assert shown() == rows
    assert shown(since=first) == rows[:4]
    assert shown(since=second) == [second, f"{second}-dirty"]
    assert shown(since=_git(repo, "rev-parse", "HEAD")) == [second, f"{second}-dirty"]
    with pytest.raises(ValueError, match="not a commit"):
        discovery.table(results, repo=repo, since=unknown)
