"""What went wrong reaches the next prompt: every failed answer's cause and fix, alike causes
told once, repeats named; the shown top-K holds distinct laws; the prompt keeps to its budget."""

from __future__ import annotations

import json
import math
import re

from sga_agent.causes import REPEATED, cause_of, top_causes
from sga_agent.failures import MAX_CAUSES, Outcome, failures_text
from sga_agent.fingerprint import form_fingerprint
from sga_agent.heap import SolutionHeap
from sga_agent.prompting import FEEDBACK_LINES, Shown, fit_to_budget, shortened
from sga_agent.run_store import RunStore
from sga_agent.search import Search
from sga_agent.task import Evaluation, PromptParts
from tests.sga_agent.test_search import LAW, FakeTask, LossInCode, Scripted, config

REJECTED = Evaluation.invalid(
    "the code was rejected before it ran: line 3: importing 'os' is not allowed; only torch"
).to_dict()
TRACE = Evaluation.invalid(
    "line 2 (`t = torch.trace(F)`): RuntimeError: trace: expected a matrix; torch.trace works "
    "on one matrix: use torch.diagonal(A, dim1=-2, dim2=-1).sum(-1)"
).to_dict()
CODE = "import torch\nt = torch.trace(F)\nreturn t\n"


def test_alike_failures_are_told_once_with_every_answer_they_hit():
    outcomes = [
        Outcome("02-explore-00", CODE, TRACE),
        Outcome("02-explore-01", CODE, TRACE),
        Outcome("02-explore-02", "import os\n", REJECTED),
        Outcome("02-exploit-00", "x", {"valid": True, "loss": 2.0}),
    ]
    text = failures_text(outcomes, {})
    assert text.count("torch.trace works on one matrix") == 1
    assert "02-explore-00, 02-explore-01 (invalid)" in text
    assert "  2 | t = torch.trace(F)" in text  # the line the reason names
    assert "importing 'os' is not allowed" in text and "02-exploit-00" not in text
    assert cause_of(TRACE) == cause_of({**TRACE, "reason": TRACE["reason"].replace("2", "7")})


def test_repeats_are_named_with_the_law_they_repeat():
    same_code = Evaluation(True, 1.0, "", extras={"duplicate_of": "01-exploit-00"}).to_dict()
    same_form = Evaluation(True, 3.0, "", extras={"same_form_as": "01-explore-01"}).to_dict()
    same_loss = Evaluation(True, 2.5e-6, "").to_dict()
    outcomes = [
        Outcome("02-exploit-00", "a", same_code),
        Outcome("02-explore-00", "b", same_form),
        Outcome("02-explore-01", "c", same_loss),
    ]
    losses = {"01-exploit-00": 1.0, "01-explore-01": 1.2e-6, "01-explore-02": 2.5e-6}
    text = failures_text(outcomes, losses)
    assert "02-exploit-00 is the same code as 01-exploit-00, loss 1" in text
    assert "02-explore-00 is the same law as 01-explore-01, loss 1.2e-06" in text
    assert "02-explore-01 reached exactly the loss of 01-explore-02" in text
    assert "Propose a different form" in text
    assert cause_of(same_form) == REPEATED


def test_the_section_is_bounded_and_empty_when_nothing_failed():
    many = [
        Outcome(
            f"03-explore-{i:02d}",
            "x\n" * 50,
            Evaluation.invalid(f"cause {'x' * i} " + "y" * 900).to_dict(),
        )
        for i in range(MAX_CAUSES + 3)
    ]
    text = failures_text(many, {})
    assert "(3 more causes, 3 answers, not listed)" in text
    assert len(text) < MAX_CAUSES * 1200
    assert failures_text([Outcome("01-exploit-00", "x", {"valid": True, "loss": 1.0})], {}) == ""
    counted = top_causes([o.evaluation for o in many] + [TRACE, TRACE], 1)
    assert counted[0][1] == 2 and "trace" in counted[0][0]


def test_the_shown_top_k_holds_one_entry_per_law():
    heap = SolutionHeap()
    law = "def f(x):\n    return {a} * x + {b}\n"
    heap.push("a", law.format(a=1.0, b=2.0), 1.0, "", True)
    heap.push("b", law.format(a=3.0, b=-2.0), 0.5, "", True)  # the same form, better
    heap.push("c", "def f(x):\n    return x ** 2\n", 0.7, "", True)
    heap.push("d", "def g(y):\n    return y ** 2\n", 0.7, "", True)  # the same loss as c
    heap.push("e", "broken(", math.inf, "", False)
    heap.push("f", "def f(x):\n    return abs(x)\n", 2.0, "", True)
    shown = heap.distinct_top(5, form_fingerprint)
    assert [entry.candidate for entry in shown] == ["b", "c", "f"]
    assert [entry.candidate for entry in heap.top(3)] == ["b", "c", "d"]  # the heap keeps all


