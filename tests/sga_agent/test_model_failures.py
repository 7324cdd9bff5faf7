"""What real providers do to a request, through the real litellm client and the stand-in
server: no choices, a body that is not JSON, rate limits, cut-off answers, reasoning sent
apart, silence; and the one-word request a search sends before it starts."""

from __future__ import annotations

import time
from typing import Any

import pytest
from click.testing import CliRunner

from sga_agent.cli import main
from sga_agent.proposers.base import ProposerError
from sga_agent.proposers.litellm_backbone import PING_TOKENS, import_litellm
from sga_agent.standin import Reply, ScriptedOpenAIServer
from tests.sga_agent.test_proposers import KEY, MESSAGES, proposer


@pytest.fixture(autouse=True)
def api_key(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("OPENAI_API_KEY", KEY)


@pytest.fixture(scope="module", autouse=True)
def litellm() -> Any:
    return import_litellm()


@pytest.mark.parametrize("failure", [Reply.empty(), Reply.malformed(), Reply.error(429)])
def test_an_empty_malformed_or_rate_limited_answer_is_retried(failure):
    with ScriptedOpenAIServer([failure, "the answer"]) as server:
        sleeps: list[float] = []
        backbone = proposer("openai/test-model", api_base=server.url, sleeps=sleeps, backoff_s=0)
        (answer,) = backbone.sample(MESSAGES, 0.5, 1)
    assert answer.text == "the answer" and len(sleeps) == 1
    assert answer.finish_reason == "stop"


def test_empty_answers_that_outlast_the_retries_stop_with_the_cause():
    with ScriptedOpenAIServer([Reply.empty()] * 3) as server:
        backbone = proposer(
            "openai/test-model", api_base=server.url, sleeps=[], backoff_s=0, max_retries=2
        )
        with pytest.raises(ProposerError, match="after 3 attempts.*answered with no choices"):
            backbone.sample(MESSAGES, 0.5, 1)


def test_a_cut_off_answer_is_asked_again_with_twice_the_room():
    cut = Reply("### Code\n```python\nclass Physics", finish_reason="length", completion_tokens=900)
    whole = Reply("### Code\n```python\nx = 1\n```", completion_tokens=40, prompt_tokens=100)
    with ScriptedOpenAIServer([cut, whole]) as server:
        backbone = proposer("openai/test-model", api_base=server.url, price_per_million=(1, 10))
        (answer,) = backbone.sample(MESSAGES, 0.5, 1)
        requests = server.requests
    assert answer.text.endswith("```") and answer.finish_reason == "stop"
    assert answer.truncated_before == 1
    assert requests[1]["max_tokens"] == 2 * 1024  # at least twice 1024, twice what was cut
    assert answer.completion_tokens == 940
    assert answer.cost_usd == pytest.approx((answer.prompt_tokens * 1 + 940 * 10) / 1e6)


def test_a_cut_off_answer_is_kept_when_asking_again_is_cut_off_too():
    cut = Reply("never finished", finish_reason="length", completion_tokens=3000)
    with ScriptedOpenAIServer([cut, cut]) as server:
        backbone = proposer("openai/test-model", api_base=server.url)
        (answer,) = backbone.sample(MESSAGES, 0.5, 1)
        assert server.requests[1]["max_tokens"] == 6000
    assert answer.finish_reason == "length" and answer.truncated_before == 1


def test_the_provider_s_reasoning_is_kept_with_the_answer():
    reply = Reply(["a", "b"], reasoning_content=["first thought", "second thought"])
    with ScriptedOpenAIServer([reply]) as server:
        backbone = proposer("openai/test-model", api_base=server.url)
        answers = backbone.sample(MESSAGES, 0.5, 2)
    assert [(a.text, a.reasoning) for a in answers] == [
        ("a", "first thought"),
        ("b", "second thought"),
    ]


def test_the_one_word_request_is_short_and_a_silent_provider_fails_it_fast():
    with ScriptedOpenAIServer(["ready"]) as server:
        proposer("openai/test-model", api_base=server.url).check_reachable()
        assert server.requests[0]["max_tokens"] == PING_TOKENS
    with ScriptedOpenAIServer(lambda body: Reply.hang()) as server:
        sleeps: list[float] = []
        silent = proposer(
            "openai/test-model", api_base=server.url, sleeps=sleeps, timeout_s=0.5, max_retries=1
        )
        started = time.monotonic()
        with pytest.raises(ProposerError, match="did not answer within 0.5 s") as raised:
            silent.check_reachable()
        assert time.monotonic() - started < 5 and raised.value.transient


def test_a_search_whose_provider_never_answers_ends_in_seconds_with_no_run_folder(tmp_path):
    with ScriptedOpenAIServer(lambda body: Reply.hang()) as server:
        started = time.monotonic()
        result = CliRunner().invoke(
            main,
            ["search", "--task", "elastic", "--model", "openai/test-model", "--api-base",
             server.url, "--request-timeout", "1", "--retries", "1", "--out-dir", str(tmp_path)],
        )  # fmt: skip
        seconds = time.monotonic() - started
    assert result.exit_code == 1, result.output
    assert seconds < 30
    assert "openai/test-model did not answer within 1 s" in result.output
    assert "no run was started" in result.output
    assert not any(tmp_path.iterdir())
