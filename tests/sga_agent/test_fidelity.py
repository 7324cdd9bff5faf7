"""Multi-fidelity search: screens, promotion, the heap and the run store (test doubles for the
model and the evaluator; the constitutive task's screen is tested in tests/tasks).

The evaluator double scores a law's code by the numbers written in it: ``loss X`` at the full
fidelity, ``screen S`` (default: X / 1000) at a lower one. Screen losses are below every full
loss, so a heap or a prompt that mixed the two would put a screen first.
"""

from __future__ import annotations

import json
import re
from concurrent.futures import Future

import pytest

from sga_agent.config import ConfigError, SearchConfig
from sga_agent.run_store import RunStore
from sga_agent.search import SEED, Search, kth_best, promoted
from sga_agent.task import Evaluation
from tests.sga_agent.test_search import LAW as SEARCH_LAW
from tests.sga_agent.test_search import FakeTask, Scripted

#: The search tests' law, with its screen loss written beside its loss.
LAW = SEARCH_LAW.replace('loss {value}"', 'loss {value} screen {screen}"')


def law(value: float, screen: float | None = None) -> str:
    return LAW.format(value=value, screen=value / 1000 if screen is None else screen)


class TwoFidelities:
    """Evaluator double: loss and screen loss from the code; records each submission's
    fidelity and whether it came with captured data (which it checks is its own)."""

    def __init__(self) -> None:
        self.calls: list[tuple[float, float, bool]] = []  # (loss in the code, fidelity, captured)

    def submit(self, task, solution, settings, captured=None) -> Future[Evaluation]:
        value = float(re.search(r"loss ([-\d.e+]+)", solution).group(1))
        screen = re.search(r"screen ([-\d.e+]+)", solution)
        if captured is not None:
            assert captured == {"code": solution}  # the screen's own capture
        self.calls.append((value, settings.fidelity, captured is not None))
        if settings.fidelity < 1:
            value = float(screen.group(1)) if screen else value / 1000
        future: Future[Evaluation] = Future()
        evaluation = Evaluation(True, value, f"feedback for loss {value}")
        evaluation.artifacts["captured"] = {"code": solution}
        future.set_result(evaluation)
        return future


def config(**overrides) -> SearchConfig:
    values = {"task": "fake", "proposer": "scripted", "iterations": 2, "top_k": 3,
              "exploit": 2, "explore": 4, "workers": 1, "fidelity": "multi",
              "screen_fidelity": 0.2, "promote": 0.25}  # fmt: skip
    values.update(overrides)
    return SearchConfig.from_settings(**values)


def run(tmp_path, answers, **overrides):
    cfg = config(**overrides)
    store = RunStore.create(tmp_path, cfg, {})
    evaluator = TwoFidelities()
    result = Search(cfg, FakeTask(), Scripted(answers), evaluator, store).run()
    return result, store, evaluator


ANSWERS = [law(v) for v in (9.0, 3.0, 7.0, 5.0, 8.0, 6.0)] + [
    law(v) for v in (2.0, 4.0, 1.0, 10.0, 11.0, 12.0)
]


def by_type(store: RunStore, kind: str) -> dict[str, dict]:
    return {e["candidate"]: e for e in store.events() if e["type"] == kind}


def test_promotion_takes_the_best_share_of_the_valid_screens_once_per_code():
    def screen(loss: float, valid: bool = True) -> Evaluation:
        return Evaluation(valid, loss, "") if valid else Evaluation.invalid("no")

    screens = [("a", screen(5.0)), ("b", screen(1.0)), ("c", screen(0.0, valid=False)),
               ("d", screen(3.0)), ("b", screen(1.0)), ("e", screen(3.0)),
               ("f", screen(9.0))]  # fmt: skip
    # valid distinct codes: a, b, d, e, f: a quarter rounded up is 2; d ties e and comes first
    inf = float("inf")
    assert promoted(screens, 0.25, inf) == {"b", "d"}
    assert promoted(screens, 0.5, inf) == {"b", "d", "e"}
    assert promoted(screens, 1.0, inf) == {"a", "b", "d", "e", "f"}
    assert promoted(screens[:1], 0.01, inf) == {"a"}  # at least one
    assert promoted([("c", screen(0.0, valid=False))], 1.0, inf) == set()
    # only those below the bar (the K-th best screen of the earlier iterations)
    assert promoted(screens, 0.5, 3.0) == {"b"}
    assert promoted(screens, 1.0, 1.0) == set()