def test_the_prompt_is_shortened_worst_feedback_first_to_fit_its_budget():
    parts = PromptParts("a tester", "find it", "class Physics: ...", "rules")
    feedback = "\n".join(f"line {i} of a long table" for i in range(60))
    history = [Shown(f"code {i}", feedback, float(i)) for i in range(5)]

    def count(messages):
        return len(" ".join(m["content"] for m in messages).split())

    full, full_count = fit_to_budget("equation", parts, history, "", None, count)
    budget = full_count - 200
    messages, tokens = fit_to_budget("equation", parts, history, "", budget, count)
    assert tokens <= budget < full_count
    user = messages[-1]["content"]
    worst, best = user.split("### Iteration 1", 1)[1], user.split("### Iteration 5", 1)[1]
    assert "more lines of this feedback left out" in worst.split("### Iteration 2")[0]
    assert "left out" not in best.split("## Format")[0]  # the best still whole
    for section in ("## Task", "## Earlier solutions", "### Code template", "### Analysis"):
        assert section in user
    assert shortened("a\nb\nc", 2) == "a\nb\n(1 more lines of this feedback left out)"
    # shortened again, a feedback counts what it left out of the whole, not of the last cut
    tight, _ = fit_to_budget("equation", parts, history, "", full_count - 1500, count)
    left = [int(n) for n in re.findall(r"\((\d+) more lines", tight[-1]["content"])]
    assert any(n > 60 - FEEDBACK_LINES[0] for n in left)  # the second cut at least
    assert set(left) <= {60 - lines for lines in FEEDBACK_LINES}
    assert FEEDBACK_LINES[-1] >= 2


#: The search tests' law with its loss in a comment: one form whatever the number.
REPEATING = LAW.replace('    label = "a law of its own form: loss {value}"\n\n', "").replace(
    "return F * {value}", "return F * {value}  # loss {value}"
)


def test_a_run_whose_answers_repeat_shows_distinct_laws_and_tells_the_repeats(tmp_path):
    """Iteration 1 answers the same law thrice with other constants, and one broken answer;
    iteration 2's prompt shows that law once, tells the repeats and the failure."""
    answers = [
        REPEATING.format(value=3.0),
        REPEATING.format(value=2.0),
        "I think the law should be softer.",
        REPEATING.format(value=4.0),
    ] + [LAW.format(value=v) for v in (1.0, 5.0, 6.0)]
    cfg = config(iterations=2, top_k=3, exploit=1, explore=2)
    store = RunStore.create(tmp_path, cfg, {})
    Search(cfg, FakeTask(), Scripted(answers), LossInCode(), store).run()
    prompt = json.loads((store.path / "candidates/02-exploit-00/messages.json").read_text())
    user = prompt[-1]["content"]
    history = user.split("## What went wrong")[0]
    assert history.count("# loss 2.0") == 1 and "loss 3.0" not in history  # the form once, best
    assert "loss 100.0" in history  # and the seed: two distinct laws
    failures = user.split("## What went wrong")[1]
    assert "01-explore-00 is the same law as 01-exploit-00" in failures
    assert "01-explore-01 (invalid): the answer has no ```python code block" in failures
    parents = json.loads((store.path / "candidates/02-exploit-00/proposal.json").read_text())
    assert parents["parents"] == ["00-seed", "01-explore-00"]
    evaluation = json.loads((store.path / "candidates/01-explore-00/evaluation.json").read_text())
    assert evaluation["extras"]["same_form_as"] == "01-exploit-00"


class FakeEntityTask(FakeTask):
    """An entity task: its solutions are literal numbers, each a solution of its own."""

    kind = "entity"

    def seed_solution(self) -> str:
        return "guess = 100.0  # loss 100.0\n"


def test_an_entity_s_other_numbers_are_another_solution_not_a_repeat(tmp_path):
    answers = [f"```python\nguess = {v}  # loss {v}\n```" for v in (3.0, 2.0, 4.0, 1.0, 5.0, 6.0)]
    cfg = config(iterations=2, top_k=3, exploit=1, explore=2)
    store = RunStore.create(tmp_path, cfg, {})
    Search(cfg, FakeEntityTask(), Scripted(answers), LossInCode(), store).run()
    prompt = json.loads((store.path / "candidates/02-exploit-00/messages.json").read_text())
    user = prompt[-1]["content"]
    assert "What went wrong" not in user  # nothing repeated, nothing failed
    assert all(f"guess = {v}" in user for v in (2.0, 3.0, 4.0))  # three solutions shown
    for path in store.path.glob("candidates/*/evaluation.json"):
        assert "same_form_as" not in json.loads(path.read_text())["extras"]
