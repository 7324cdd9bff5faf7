"""The stand-in provider: the scripted server through the real litellm client, and its corpus."""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import time
import urllib.request
from collections import Counter
from collections.abc import Iterator
from importlib import resources
from typing import Any

import pytest

from sga_agent.proposers.litellm_backbone import import_litellm
from sga_agent.standin import (
    Answer,
    CorpusScript,
    Reply,
    ScriptedOpenAIServer,
    load_corpus,
    load_index,
    task_of,
)
from sga_agent.standin.__main__ import make_script
from sga_agent.standin.corpus import EXPECTATIONS
from tasks.constitutive import prompt_text

MESSAGES = [{"role": "user", "content": "Improve the law below."}]
#: Slip categories the corpus must cover (the ``tags`` of its index).
CATEGORIES = {
    "clean", "missing-import", "usage-same-block", "usage-separate-block",
    "class-not-last-block", "old-and-new-law", "harmless-import", "integer-default",
    "torch-trace", "dtype-mix", "tensor-branch", "truncated", "no-code", "refusal", "py-fence",
    "untagged-fence", "odd-indentation", "same-law-other-constants", "exact-repeat",
    "think-in-content", "reasoning-content",
}  # fmt: skip


@pytest.fixture(scope="module")
def litellm() -> Any:
    """litellm, imported once (seconds) rather than inside the first test."""
    return import_litellm()


