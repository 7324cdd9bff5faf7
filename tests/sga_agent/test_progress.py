"""The search's progress bar and final screen, rendered by rich at 80 and 120 columns."""

from __future__ import annotations

import dataclasses
import io
import json
import math
import re
from concurrent.futures import Future

import pytest
from rich.console import Console

from sga_agent.causes import cause_of
from sga_agent.cli.progress import SearchProgress, failures_line, print_result
from sga_agent.config import UNTIL_BUDGET, SearchConfig
from sga_agent.events import CandidateEvaluated, CandidateScreened
from sga_agent.run_store import RunStore
from sga_agent.search import Search, SearchResult, Totals
from sga_agent.task import Evaluation
from sga_agent.wording import counted
from tasks.constitutive.task import ElasticTask, GranularTask
from tasks.molecules.task import HomoTask
from tests.sga_agent.test_search import LAW, FakeTask, Scripted, config

WIDTHS = (80, 120)


def console(width: int) -> Console:
    return Console(file=io.StringIO(), width=width, record=True, color_system=None)


def bar_line(progress: SearchProgress, width: int) -> str:
    """The progress bar as it is drawn at ``width`` columns (one line)."""
    screen = console(width)
    screen.print(progress.progress.get_renderable())
    lines = screen.export_text().rstrip("\n").splitlines()
    assert len(lines) == 1, lines
    assert len(lines[0]) <= width
    return lines[0]


def evaluation_event(loss: float, valid: bool = True) -> dict:
    return {"type": "evaluation", "evaluation": {"valid": valid, "loss": loss}}


def feed(progress: SearchProgress, *events: dict, totals: Totals | None = None) -> None:
    for event in events:
        progress({**event, "totals": totals or Totals()})


@pytest.mark.parametrize("width", WIDTHS)
def test_the_bar_shows_the_running_iteration_the_count_and_the_clock(width):
    cfg = config(proposer="builtin", iterations=4, exploit=1, explore=2)
    progress = SearchProgress(console(width), cfg)
    feed(progress, evaluation_event(100.0), {"type": "iteration_started", "iteration": 1})
    line = bar_line(progress, width)
    assert line.startswith("iteration 1/4")  # not "seed" while iteration 1 runs
    assert "1/13" in line and re.search(r"\d:\d\d:\d\d", line)
    feed(progress, evaluation_event(3.5), evaluation_event(float("inf"), valid=False))
    line = bar_line(progress, width)
    assert "3/13" in line and "best 3.5" in line and "failed 1" in line
    assert "tokens" not in line and "$" not in line  # no model, no spend


def test_a_search_until_its_time_budget_shows_no_iteration_total():
    cfg = config(proposer="builtin", iterations=UNTIL_BUDGET, exploit=1, explore=2)
    progress = SearchProgress(console(80), cfg)
    feed(progress, evaluation_event(1.0), {"type": "iteration_started", "iteration": 7})
    line = bar_line(progress, 80)
    assert line.startswith("iteration 7 ") and str(UNTIL_BUDGET) not in line


def test_a_screened_candidate_counts_once_and_its_screen_loss_is_not_the_best():
    cfg = config(proposer="builtin", iterations=1, exploit=1, explore=1, fidelity="multi")
    progress = SearchProgress(console(80), cfg)
    screen = {"type": "screened", "fidelity": 0.2, "evaluation": {"valid": True, "loss": 0.01}}
    feed(progress, {**evaluation_event(100.0), "candidate": "00-seed"},
         {**screen, "candidate": "01-exploit-00"}, {**screen, "candidate": "01-explore-00"},
         {**evaluation_event(50.0), "candidate": "01-explore-00"})  # fmt: skip
    line = bar_line(progress, 80)
    assert "3/3" in line and "best 50" in line


def test_with_a_model_the_bar_shows_the_spend():
    cfg = config(proposer="openai/gpt-4o", iterations=4, exploit=1, explore=2)
    progress = SearchProgress(console(120), cfg)
    feed(progress, evaluation_event(1.0), totals=Totals(tokens=1234, cost_usd=0.5))
    assert "1234 tokens  $0.500" in bar_line(progress, 120)


def test_a_resumed_run_counts_from_what_its_folder_holds(tmp_path):
    cfg = config(iterations=1, exploit=1, explore=1)
    store = RunStore.create(tmp_path, cfg, {})
    finished = {"00-seed": Evaluation(True, 100.0, "fine"),
                "01-exploit-00": Evaluation(True, 7.0, "fine"),
                "01-explore-00": Evaluation.invalid("broken")}  # fmt: skip
    for candidate, evaluation in finished.items():
        store.append(
            {"type": "evaluation", "candidate": candidate, "evaluation": evaluation.to_dict()}
        )
    progress = SearchProgress(console(80), cfg, store.recorded())
    line = bar_line(progress, 80)
    assert line.startswith("resuming") and "3/3" in line
    assert "best 7" in line and "failed 1" in line