def test_the_bar_is_the_k_th_best_earlier_screen():
    assert kth_best([4.0, 1.0, 3.0, 2.0], 3) == 3.0
    assert kth_best([4.0, 1.0], 3) == float("inf")


def test_the_heap_and_the_prompt_hold_full_fidelity_scores_only(tmp_path):
    result, store, evaluator = run(tmp_path, ANSWERS)
    full = by_type(store, "evaluation")
    screens = by_type(store, "screened")
    # every offspring screened at the screen fidelity, the seed only fitted in full
    kinds = ("exploit-00", "exploit-01", "explore-00", "explore-01", "explore-02", "explore-03")
    assert sorted(screens) == [f"{i:02d}-{kind}" for i in (1, 2) for kind in kinds]
    assert {e["fidelity"] for e in screens.values()} == {0.2}
    # a quarter of 6, rounded up: 2 promoted per iteration, the lowest screens
    assert sorted(full) == sorted([SEED, "01-exploit-01", "01-explore-01",
                                   "02-exploit-00", "02-explore-00"])  # fmt: skip
    for entry in result.heap.entries:
        assert entry.candidate in full
        assert entry.loss == float(full[entry.candidate]["evaluation"]["loss"])
    assert [(e.candidate, e.loss) for e in result.top] == [
        ("02-explore-00", 1.0),
        ("02-exploit-00", 2.0),
        ("01-exploit-01", 3.0),
    ]
    user = json.loads((store.path / "candidates/02-exploit-00/messages.json").read_text())
    prompt = user[-1]["content"]
    assert "loss 3.0" in prompt and "loss 5.0" in prompt  # the promoted, fitted in full
    assert "loss 9.0" not in prompt  # no law that was only screened
    assert "feedback for loss 0.0" not in prompt  # no screen's feedback
    # no extra capture: each promoted law is fitted in full from its screen's captured data
    assert evaluator.calls.count((100.0, 1.0, False)) == 1  # the seed
    assert sorted(c for c in evaluator.calls if c[1] == 1.0 and c[2]) == [
        (1.0, 1.0, True),
        (2.0, 1.0, True),
        (3.0, 1.0, True),
        (5.0, 1.0, True),
    ]
    summary = json.loads((store.path / "summary.json").read_text())
    assert summary["screened"] == 12 and summary["evaluations"] == 17
    assert summary["valid"] == 5


def test_the_run_folder_keeps_each_fidelity_s_score(tmp_path):
    _, store, _ = run(tmp_path, ANSWERS)
    promoted_one = store.path / "candidates/01-exploit-01"
    screen = json.loads((promoted_one / "screen.json").read_text())
    fitted = json.loads((promoted_one / "evaluation.json").read_text())
    assert (screen["loss"], fitted["loss"]) == (0.003, 3.0)
    screened_only = store.path / "candidates/01-exploit-00"
    assert json.loads((screened_only / "screen.json").read_text())["loss"] == 0.009
    assert not (screened_only / "evaluation.json").exists()
    recorded = store.recorded()
    assert recorded.screens["01-exploit-01"].loss == 0.003
    assert recorded.evaluations["01-exploit-01"].loss == 3.0
    assert "01-exploit-00" not in recorded.evaluations


def test_screen_ranks_can_differ_from_full_ones(tmp_path):
    """Promotion follows the screen; the heap then follows the full fit."""
    answers = [law(1.0, screen=0.9), law(50.0, screen=0.1), law(60.0, screen=0.2),
               law(70.0, screen=0.3), law(80.0, screen=0.4), law(90.0, screen=0.5)]  # fmt: skip
    result, store, _ = run(tmp_path, answers, iterations=1)
    assert sorted(by_type(store, "evaluation")) == [SEED, "01-exploit-01", "01-explore-00"]
    assert result.best.loss == 50.0  # the law of full loss 1.0 was screened out