@pytest.fixture(autouse=True)
def api_key(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("OPENAI_API_KEY", "anything")


def ask(litellm: Any, server: ScriptedOpenAIServer, **kwargs: Any) -> Any:
    """One chat completion from ``server`` through litellm, without retries."""
    settings = {"messages": MESSAGES, "timeout": 5.0, "max_retries": 0, **kwargs}
    return litellm.completion(model="openai/standin", api_base=server.url, **settings)


def prompt(context: str, rules: str, template: str) -> dict[str, Any]:
    """A request body shaped like a task's prompt."""
    user = f"## Task\n\n{context}\n\n{rules}\n\n```python\n{template}```"
    return {"messages": [{"role": "system", "content": prompt_text.ROLE},
                         {"role": "user", "content": user}]}  # fmt: skip


ELASTIC_PROMPT = prompt(
    prompt_text.ELASTIC_CONTEXT, prompt_text.ELASTIC_RULES, prompt_text.ELASTIC_TEMPLATE
)
PLASTIC_PROMPT = prompt(
    prompt_text.PLASTIC_CONTEXT, prompt_text.PLASTIC_RULES, prompt_text.PLASTIC_TEMPLATE
)


# --- what real providers send, through litellm --------------------------------------------------


def test_finish_reason_and_reasoning_reach_each_choice(litellm: Any) -> None:
    reply = Reply(
        texts=["complete", "cut"],
        finish_reason=["stop", "length"],
        reasoning_content=["thought one", "thought two more"],
    )
    with ScriptedOpenAIServer([reply]) as server:
        response = ask(litellm, server, n=2)
    choices = response.choices
    assert [c.message.content for c in choices] == ["complete", "cut"]
    assert [c.finish_reason for c in choices] == ["stop", "length"]
    assert [c.message.reasoning_content for c in choices] == ["thought one", "thought two more"]
    assert response.usage.completion_tokens == 2 + 5  # answers and reasoning, in words
    assert response.usage.completion_tokens_details.reasoning_tokens == 5


def test_a_reply_without_reasoning_sends_none(litellm: Any) -> None:
    with ScriptedOpenAIServer(["plain"]) as server:
        choice = ask(litellm, server).choices[0]
    assert choice.finish_reason == "stop"
    assert getattr(choice.message, "reasoning_content", None) is None


def test_usage_counts_words_unless_the_reply_sets_it(litellm: Any) -> None:
    with ScriptedOpenAIServer(
        ["one two three", Reply("x", prompt_tokens=1200, completion_tokens=3400)]
    ) as server:
        counted = ask(litellm, server).usage
        given = ask(litellm, server).usage
    assert (counted.prompt_tokens, counted.completion_tokens) == (4, 3)
    assert (given.prompt_tokens, given.completion_tokens, given.total_tokens) == (1200, 3400, 4600)


def test_no_choices_come_back_as_an_empty_list(litellm: Any) -> None:
    """litellm does not raise on ``"choices": []``: the caller must check."""
    with ScriptedOpenAIServer([Reply.empty()]) as server:
        response = ask(litellm, server, n=2)
    assert response.choices == []
    assert response.usage.completion_tokens == 0


def test_a_body_that_is_not_json_raises_an_internal_server_error(litellm: Any) -> None:
    with (
        ScriptedOpenAIServer([Reply.malformed()]) as server,
        pytest.raises(litellm.InternalServerError, match="invalid response") as raised,
    ):
        ask(litellm, server)
    assert "502 Bad Gateway" in str(raised.value)  # the page is quoted in the message


def test_a_proxy_error_page_with_its_status_raises_by_status(litellm: Any) -> None:
    with (
        ScriptedOpenAIServer([Reply.malformed(status=502)]) as server,
        pytest.raises(litellm.BadGatewayError),
    ):
        ask(litellm, server)


def test_a_hanging_server_makes_the_client_time_out(litellm: Any) -> None:
    with ScriptedOpenAIServer([Reply.hang()]) as server:
        start = time.monotonic()
        with pytest.raises(litellm.Timeout):
            ask(litellm, server, timeout=0.3)
        assert time.monotonic() - start < 3.0
        assert len(server.requests) == 1


def test_closing_the_server_ends_a_hanging_request_without_an_answer(litellm: Any) -> None:
    """Closing releases the request; litellm reports the dropped connection as a 500."""
    errors: list[Exception] = []
    server = ScriptedOpenAIServer([Reply.hang()]).__enter__()

    def call() -> None:
        try:
            ask(litellm, server, timeout=30.0)
        except Exception as error:
            errors.append(error)

    client = threading.Thread(target=call)
    client.start()
    deadline = time.monotonic() + 10
    while not server.requests and time.monotonic() < deadline:
        time.sleep(0.01)
    start = time.monotonic()
    server.__exit__(None, None, None)
    client.join(timeout=10)
    assert time.monotonic() - start < 5.0 and not client.is_alive()
    (error,) = errors
    assert isinstance(error, litellm.InternalServerError) and "Connection error" in str(error)


def test_an_error_reply_keeps_its_status(litellm: Any) -> None:
    with (
        ScriptedOpenAIServer([Reply.error(503, "warming up")]) as server,
        pytest.raises(litellm.ServiceUnavailableError, match="warming up"),
    ):
        ask(litellm, server)


# --- the corpus ---------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def corpus() -> list[Answer]:
    return load_corpus()


def test_the_index_lists_every_answer_file_and_only_them(corpus: list[Answer]) -> None:
    folder = resources.files("sga_agent.standin") / "answers"
    files = {p.name for p in folder.iterdir() if p.name.endswith(".md")}
    assert sorted(files) == sorted(a.file for a in corpus)
    assert len(corpus) >= 36 and sum(a.readable for a in corpus) >= 30
    for answer in corpus:
        number, style_and_slip = answer.file.split("-", 1)
        assert number.isdigit() and style_and_slip.startswith(answer.style + "-"), answer.file


def test_the_index_entries_are_consistent(corpus: list[Answer]) -> None:
    styles = Counter(a.style for a in corpus)
    assert len(styles) >= 8 and min(styles.values()) >= 2, styles
    assert {a.task for a in corpus} == {"elastic", "plastic"}
    assert {tag for a in corpus for tag in a.tags} >= CATEGORIES
    assert sum("clean" in a.tags for a in corpus) >= 8
    for a in corpus:
        assert a.expect in EXPECTATIONS and a.finish_reason in ("stop", "length"), a.file
        assert (a.expect == "truncated") == (a.finish_reason == "length"), a.file
        assert a.readable == (a.expect in ("evaluated", "runtime error")), a.file
        assert (a.slip == "") == (set(a.tags) <= {"clean", "reasoning-content"}), a.file
        assert ("class Physics" in a.text) == (a.expect != "no code"), a.file
        assert ("reasoning-content" in a.tags) == bool(a.reasoning_content), a.file


def test_truncated_answers_stop_inside_an_open_code_block(corpus: list[Answer]) -> None:
    for a in corpus:
        fences = [line for line in a.text.splitlines() if line.strip().startswith("```")]
        assert (len(fences) % 2 == 1) == (a.expect == "truncated"), a.file
        if a.expect == "truncated":
            assert not a.text.endswith("\n"), a.file  # cut mid-line


def test_repeats_are_identical_and_variants_are_not(corpus: list[Answer]) -> None:
    by_file = {a.file: a for a in corpus}
    for a in corpus:
        if "exact-repeat" in a.tags:
            assert a.text == by_file[a.same_as].text
        if "same-law-other-constants" in a.tags:
            original = by_file[a.same_as]
            assert a.text != original.text and a.task == original.task


def test_the_index_is_plain_json_data() -> None:
    entries = load_index()
    assert all(isinstance(entry, dict) and entry["file"].endswith(".md") for entry in entries)
    json.dumps(entries)


# --- the corpus script --------------------------------------------------------------------------


def test_prompts_are_told_apart_by_what_forward_returns() -> None:
    assert task_of(ELASTIC_PROMPT) == "elastic"
    assert task_of(PLASTIC_PROMPT) == "plastic"
    assert task_of({"messages": MESSAGES}) == "elastic"


def test_the_script_answers_each_task_from_its_own_answers_in_order(
    corpus: list[Answer],
) -> None:
    script = CorpusScript(corpus)
    elastic = [a for a in corpus if a.task == "elastic"]
    plastic = [a for a in corpus if a.task == "plastic"]
    first = script({**ELASTIC_PROMPT, "n": 2})
    second = script(PLASTIC_PROMPT)
    third = script(ELASTIC_PROMPT)
    assert first.texts == [elastic[0].text, elastic[1].text]
    assert second.texts == [plastic[0].text]
    assert third.texts == [elastic[2].text]
    for _ in range(len(elastic) - 3):
        script(ELASTIC_PROMPT)
    assert script(ELASTIC_PROMPT).texts == [elastic[0].text]  # cycles


def test_the_corpus_through_litellm_keeps_finish_reason_and_reasoning(
    litellm: Any, corpus: list[Answer]
) -> None:
    plastic = [a for a in corpus if a.task == "plastic"]
    with ScriptedOpenAIServer(CorpusScript(corpus)) as server:
        response = ask(litellm, server, messages=PLASTIC_PROMPT["messages"], n=len(plastic))
    assert [c.message.content for c in response.choices] == [a.text for a in plastic]
    assert [c.finish_reason for c in response.choices] == [a.finish_reason for a in plastic]
    thoughts = [c.message.reasoning_content or None for c in response.choices]
    assert thoughts == [a.reasoning_content for a in plastic]


# --- the command line ---------------------------------------------------------------------------


def test_modes_take_turns() -> None:
    script = make_script(["down", "corpus"])
    assert script(ELASTIC_PROMPT) == Reply.error(503, "The server is overloaded or not ready yet.")
    assert isinstance(script(ELASTIC_PROMPT), Reply)
    assert script(ELASTIC_PROMPT).status == 503


@pytest.fixture
def served() -> Iterator[str]:
    """``python -m sga_agent.standin --port 0`` running; yields the URL it printed."""
    process = subprocess.Popen(
        [sys.executable, "-m", "sga_agent.standin", "--port", "0", "--mode", "corpus"],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert process.stdout is not None
        yield process.stdout.readline().strip()
    finally:
        process.terminate()
        process.wait(timeout=10)


def test_the_command_prints_its_url_and_serves_the_corpus(served: str) -> None:
    assert served.startswith("http://127.0.0.1:") and served.endswith("/v1")
    request = urllib.request.Request(
        served + "/chat/completions",
        data=json.dumps({"model": "standin", **PLASTIC_PROMPT}).encode(),
        headers={"Content-Type": "application/json"},
    )
    with urllib.request.urlopen(request, timeout=10) as response:
        body = json.load(response)
    first = next(a for a in load_corpus() if a.task == "plastic")
    assert body["choices"][0]["message"]["content"] == first.text


def test_an_unknown_mode_is_a_usage_error() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "sga_agent.standin", "--mode", "corpus,slow"],
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert result.returncode == 2 and "unknown mode slow" in result.stderr
