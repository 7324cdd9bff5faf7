"""The report's table of every candidate, over a run folder written by hand (no simulator)."""

from __future__ import annotations

import html
import json

from click.testing import CliRunner

from sga_agent.cli import main
from sga_agent.report.candidates import PLAN_CHARS, first_line, fitted, number
from sga_agent.report.data import read_run
from sga_agent.run_store import RunStore
from sga_agent.task import Evaluation
from tests.sga_agent.test_search import config

PLAN = """### Step-by-Step Plan

1. **Replace** the `volume` term with a log barrier, so that the energy grows without bound as
   J goes to zero, then fit its weight.
2. Keep the deviatoric part.
"""
ANALYSIS = "The loss <b>grows</b> after step 40 & the body < collapses."


def proposal(temperature: float, **new: object) -> dict:
    """A proposal record as a proposer leaves it (``new``: the fields older runs lack)."""
    return {"text": "answer", "model": "m", "temperature": temperature, "prompt_tokens": 10,
            "completion_tokens": 5, "cost_usd": 0.001, **new}  # fmt: skip


def write_run(tmp_path) -> RunStore:
    """A run with a fitted seed, a model answer with its analysis, plan and reasoning, a
    rejected answer cut off at the token limit, a repeat, an older run's answer (no new
    records) and a screen never fitted fully."""
    store = RunStore.create(tmp_path, config(), {"proposer": "scripted"})
    seed = Evaluation(True, 100.0, "fine", parameters={"E": 1.2e5, "nu": 0.31})
    store.save_evaluation("00-seed", "class Physics: ...", seed)

    store.save_proposal("01-exploit-00", None, proposal(0.5, finish_reason="stop",
                                                        parents=["00-seed"]))  # fmt: skip
    folder = store.candidate_dir("01-exploit-00")
    (folder / "plan.md").write_text(PLAN)
    (folder / "analysis.md").write_text(ANALYSIS)
    (folder / "reasoning.md").write_text("Let me think </pre> about it.")
    five = {"a": 1.0, "b": 2e-7, "c": -3.0, "d": 4.5e12, "e": 5.0}
    store.save_evaluation("01-exploit-00", "code", Evaluation(True, 5.0, "ok", parameters=five))

    store.save_proposal("01-explore-00", None, proposal(1.0, finish_reason="length",
                                                        parents=["00-seed", "01-x"]))  # fmt: skip
    rejected = Evaluation.invalid(
        "the code was rejected before it ran: line 3: the code defines no top-level class "
        "'Physics'", extras={"read_as": ["added `import torch`"]},
    )  # fmt: skip
    store.save_evaluation("01-explore-00", "code", rejected)

    store.save_proposal("01-explore-01", None, proposal(1.0, parents=["00-seed"]))
    repeat = Evaluation(True, 5.0, "ok", extras={"duplicate_of": "01-exploit-00"})
    store.save_evaluation("01-explore-01", "code", repeat)

    store.save_proposal("02-exploit-00", None, proposal(0.5))  # an older run's record
    store.save_evaluation("02-exploit-00", "code", Evaluation(True, 2.0, "ok"))

    store.save_proposal("02-explore-00", None, proposal(1.0, parents=["01-exploit-00"]))
    unstable = Evaluation.invalid("the stress is NaN at step 12", status="unstable")
    store.save_screen("02-explore-00", "code", unstable)
    return store


