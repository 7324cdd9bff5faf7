"""Prompt assembly: message layout, history order, filled templates, kind-specific formats."""

import math
import re

import pytest

from sga_agent.prompting import Shown, build_messages, worst_first
from sga_agent.registry import load_task, task_names
from sga_agent.task import PromptParts
from tests.tasks.observed.conftest import ready_task

PARTS = PromptParts(
    role="ROLE-SENTENCE",
    context="CONTEXT-PARAGRAPH",
    template="class Physics:  # TEMPLATE-CODE\n    pass",
    requirements="1. REQUIREMENT-RULE",
)


def shown(name: str, loss: float) -> Shown:
    return Shown(code=f"code_{name} = {{'a': 1}}", feedback=f"feedback of {name}", loss=loss)


def user_text(kind: str, parts: PromptParts, history: list[Shown]) -> str:
    messages = build_messages(kind, parts, history)
    assert [m["role"] for m in messages] == ["system", "user"]
    return messages[1]["content"]


def test_history_is_shown_worst_first_best_last():
    history = [
        shown("mid", 0.5),
        shown("inf", math.inf),
        shown("best", 0.1),
        shown("nan", math.nan),
        shown("worst", 2.0),
    ]
    text = user_text("equation", PARTS, history)
    order = ["inf", "nan", "worst", "mid", "best"]  # unscored first, in the caller's order
    positions = [text.index(f"code_{name} =") for name in order]
    assert positions == sorted(positions)
    for index, name in enumerate(order, start=1):
        block = text.split(f"### Iteration {index}\n", 1)[1]
        assert block.lstrip().startswith(f"```python\ncode_{name} =")
        assert f"feedback of {name}" in block.split("### Iteration", 1)[0]
    assert "### Iteration 6" not in text
    assert "Iteration 5 is the best" in text


def test_worst_first_is_stable_for_equal_losses():
    history = [shown("a", 1.0), shown("b", 1.0), shown("c", math.inf), shown("d", math.inf)]
    assert [s.code[5] for s in worst_first(history)] == ["c", "d", "a", "b"]


def test_user_message_order_context_history_format():
    text = user_text("equation", PARTS, [shown("one", 1.0)])
    marks = [
        "CONTEXT-PARAGRAPH",
        "### Iteration 1",
        "code_one =",
        "feedback of one",
        "## Format requirements",
        "REQUIREMENT-RULE",
        "TEMPLATE-CODE",
        '"### Analysis"',
        '"#### Iteration N"',
        '"### Step-by-Step Plan"',
        '"### Code"',
    ]
    positions = [text.index(mark) for mark in marks]
    assert positions == sorted(positions)


def test_system_message_carries_the_role():
    system = build_messages("equation", PARTS, [])[0]["content"]
    assert system.startswith("ROLE-SENTENCE\n")


def test_without_history_no_iteration_is_shown():
    text = user_text("equation", PARTS, [])
    assert "Iteration 1" not in text and "Earlier solutions" not in text
    assert "CONTEXT-PARAGRAPH" in text and "TEMPLATE-CODE" in text


@pytest.mark.parametrize("name", task_names())
def test_real_task_prompts_are_complete(name, tmp_path):
    task = ready_task(name, tmp_path)
    parts = task.prompt_parts()
    history = [Shown(task.seed_solution(), "loss 1.0", 1.0), Shown("broken", "invalid", math.inf)]
    messages = build_messages(task.kind, parts, history)
    system, user = (m["content"] for m in messages)
    for text in (system, user):
        assert "${" not in text
        assert not re.search(r"\$[a-z_]+\b", text), "a template placeholder was left unfilled"
    assert parts.role.strip() in system
    for piece in (parts.context, parts.template, parts.requirements, task.seed_solution()):
        assert piece.strip() in user


def test_molecule_tasks_use_the_entity_format():
    task = load_task("homo")
    assert task.kind == "entity"
    system, user = (m["content"] for m in build_messages("entity", task.prompt_parts(), []))
    law_system, law_user = (m["content"] for m in build_messages("equation", PARTS, []))
    assert "Count the atoms" in user and "Count the atoms" not in law_user
    assert "never run" in system and "never run" not in law_system
    assert "continuous parameters" in law_user


def test_unknown_kind_is_refused():
    with pytest.raises(ValueError, match="kind must be one of"):
        build_messages("formula", PARTS, [])