class FittedScale:
    """Evaluator double: the loss written in the code, and a fitted ``scale`` of 2.5."""

    def submit(self, task, solution, settings) -> Future[Evaluation]:
        future: Future[Evaluation] = Future()
        loss = float(re.search(r"loss ([-\d.e+]+)", solution).group(1))
        future.set_result(Evaluation(True, loss, "fitted", parameters={"scale": 2.5}))
        return future


@pytest.mark.parametrize("width", WIDTHS)
def test_the_final_screen_compares_with_the_seed_and_shows_the_fitted_law(tmp_path, width):
    cfg = dataclasses.replace(config(iterations=1, exploit=1, explore=1), proposer="builtin")
    store = RunStore.create(tmp_path, cfg, {})
    answers = [LAW.format(value=10.0), "no code in this answer"]
    result = Search(cfg, FakeTask(), Scripted(answers), FittedScale(), store).run()
    screen = console(width)
    print_result(screen, store, result, False, ElasticTask(), cfg)
    text = screen.export_text()

    assert "best: 01-exploit-00, loss 10, 10x below the seed's 100" in text
    assert "scale: float = 2.5" in text and "scale: float = 1.0" not in text
    assert "3 evaluations (2 ok, 1 invalid)\n" in text  # no screens in a full-fidelity run
    assert "tokens" not in text
    assert f"report: sga-agent report {store.path}\n" in text  # one line, whatever the width
    code = text.split("its code, with the fitted constants written in:\n")[1].split("\n3 eval")[0]
    compile(code, "<screen>", "exec")  # the code as written, not wrapped at the width
    for line in text.replace(code, "").splitlines():
        if not line.startswith(("report:", "run folder:")):
            assert len(line) <= width, line


def test_the_law_on_the_final_screen_compiles_however_narrow_the_screen(tmp_path):
    """Piped or narrow, the printed law is the law: long lines are not wrapped."""
    cfg = dataclasses.replace(config(iterations=1, exploit=1, explore=0), proposer="builtin")
    store = RunStore.create(tmp_path, cfg, {})
    long_line = "        return F * 10.0  # " + "a comment that runs far past forty columns " * 3
    law = LAW.format(value=10.0).replace("        return F * 10.0", long_line)
    result = Search(cfg, FakeTask(), Scripted([law]), FittedScale(), store).run()
    screen = console(40)
    print_result(screen, store, result, False, ElasticTask(), cfg)
    text = screen.export_text()
    code = text.split("written in:\n")[1].split("\n2 evaluations")[0]
    assert long_line.rstrip() in code
    compile(code, "<screen>", "exec")


def test_the_final_screen_says_whether_the_data_determine_the_law(tmp_path):
    cfg = dataclasses.replace(config(iterations=1, exploit=1, explore=0), proposer="builtin")
    store = RunStore.create(tmp_path, cfg, {})
    result = Search(cfg, FakeTask(), Scripted([LAW.format(value=10.0)]), FittedScale(),
                    store).run()  # fmt: skip
    sentence = ("the observation does not determine the law: 2 distinct forms fit it within "
                "the noise, and their motions differ by up to 9 % of the body size")  # fmt: skip
    simpler = "class Physics:\n    " + "x = 1  # a line longer than the screen " * 4 + "\n"
    findings = {"verdict": "the best law reproduces the motion",
                "identifiability": {"determined": False, "sentence": sentence},
                "simplified": {"sentence": "1 of its parts costs less than the noise",
                               "solution": simpler}}  # fmt: skip
    store.save_summary({**store.summary(), "findings": findings})
    screen = console(WIDTHS[0])
    print_result(screen, store, result, False, ElasticTask(), cfg)
    text = screen.export_text()
    assert f"verdict: the best law reproduces the motion\nidentifiability: {sentence}\n" in text
    assert "simplified: 1 of its parts costs less than the noise:\n" + simpler in text