def test_the_table_has_a_row_per_candidate_with_its_answer_folded_in(tmp_path):
    store = write_run(tmp_path)
    result = CliRunner().invoke(main, ["report", str(store.path), "--no-motion"])
    assert result.exit_code == 0, result.output
    folder = store.path / "report"
    md = (folder / "report.md").read_text()
    page = (folder / "report.html").read_text()
    # the summary counts as the end screen does: the repeat left out, one screen in the singular
    assert "- 4 evaluations (3 ok, 1 invalid) after 1 screen (1 unstable), proposer" in md
    table = md.split("## Candidates")[1].split("<details>")[0]
    rows = [line for line in table.splitlines() if line.startswith("| 0")]
    assert [row.split(" | ")[0] for row in rows] == [
        "| 00-seed", "| 01-exploit-00", "| 01-explore-00", "| 01-explore-01", "| 02-exploit-00",
        "| 02-explore-00",
    ]  # fmt: skip
    plan = ("Replace the volume term with a log barrier, so that the energy grows without bound "
            "as J goes to…")  # the item's wrapped lines joined # fmt: skip
    # the run has a screen: a screen column follows the loss, empty where none was made
    assert rows[0] == "| 00-seed | 0 |  | ok |  | 100 |  | E=1.2e5, nu=0.31 |  |  |  |"
    assert rows[1] == (
        "| 01-exploit-00 | 1 | 0.5 | ok |  | 5 |  | a=1, b=2e-7, c=-3, d=4.5e12, … | "
        f"{plan} | 00-seed | [analysis](../candidates/01-exploit-00/analysis.md), "
        "[plan](../candidates/01-exploit-00/plan.md), "
        "[reasoning](../candidates/01-exploit-00/reasoning.md) |"
    )
    assert rows[2] == (
        "| 01-explore-00 | 1 | 1 | invalid, finish: length | rejected: the code defines no "
        "top-level class 'Physics' | - |  |  |  | 00-seed, 01-x | read as |"
    )
    assert rows[3].startswith("| 01-explore-01 | 1 | 1 | ok | repeated an earlier law "
                              "(01-exploit-00) | 5 |")  # fmt: skip
    assert rows[4] == "| 02-exploit-00 | 2 | 0.5 | ok |  | 2 |  |  |  |  |  |"
    assert rows[5] == (
        "| 02-explore-00 | 2 | 1 | unstable (screen) | unstable: the stress is NaN at step N | "
        "- | unstable, not promoted |  |  | 01-exploit-00 |  |"
    )
    # the HTML folds the texts into the row, escaped
    html_rows = page.split('<table class="folded">')[1].split("</table>")[0].split("<tr>")[2:]
    assert len(html_rows) == 6
    assert (
        "<td>01-exploit-00</td><td>1</td><td>0.5</td><td>ok</td><td></td><td>5</td><td></td>"
        "<td>a=1, b=2e-7, c=-3, d=4.5e12, …</td>"
    ) in html_rows[1]
    assert (
        "<details><summary>analysis, plan, reasoning</summary><p><b>analysis</b></p>"
        f"<pre>{html.escape(ANALYSIS)}</pre><p><b>plan</b></p><pre>{html.escape(PLAN)}</pre>"
        "<p><b>reasoning</b></p><pre>Let me think &lt;/pre&gt; about it.</pre></details>"
    ) in html_rows[1]
    assert "<b>grows</b>" not in page and "</pre> about" not in page
    assert "<pre>- added `import torch`</pre>" in html_rows[2]
    assert "<details>" not in html_rows[0] + html_rows[4] + html_rows[5]


def test_the_report_reads_what_is_recorded_and_ranks_as_before(tmp_path):
    run = read_run(write_run(tmp_path).path)
    assert [c.id for c in run.candidates] == [
        "00-seed", "01-exploit-00", "01-explore-00", "01-explore-01", "02-exploit-00"]  # fmt: skip
    assert [c.id for c in run.screened] == ["02-explore-00"] and run.screened[0].screen_only
    ranked = ["02-exploit-00", "01-exploit-00", "00-seed"]  # no screen, no repeat
    assert [c.id for c in run.ranked()] == ranked
    answer = run.candidates[1].answer
    assert answer is not None and answer.temperature == 0.5 and answer.finish_reason == "stop"
    assert answer.parents == ["00-seed"] and answer.plan == PLAN and answer.analysis == ANALYSIS
    assert run.candidates[0].answer is None  # the seed: no answer
    old = run.candidates[4].answer
    assert old is not None and (old.finish_reason, old.parents, old.plan) == ("", [], "")


def test_a_report_written_elsewhere_links_back_to_the_candidates(tmp_path):
    store = write_run(tmp_path / "runs")
    out = tmp_path / "elsewhere" / "report"
    result = CliRunner().invoke(main, ["report", str(store.path), "--out-dir", str(out),
                                       "--no-motion", "--json"])  # fmt: skip
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["run"] == str(store.path)
    md = (out / "report.md").read_text()
    link = f"../../runs/{store.path.name}/candidates/01-exploit-00/plan.md"
    assert f"[plan]({link})" in md and (out / link).is_file()


def test_cells_are_compact():
    assert [number(v) for v in (1.2e5, 0.31, -3.0, 2.5e-7, 1e10, 7)] == [
        "1.2e5", "0.31", "-3", "2.5e-7", "1e10", "7"]  # fmt: skip
    assert fitted({"E": 1.2e5, "nu": 0.31}) == "E=1.2e5, nu=0.31"
    assert fitted({}) == ""
    assert first_line("\n\n## Plan:\n- `forward`: add **one** term\n") == "forward: add one term"
    assert first_line("### Step-by-Step Plan\n") == ""
    assert first_line("Plan:\n\n1. Add\n   a term.\n2. Fit it.") == "Add a term."
    assert first_line("# A heading\nthat goes on\n\nthen text") == "A heading"
    long = first_line("x" * 300)
    assert len(long) == PLAN_CHARS and long.endswith("…")
    words = first_line("a long word " * 30)  # 99 characters end in "a l": cut before "l"
    assert len(words) == PLAN_CHARS - 2 and words.endswith("word a…")