def test_later_screens_are_promoted_only_below_the_k_th_best_earlier_screen(tmp_path):
    # iteration 1's screens: 0.003 to 0.009, the third best (K = 3) 0.006
    second = [law(4.0, screen=0.004), law(6.1, screen=0.0061), law(7.5, screen=0.0075),
              law(8.5, screen=0.0085), law(9.5, screen=0.0095), law(10.0, screen=0.01)]  # fmt: skip
    _, store, _ = run(tmp_path, ANSWERS[:6] + second, promote_rank=None)  # None: the bar at K
    # a quarter of six, rounded up, is two: 0.004 and 0.0061, of which only the first < 0.006
    assert sorted(by_type(store, "evaluation")) == sorted(
        [SEED, "01-exploit-01", "01-explore-01", "02-exploit-00"]
    )
    # with the bar at the best earlier screen (0.003, the default), none of iteration 2 is
    # fitted in full
    _, store, _ = run(tmp_path / "rank-1", ANSWERS[:6] + second)
    assert sorted(by_type(store, "evaluation")) == sorted([SEED, "01-exploit-01", "01-explore-01"])


def test_resume_of_a_killed_multi_fidelity_run_continues_where_it_stopped(tmp_path):
    whole, whole_store, whole_calls = run(tmp_path / "whole", ANSWERS)
    cfg = config()
    store = RunStore.create(tmp_path / "killed", cfg, {})
    lines = whole_store.path.joinpath("events.jsonl").read_text().splitlines()
    # killed in iteration 2 after three of its screens
    screened = [i for i, line in enumerate(lines) if '"type": "screened"' in line]
    kept = lines[1 : screened[8] + 1]
    with open(store.path / "events.jsonl", "a") as log:
        log.write("\n".join(kept) + "\n")
    evaluator = TwoFidelities()
    resumed = Search(cfg, FakeTask(), Scripted([]), evaluator, store).run()
    assert [(e.candidate, e.loss) for e in resumed.heap.top(10)] == [
        (e.candidate, e.loss) for e in whole.heap.top(10)
    ]
    # only the three screens left, then the two promoted: fitted from their screen's captured
    # data where the screen ran in this session, captured anew where it ran before the kill
    values = dict(zip([f"02-{kind}" for kind in ("exploit-00", "exploit-01", "explore-00",
                                                 "explore-01", "explore-02", "explore-03")],
                      (2.0, 4.0, 1.0, 10.0, 11.0, 12.0), strict=True))  # fmt: skip
    before = {json.loads(line)["candidate"] for line in kept if '"type": "screened"' in line}
    left = [value for candidate, value in values.items() if candidate not in before]
    screened_now = {(value, 0.2, False) for value in left}
    fitted = {(value, 1.0, value in left) for value in (1.0, 2.0)}
    assert len(evaluator.calls) == 5 and set(evaluator.calls) == screened_now | fitted
    assert store.recorded().finished
    assert len(by_type(store, "screened")) == 12


def test_full_fidelity_is_the_default_and_old_configs_load_without_the_setting(tmp_path):
    plain = SearchConfig.from_settings(task="fake", proposer="scripted")
    assert plain.loop.fidelity == "full"
    # multi's defaults: a screen of a tenth of the fit, promoted only as a possible new best
    assert (plain.loop.screen_fidelity, plain.loop.promote_rank) == (0.1, 1)
    data = plain.to_dict()
    for name in ("fidelity", "screen_fidelity", "promote", "promote_rank"):
        del data["loop"][name]
    from sga_agent.task import NoOptions

    assert SearchConfig.from_dict(data, NoOptions).loop.fidelity == "full"
    recorded = config().to_dict()["loop"]
    assert (recorded["fidelity"], recorded["screen_fidelity"], recorded["promote"]) == (
        "multi", 0.2, 0.25,
    )  # fmt: skip


@pytest.mark.parametrize("setting", [{"fidelity": "half"}, {"screen_fidelity": 1.0},
                                     {"screen_fidelity": 0.0}, {"promote": 0.0},
                                     {"promote_rank": 0}])  # fmt: skip
def test_bad_fidelity_settings_are_refused(setting):
    with pytest.raises(ConfigError):
        config(**setting)


def test_a_full_fidelity_run_never_screens(tmp_path):
    result, store, evaluator = run(tmp_path, ANSWERS, fidelity="full")
    assert not by_type(store, "screened")
    assert {fidelity for _, fidelity, _ in evaluator.calls} == {1.0}
    assert len(by_type(store, "evaluation")) == 13