def test_the_final_screen_writes_the_task_s_formula_of_the_best_on_one_line(tmp_path):
    cfg = dataclasses.replace(config(iterations=1, exploit=1, explore=0), proposer="builtin")
    store = RunStore.create(tmp_path, cfg, {})
    result = Search(cfg, FakeTask(), Scripted([LAW.format(value=10.0)]), FittedScale(),
                    store).run()  # fmt: skip
    best = "F_corrected = 0.3055*F + 0.6124*U diag(exp(vol(eps))) Vh + 0.082*R"
    simpler = "F_corrected = 0.3055*F + 0.6124*U diag(exp(vol(eps))) Vh"
    findings = {"best_formula": best,
                "simplified": {"sentence": "1 of its parts costs less than the noise",
                               "solution": "class Physics:\n    pass\n", "formula": simpler}}
    store.save_summary({**store.summary(), "findings": findings})
    screen = console(WIDTHS[0])
    print_result(screen, store, result, False, ElasticTask(), cfg)
    text = screen.export_text()
    assert f"as a formula: {best}\nits code, with the fitted constants written in:" in text
    assert f"class Physics:\n    pass\n\nas a formula: {simpler}\n" in text


def test_the_final_count_of_a_multi_fidelity_search_names_its_screens(tmp_path):
    cfg = dataclasses.replace(config(iterations=1, exploit=1, explore=1), proposer="builtin")
    store = RunStore.create(tmp_path, cfg, {})
    answers = [LAW.format(value=10.0), LAW.format(value=20.0)]
    result = Search(cfg, FakeTask(), Scripted(answers), FittedScale(), store).run()
    unstable = Evaluation(False, float("inf"), "blew up", status="unstable")
    store.append(CandidateScreened("01-explore-09", 0.2, unstable.to_dict()))
    screen = console(WIDTHS[-1])
    print_result(screen, store, result, False, ElasticTask(), cfg)
    assert "3 evaluations (3 ok) after 1 screen (1 unstable)" in screen.export_text()


def failing_run(tmp_path) -> tuple[RunStore, SearchResult, SearchConfig]:
    """A run of two answers without code, then (appended) two answers unstable at different
    steps, a repeat, a timeout, an error and a screen that blew up."""
    cfg = dataclasses.replace(config(iterations=1, exploit=1, explore=1), proposer="builtin")
    store = RunStore.create(tmp_path, cfg, {})
    answers = ["no code in this answer", "no code here either"]
    result = Search(cfg, FakeTask(), Scripted(answers), FittedScale(), store).run()
    more = {
        "02-explore-00": Evaluation.invalid("NaN stress at step 3", status="unstable"),
        "02-explore-01": Evaluation.invalid("NaN stress at step 9", status="unstable"),
        "02-exploit-00": Evaluation(True, 10.0, "ok", extras={"duplicate_of": "00-seed"}),
        "02-explore-02": Evaluation.invalid("ran past 60 s", status="timeout"),
        "02-explore-03": Evaluation.invalid("ValueError: bad shape", status="error"),
    }
    for candidate, evaluation in more.items():
        store.append(CandidateEvaluated(candidate, evaluation.to_dict()))
    store.append(CandidateScreened("03-explore-00", 0.2, more["02-explore-00"].to_dict()))
    return store, result, cfg


def test_the_final_screen_names_the_most_frequent_causes_of_failure(tmp_path):
    store, result, cfg = failing_run(tmp_path)
    no_code = cause_of(vars(store.recorded().evaluations["01-exploit-00"]))
    assert no_code.startswith("invalid: ")
    screen = console(WIDTHS[-1])
    print_result(screen, store, result, False, ElasticTask(), cfg)
    text = screen.export_text()
    assert "failures:" in text.split("evaluations (")[1]  # after the counts by status
    lines = text.splitlines()
    first = next(i for i, line in enumerate(lines) if line.startswith("failures:"))
    assert " ".join(" ".join(lines[first:-1]).split()) == (  # wrapped, before the report line
        f"failures: 8 of 8 answers: 3 unstable: NaN stress at step N; 2 {no_code}; "
        "1 repeated an earlier law; 2 of other causes"
    )


def test_without_failures_no_causes_are_printed_and_json_lists_them(tmp_path, capsys):
    cfg = dataclasses.replace(config(iterations=1, exploit=1, explore=1), proposer="builtin")
    store = RunStore.create(tmp_path, cfg, {})
    answers = [LAW.format(value=10.0).replace("F * 10.0", "F + F * 10.0"),  # other forms
               LAW.format(value=20.0).replace("F * 20.0", "F.T * 20.0")]  # fmt: skip
    result = Search(cfg, FakeTask(), Scripted(answers), FittedScale(), store).run()
    screen = console(WIDTHS[-1])
    print_result(screen, store, result, False, ElasticTask(), cfg)
    assert "3 evaluations (3 ok)" in screen.export_text()
    assert "failures" not in screen.export_text()

    store, result, cfg = failing_run(tmp_path / "failing")
    capsys.readouterr()
    print_result(console(80), store, result, True, ElasticTask(), cfg)
    summary = json.loads(capsys.readouterr().out)
    assert summary["causes"][0] == ["unstable: NaN stress at step N", 3]
    assert [count for _, count in summary["causes"]] == [3, 2, 1]
    assert summary["run"] == str(store.path)


