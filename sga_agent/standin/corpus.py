"""The stand-in's corpus: answers written the way model families write them, slips included.

``answers/index.json`` describes each answer file: its ``style`` (the model family it
imitates), ``task`` ("elastic" or "plastic"), ``readable`` (a person finds a complete class
``Physics`` in it), ``finish_reason``, an optional ``reasoning_content`` (sent apart from the
text, as reasoning models do), ``slip`` (what is off, "" when nothing is), ``tags`` (the slip
categories), ``expect`` (what a careful reader's evaluation gives: "evaluated", "runtime
error", "truncated" or "no code") and, for a variant or a repeat, ``same_as``.

:class:`CorpusScript` is a server script that answers each request with the next answer
fitting the request's task.
"""

from __future__ import annotations

import json
import threading
from dataclasses import dataclass
from importlib import resources
from typing import Any, Literal

from sga_agent.standin.server import Reply

TaskKind = Literal["elastic", "plastic"]
EXPECTATIONS = ("evaluated", "runtime error", "truncated", "no code")
#: The rule that names what ``forward`` returns, in each kind of task's prompt (lowercase).
PLASTIC_RULE = "returns the corrected deformation gradient"
ELASTIC_RULE = "returns the kirchhoff stress"
#: Words only the plastic tasks' prompts use (they ask for the corrected F), and words only
#: the elastic task's prompt uses (it asks for the Kirchhoff stress tau = P F^T).
PLASTIC_WORDS = ("corrected deformation gradient", "return mapping")
ELASTIC_WORDS = ("kirchhoff stress",)


@dataclass(frozen=True)
class Answer:
    """One corpus answer: its index entry and its text."""

    file: str
    style: str
    task: TaskKind
    readable: bool
    finish_reason: str
    slip: str
    expect: str
    text: str
    tags: tuple[str, ...] = ()
    reasoning_content: str | None = None
    same_as: str | None = None

    def reply(self) -> Reply:
        """The answer as a one-choice server reply."""
        return Reply(
            texts=self.text,
            finish_reason=self.finish_reason,
            reasoning_content=self.reasoning_content,
        )


def load_index() -> list[dict[str, Any]]:
    """The entries of ``answers/index.json``, in order."""
    folder = resources.files(__package__) / "answers"
    return json.loads((folder / "index.json").read_text(encoding="utf-8"))


def load_corpus() -> list[Answer]:
    """Every answer of the corpus, text included, in index order."""
    folder = resources.files(__package__) / "answers"
    answers = []
    for entry in load_index():
        text = (folder / entry["file"]).read_text(encoding="utf-8")
        fields = {**entry, "tags": tuple(entry.get("tags", ()))}
        answers.append(Answer(text=text, **fields))
    return answers


def task_of(body: dict[str, Any]) -> TaskKind:
    """Which task a chat request is for, from its messages' wording (elastic when unclear).

    The rule saying what ``forward`` returns decides; without it, the more frequent of the
    task-specific words.
    """
    text = " ".join(str(m.get("content", "")) for m in body.get("messages", [])).lower()
    text = " ".join(text.replace("`", "").split())
    if (PLASTIC_RULE in text) != (ELASTIC_RULE in text):
        return "plastic" if PLASTIC_RULE in text else "elastic"
    plastic = sum(text.count(words) for words in PLASTIC_WORDS)
    elastic = sum(text.count(words) for words in ELASTIC_WORDS)
    return "plastic" if plastic > elastic else "elastic"


class CorpusScript:
    """A server script: each choice gets the next answer of the request's task, in order.

    Parameters
    ----------
    answers : list of Answer, optional
        The answers to cycle through (default: the whole corpus).
    """

    def __init__(self, answers: list[Answer] | None = None) -> None:
        answers = load_corpus() if answers is None else answers
        self.answers: dict[str, list[Answer]] = {
            task: [a for a in answers if a.task == task] for task in ("elastic", "plastic")
        }
        self._next = {task: 0 for task in self.answers}
        self._lock = threading.Lock()

    def take(self, task: TaskKind) -> Answer:
        """The next answer for ``task``, cycling through its answers."""
        pool = self.answers[task]
        if not pool:
            raise ValueError(f"the corpus has no {task} answer")
        with self._lock:
            answer = pool[self._next[task] % len(pool)]
            self._next[task] += 1
        return answer

    def __call__(self, body: dict[str, Any]) -> Reply:
        task = task_of(body)
        chosen = [self.take(task) for _ in range(int(body.get("n") or 1))]
        thoughts = [a.reasoning_content or "" for a in chosen]
        return Reply(
            texts=[a.text for a in chosen],
            finish_reason=[a.finish_reason for a in chosen],
            reasoning_content=thoughts if any(thoughts) else None,
        )