class Fitted:
    """Evaluator double: the loss written in the code, and the given fitted ``parameters``."""

    def __init__(self, parameters: dict[str, float]) -> None:
        self.parameters = parameters

    def submit(self, task, solution, settings) -> Future[Evaluation]:
        future: Future[Evaluation] = Future()
        loss = float(re.search(r"loss ([-\d.e+]+)", solution).group(1))
        future.set_result(Evaluation(True, loss, "fitted", parameters=dict(self.parameters)))
        return future


def final_screen(tmp_path, values, evaluator=None, task=None, findings=None) -> str:
    """The final screen (120 columns) of a run whose answers have the losses ``values``, the
    seed's being 100; ``findings`` stand in for what the run's end would have recorded."""
    explore = len(values) - 1
    cfg = dataclasses.replace(config(iterations=1, exploit=1, explore=explore, top_k=5),
                              proposer="builtin")  # fmt: skip
    store = RunStore.create(tmp_path, cfg, {})
    answers = [LAW.format(value=value) for value in values]
    result = Search(cfg, FakeTask(), Scripted(answers), evaluator or FittedScale(), store).run()
    if findings is not None:
        store.save_summary({**store.summary(), "findings": findings})
    screen = console(WIDTHS[-1])
    print_result(screen, store, result, False, task or ElasticTask(), cfg)
    return screen.export_text()


def test_a_loss_above_the_seed_s_reads_above_not_below(tmp_path):
    findings = {"truth": "the true law", "truth_loss": 20.0, "best_over_truth": 0.5}
    text = final_screen(tmp_path, [10.0, 200.0], findings=findings)
    rows = {line.split("│")[2].strip(): line for line in text.splitlines() if "│" in line}
    assert "10x below" in rows["01-exploit-00"]  # 100 / 10
    assert "2.00x above" in rows["01-explore-00"] and "below" not in rows["01-explore-00"]
    assert "equal" in rows["00-seed"]
    assert "vs the seed's ┃" in text  # not "x below the seed": wrong for a ratio under 1
    assert "best: 01-exploit-00, loss 10, 10x below the seed's 100" in text
    # the truth's loss 20 is twice the best's 10: above it, not "0.5x below"
    assert "ground truth: the true law; its loss 20, 2.00x above the best's" in text


def test_the_fitted_values_are_shown_in_natural_units(tmp_path):
    fitted = {"log_yield_stress": math.log(3e4), "log_friction_angle": math.log(0.5), "nu": 0.2}
    text = final_screen(tmp_path, [10.0], Fitted(fitted), GranularTask())
    # the law's code does not turn degrees into radians: its angle is in radians
    assert "fitted, in natural units: yield stress 3e+04 Pa; friction angle 0.5 rad\n" in text
    assert "its code, with the fitted constants written in:" in text


def test_the_end_of_a_molecule_search_speaks_of_the_molecule_and_its_property(tmp_path):
    fitted = {"property": 0.012, "strain_kcal_mol": 1.5}
    molecule = {"candidate": "01-exploit-00", "smiles": "CC(=O)Nc1ccc(O)cc1",
                "property": "HOMO", "normalized": 0.012, "target": 0.0, "distance": 0.012,
                "hartree": -0.2399, "ev": -6.528, "loss": 10.0}  # fmt: skip
    findings = {"best": {"candidate": "01-exploit-00"}, "molecules": [molecule]}
    text = final_screen(tmp_path, [10.0], Fitted(fitted), HomoTask(), findings)
    assert "best molecule (SMILES): CC(=O)Nc1ccc(O)cc1\n" in text
    property_line = "its HOMO: -0.2399 Ha (-6.53 eV) on the QM9 B3LYP scale, +0.012 normalized"
    assert property_line + " (target +0)\n" in text
    assert "its code" not in text and "fitted constants" not in text
    assert "as proposed, before its optimization:" in text
    assert "fitted, in natural units" not in text  # no log_ parameter


def test_counts_of_one_are_singular():
    outcome = vars(Evaluation.invalid("no code in this answer"))
    assert failures_line([outcome]).startswith("failures: 1 of 1 answer: ")
    assert counted(1, "evaluation") == "1 evaluation"
    assert counted(0, "evaluation") == "0 evaluations"
    assert counted(2, "finished evaluation") == "2 finished evaluations"
