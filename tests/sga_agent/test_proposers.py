"""The litellm backbone: litellm's own mocks for errors and prices, a local server for HTTP.

Nothing here waits for real: the proposer's sleep is a recorder. The key in OPENAI_API_KEY is a
dummy, and every error path checks that it appears neither in the error nor in the logs.
"""

from __future__ import annotations

import logging
import os
import socket
import time
from collections.abc import Iterator
from itertools import count
from typing import Any

import pytest

from sga_agent.config import SearchConfig
from sga_agent.proposers import (
    BackboneSettings,
    BackboneSettingsError,
    BuiltinAdapter,
    LiteLLMProposer,
    Proposal,
    ProposalRequest,
    Proposer,
    ProposerError,
    ReplayProposer,
)
from sga_agent.proposers.litellm_backbone import (
    MAX_BACKOFF_S,
    NO_PRICE_NOTE,
    PROVIDER_KEYS,
    backoff_wait,
    import_litellm,
    missing_keys,
)
from sga_agent.proposers.redact import RedactingFilter, redact
from sga_agent.registry import load_task
from sga_agent.run_store import RunStore, RunStoreError
from sga_agent.runner import make_proposer
from sga_agent.standin import Reply, ScriptedOpenAIServer

KEY = "sk-test-not-a-real-key"
MESSAGES = [
    {"role": "system", "content": "You propose constitutive laws."},
    {"role": "user", "content": "Improve the law below."},
]


@pytest.fixture(scope="module")
def litellm() -> Any:
    """litellm, imported once (seconds) rather than inside the first test."""
    return import_litellm()


@pytest.fixture(autouse=True)
def api_key(monkeypatch: pytest.MonkeyPatch) -> str:
    monkeypatch.setenv("OPENAI_API_KEY", KEY)
    return KEY


class Mocked:
    """A ``completion`` that runs litellm's real mock path with one scripted answer per call.

    Each entry is a ``mock_response`` (a text, "litellm.RateLimitError", an exception) or a
    dict of extra mock arguments such as ``{"mock_timeout": True}``.
    """

    def __init__(self, litellm: Any, *script: Any) -> None:
        self._litellm = litellm
        self._script = iter(script)
        self.calls: list[dict[str, Any]] = []

    def __call__(self, **kwargs: Any) -> Any:
        self.calls.append(kwargs)
        entry = next(self._script)
        mock = entry if isinstance(entry, dict) else {"mock_response": entry}
        return self._litellm.completion(**kwargs, **mock)


def proposer(
    model: str = "openai/gpt-4o",
    completion: Any = None,
    sleeps: list[float] | None = None,
    **settings: Any,
) -> LiteLLMProposer:
    sleep = sleeps.append if sleeps is not None else _no_sleep
    return LiteLLMProposer(BackboneSettings(model, **settings), completion=completion, sleep=sleep)


def _no_sleep(seconds: float) -> None:
    raise AssertionError(f"unexpected wait of {seconds} s")


def assert_no_key(text: str) -> None:
    assert KEY not in text
    assert "not-a-real" not in text


# --- accounting (litellm mock_response and its local price map) -------------------------------


def test_n_choices_share_the_tokens_and_price_of_their_request(litellm: Any) -> None:
    mocked = Mocked(litellm, "### Code\nclass Physics: ...")
    proposals = proposer(completion=mocked, use_n=True).sample(MESSAGES, 0.5, 3)
    assert [p.text for p in proposals] == ["### Code\nclass Physics: ..."] * 3
    assert mocked.calls[0]["n"] == 3 and mocked.calls[0]["temperature"] == 0.5
    response = litellm.completion(model="openai/gpt-4o", messages=MESSAGES, mock_response="x", n=3)
    price = litellm.completion_cost(completion_response=response)
    assert price > 0
    assert sum(p.cost_usd for p in proposals) == pytest.approx(price)
    assert sum(p.prompt_tokens for p in proposals) == response.usage.prompt_tokens
    assert sum(p.completion_tokens for p in proposals) == response.usage.completion_tokens
    assert {(p.model, p.temperature, p.cost_note) for p in proposals} == {
        ("openai/gpt-4o", 0.5, "")
    }


def test_a_model_without_a_price_costs_zero_with_a_note(litellm: Any) -> None:
    mocked = Mocked(litellm, "hello")
    (proposal,) = proposer("openai/no-such-model-xyz", completion=mocked).sample(MESSAGES, 1.0, 1)
    assert proposal.cost_usd == 0.0
    assert proposal.cost_note == NO_PRICE_NOTE
    assert proposal.prompt_tokens > 0 and proposal.completion_tokens > 0


def test_proposals_round_trip_through_a_dict() -> None:
    proposal = Proposal("text", "openai/gpt-4o", 0.5, 10, 20, 0.01, "", 1.5)
    assert Proposal.from_dict(proposal.to_dict()) == proposal


# --- retries (litellm mock errors) -------------------------------------------------------------


@pytest.mark.parametrize(
    "failure",
    ["litellm.RateLimitError", "litellm.InternalServerError"],
    ids=["rate-limit", "server-error"],
)
def test_transient_errors_are_retried_with_growing_waits(litellm: Any, failure: str) -> None:
    mocked = Mocked(litellm, failure, failure, failure, "finally")
    sleeps: list[float] = []
    (proposal,) = proposer(completion=mocked, sleeps=sleeps, backoff_s=2.0).sample(MESSAGES, 1.0, 1)
    assert proposal.text == "finally"
    assert len(mocked.calls) == 4
    assert [1 <= sleeps[0] <= 2, 2 <= sleeps[1] <= 4, 4 <= sleeps[2] <= 8] == [True] * 3


def test_other_5xx_statuses_are_retried(litellm: Any) -> None:
    unavailable = Exception("overloaded")
    unavailable.status_code = 503  # litellm's mock turns it into an error with this status
    mocked = Mocked(litellm, unavailable, "ok")
    sleeps: list[float] = []
    assert proposer(completion=mocked, sleeps=sleeps).sample(MESSAGES, 1.0, 1)[0].text == "ok"
    assert len(sleeps) == 1


def test_retries_give_up_with_the_count_and_cause(litellm: Any) -> None:
    mocked = Mocked(litellm, *["litellm.RateLimitError"] * 3)
    sleeps: list[float] = []
    with pytest.raises(ProposerError, match="after 3 attempts.*RateLimitError"):
        proposer(completion=mocked, sleeps=sleeps, max_retries=2).sample(MESSAGES, 1.0, 1)
    assert len(sleeps) == 2


def test_giving_up_after_retries_is_transient_and_a_request_error_is_not(litellm: Any) -> None:
    mocked = Mocked(litellm, "litellm.RateLimitError")
    with pytest.raises(ProposerError) as raised:
        proposer(completion=mocked, max_retries=0).sample(MESSAGES, 1.0, 1)
    assert raised.value.transient
    bad = litellm.BadRequestError(message="no", llm_provider="openai", model="gpt-4o")
    with pytest.raises(ProposerError) as raised:
        proposer(completion=Mocked(litellm, bad)).sample(MESSAGES, 1.0, 1)
    assert not raised.value.transient


def test_nothing_listening_fails_at_once_naming_the_fix(litellm: Any) -> None:
    """A closed port is not retried (no wait) and is no transient failure."""
    backbone = proposer("hosted_vllm/some-model", api_base=closed_port_url())
    with pytest.raises(ProposerError) as raised:
        backbone.sample(MESSAGES, 1.0, 2)
    assert not raised.value.transient
    assert "connection refused" in str(raised.value)
    assert "start the server or correct --api-base" in str(raised.value)


def closed_port_url() -> str:
    """The URL of a local port nothing listens on."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    return f"http://127.0.0.1:{port}/v1"


def test_waits_double_up_to_the_cap() -> None:
    ceilings = [min(MAX_BACKOFF_S, 2.0 * 2**retry) for retry in range(10)]
    waits = [backoff_wait(retry, 2.0) for retry in range(10)]
    assert all(c / 2 <= w <= c for w, c in zip(waits, ceilings, strict=True))
    assert max(waits) <= MAX_BACKOFF_S


def test_a_timeout_is_retried_then_reported_with_the_fix(litellm: Any) -> None:
    mocked = Mocked(litellm, {"mock_timeout": True}, {"mock_timeout": True})
    sleeps: list[float] = []
    slow = proposer(completion=mocked, sleeps=sleeps, timeout_s=0.01, max_retries=1)
    with pytest.raises(ProposerError, match="did not answer within 0.01 s.*--request-timeout"):
        slow.sample(MESSAGES, 1.0, 1)
    assert len(mocked.calls) == 2 and len(sleeps) == 1
    assert mocked.calls[0]["timeout"] == 0.01


def test_a_rejected_key_fails_at_once_without_showing_it(
    litellm: Any, caplog: pytest.LogCaptureFixture
) -> None:
    rejected = litellm.AuthenticationError(
        message=f"Incorrect API key provided: {KEY}", llm_provider="openai", model="gpt-4o"
    )
    mocked = Mocked(litellm, rejected)
    with caplog.at_level(logging.DEBUG), pytest.raises(ProposerError) as raised:
        proposer(completion=mocked).sample(MESSAGES, 1.0, 1)
    assert "authentication failed for openai/gpt-4o" in str(raised.value)
    assert raised.value.__cause__ is None and raised.value.__suppress_context__
    assert len(mocked.calls) == 1
    assert_no_key(str(raised.value))
    assert_no_key(caplog.text)


def test_a_missing_key_names_the_variable_to_set(
    litellm: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv("OPENAI_API_KEY")
    mocked = Mocked(litellm, "litellm.InternalServerError")
    with pytest.raises(ProposerError, match="no API key for openai/gpt-4o: set OPENAI_API_KEY"):
        proposer(completion=mocked).sample(MESSAGES, 1.0, 1)
    assert len(mocked.calls) == 1


@pytest.mark.parametrize("provider", sorted(PROVIDER_KEYS))
def test_the_key_table_agrees_with_litellm(
    litellm: Any, monkeypatch: pytest.MonkeyPatch, provider: str
) -> None:
    """Keys checked without litellm are those litellm itself would ask for."""
    for name in [name for name in os.environ if name.endswith("_API_KEY")]:
        monkeypatch.delenv(name)
    model = f"{provider}/some-model"

    def litellms() -> list[str]:
        missing = litellm.validate_environment(model=model)["missing_keys"]
        return [name for name in missing if name.endswith("_API_KEY")]

    assert missing_keys(model) == litellms() == list(PROVIDER_KEYS[provider])
    for name in PROVIDER_KEYS[provider]:
        monkeypatch.setenv(name, "set")
        assert missing_keys(model) == litellms() == []
        monkeypatch.delenv(name)


@pytest.mark.parametrize(
    ("error", "message"),
    [
        ("NotFoundError", "was not found: check the model name"),
        ("BadRequestError", "rejected the request"),
    ],
)
def test_request_errors_are_not_retried(litellm: Any, error: str, message: str) -> None:
    exception = getattr(litellm, error)(message="no", llm_provider="openai", model="gpt-4o")
    mocked = Mocked(litellm, exception)
    with pytest.raises(ProposerError, match=message):
        proposer(completion=mocked).sample(MESSAGES, 1.0, 1)
    assert len(mocked.calls) == 1


# --- batches -----------------------------------------------------------------------------------


def test_some_failures_return_the_rest_and_all_failures_raise(litellm: Any) -> None:
    bad = litellm.BadRequestError(message="no", llm_provider="openai", model="gpt-4o")
    mocked = Mocked(litellm, "a", bad, "b")
    some = proposer(completion=mocked, use_n=False, concurrency=1).sample(MESSAGES, 1.0, 3)
    assert sorted(p.text for p in some) == ["a", "b"]
    mocked = Mocked(litellm, bad, bad)
    with pytest.raises(ProposerError, match="all 2 requests failed"):
        proposer(completion=mocked, use_n=False).sample(MESSAGES, 1.0, 2)


def test_choices_missing_from_an_n_request_are_topped_up(litellm: Any) -> None:
    def ignores_n(**kwargs: Any) -> Any:
        kwargs.pop("n", None)
        calls.append(kwargs)
        return litellm.completion(**kwargs, mock_response=f"answer {len(calls)}")

    calls: list[dict[str, Any]] = []
    proposals = proposer(completion=ignores_n, use_n=True).sample(MESSAGES, 0.5, 3)
    assert len(proposals) == 3 and len(calls) == 3


def test_n_is_used_for_providers_that_support_it(litellm: Any) -> None:
    assert proposer("openai/gpt-4o").use_n
    assert proposer("hosted_vllm/qwen", api_base="http://127.0.0.1:8000/v1").use_n
    assert not proposer("anthropic/claude-3-5-sonnet-20240620").use_n
    assert not proposer("mistral/mistral-large-latest").use_n
    assert proposer("openai/gpt-4o").sample(MESSAGES, 1.0, 0) == []


# --- settings and description ------------------------------------------------------------------


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"model": "gpt-4o"}, "needs a provider prefix.*openai/gpt-4o"),
        ({"model": "openai/gpt-4o", "api_base": "127.0.0.1:8000"}, "api_base must be an http"),
        ({"model": "openai/gpt-4o", "timeout_s": 0}, "timeout_s must be positive"),
        ({"model": "openai/gpt-4o", "max_retries": -1}, "max_retries must be >= 0"),
        ({"model": "openai/gpt-4o", "concurrency": 0}, "concurrency must be at least 1"),
        ({"model": "openai/gpt-4o", "max_tokens": 0}, "max_tokens must be at least 1"),
    ],
)
def test_bad_settings_name_the_parameter(settings: dict[str, Any], message: str) -> None:
    with pytest.raises(BackboneSettingsError, match=message):
        BackboneSettings(**settings)


def test_a_misspelt_provider_gets_a_suggestion(litellm: Any) -> None:
    with pytest.raises(BackboneSettingsError, match="unknown provider 'antropic'.*'anthropic'"):
        proposer("antropic/claude-3-5-sonnet-20240620")


def test_the_description_names_the_model_and_hides_url_credentials(litellm: Any) -> None:
    backbone = proposer("openai/local", api_base="http://user:hunter2@127.0.0.1:8000/v1")
    assert isinstance(backbone, Proposer)
    description = backbone.describe()
    assert description["name"] == backbone.name == "litellm:openai/local"
    assert description["api_base"] == "http://***@127.0.0.1:8000/v1"
    assert "hunter2" not in str(description) and KEY not in str(description)


def test_redact_masks_secret_environment_values_only() -> None:
    environ = {"MY_API_KEY": "abcdefgh12345", "HF_TOKEN": "hf_zzzzzzzzzz", "HOME": "/root/home"}
    text = "sent abcdefgh12345 and hf_zzzzzzzzzz from /root/home"
    assert redact(text, environ) == "sent *** and *** from /root/home"


def test_litellm_log_records_are_redacted(litellm: Any) -> None:
    (mask,) = [f for f in logging.getLogger("LiteLLM").filters if isinstance(f, RedactingFilter)]
    record = logging.LogRecord("LiteLLM", logging.DEBUG, "x.py", 1, "raw: %s", (KEY,), None)
    assert mask.filter(record) and record.getMessage() == "raw: ***"


# --- the real litellm client against a local OpenAI-compatible server --------------------------


@pytest.fixture
def numbered() -> Iterator[ScriptedOpenAIServer]:
    """A server answering every request with distinct numbered texts, one per choice."""
    numbers = count()

    def answer(body: dict[str, Any]) -> list[str]:
        return [f"answer {next(numbers)}" for _ in range(int(body.get("n") or 1))]

    with ScriptedOpenAIServer(answer) as server:
        yield server


def test_a_server_that_supports_n_gets_one_request(
    litellm: Any, numbered: ScriptedOpenAIServer
) -> None:
    backbone = proposer("openai/test-model", api_base=numbered.url)
    proposals = backbone.sample(MESSAGES, 0.5, 4)
    assert sorted(p.text for p in proposals) == [f"answer {i}" for i in range(4)]
    (request,) = numbered.requests
    assert (request["n"], request["temperature"], request["messages"]) == (4, 0.5, MESSAGES)
    words = sum(len(m["content"].split()) for m in MESSAGES)
    assert sum(p.prompt_tokens for p in proposals) == words
    assert sum(p.completion_tokens for p in proposals) == 8
    assert {(p.cost_usd, p.cost_note) for p in proposals} == {(0.0, NO_PRICE_NOTE)}


def test_without_n_each_sample_is_its_own_request(
    litellm: Any, numbered: ScriptedOpenAIServer
) -> None:
    backbone = proposer("openai/test-model", api_base=numbered.url, use_n=False, concurrency=3)
    proposals = backbone.sample(MESSAGES, 1.0, 5)
    assert sorted(p.text for p in proposals) == [f"answer {i}" for i in range(5)]
    assert len(numbered.requests) == 5
    assert all(r.get("n", 1) == 1 and r["temperature"] == 1.0 for r in numbered.requests)


def test_a_429_from_the_server_is_retried(litellm: Any) -> None:
    sleeps: list[float] = []
    with ScriptedOpenAIServer([Reply.error(429), Reply.error(500), ["ok", "fine"]]) as server:
        backbone = proposer("openai/test-model", api_base=server.url, sleeps=sleeps)
        proposals = backbone.sample(MESSAGES, 0.5, 2)
    assert [p.text for p in proposals] == ["ok", "fine"]
    assert len(server.requests) == 3 and len(sleeps) == 2


def test_a_slow_server_times_out(litellm: Any) -> None:
    with ScriptedOpenAIServer([Reply("late", delay_s=5.0)]) as server:
        backbone = proposer("openai/test-model", api_base=server.url, timeout_s=0.2, max_retries=0)
        start = time.monotonic()
        with pytest.raises(ProposerError, match="did not answer within 0.2 s"):
            backbone.sample(MESSAGES, 1.0, 1)
        assert time.monotonic() - start < 2.0


def test_a_key_echoed_by_the_server_is_hidden(
    litellm: Any, caplog: pytest.LogCaptureFixture
) -> None:
    echo = Reply.error(401, f"Incorrect API key provided: {KEY}")
    with ScriptedOpenAIServer([echo]) as server, caplog.at_level(logging.DEBUG):
        backbone = proposer("openai/test-model", api_base=server.url)
        with pytest.raises(ProposerError, match="authentication failed") as raised:
            backbone.sample(MESSAGES, 1.0, 1)
    assert "Incorrect API key provided: ***" in str(raised.value)
    assert_no_key(str(raised.value))
    assert_no_key(caplog.text)


def test_no_key_for_a_local_server_says_any_value_will_do(
    litellm: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv("OPENAI_API_KEY")
    with ScriptedOpenAIServer(["unused"]) as server:
        backbone = proposer("openai/test-model", api_base=server.url)
        with pytest.raises(ProposerError, match="set OPENAI_API_KEY .any value does"):
            backbone.sample(MESSAGES, 1.0, 1)
    assert server.requests == []


# --- one protocol: a request in, proposals out -------------------------------------------------


def test_a_request_builds_its_messages_once_and_only_when_read() -> None:
    built: list[int] = []

    def prompt() -> list[dict[str, str]]:
        built.append(1)
        return MESSAGES

    request = ProposalRequest(["01-exploit-00", "01-exploit-01"], 0.5, prompt=prompt)
    assert request.n == 2 and request.built_messages is None and not built
    assert request.messages() is request.messages() and built == [1]
    assert request.built_messages == MESSAGES
    assert ProposalRequest(["a"], 1.0, prompt=MESSAGES).messages() == MESSAGES


def test_the_litellm_proposer_answers_a_request_with_its_messages(litellm: Any) -> None:
    mocked = Mocked(litellm, "### Code\nclass Physics: ...")
    backbone = proposer(completion=mocked)
    (proposal,) = backbone.propose(ProposalRequest(["01-explore-00"], 0.9, prompt=lambda: MESSAGES))
    assert proposal.text == "### Code\nclass Physics: ..." and proposal.temperature == 0.9
    assert mocked.calls[0]["messages"] == MESSAGES and mocked.calls[0]["temperature"] == 0.9


def recorded_run(tmp_path: Any) -> RunStore:
    store = RunStore.create(tmp_path, SearchConfig(task="elastic", proposer="x/y"), {})
    for candidate, text in (("01-exploit-00", "a"), ("01-explore-00", "b")):
        store.append(
            {"type": "proposal", "candidate": candidate,
             "proposal": Proposal(text, "openai/gpt-4o", 0.5, 10, 5, 0.01).to_dict()}
        )  # fmt: skip
    return store


def test_the_replay_proposer_answers_from_the_recorded_run(tmp_path: Any) -> None:
    replay = ReplayProposer(recorded_run(tmp_path).path)
    request = ProposalRequest(["01-exploit-00"], 0.5, prompt=lambda: pytest.fail("read"))
    (proposal,) = replay.propose(request)
    assert proposal == Proposal("a", "openai/gpt-4o", 0.5, 10, 5, 0.01)
    gap = ProposalRequest(["01-explore-00", "01-explore-01", "01-explore-02"], 1.0)
    assert [p.text for p in replay.propose(gap)] == ["b"]  # the slots after a gap get none
    assert replay.propose(ProposalRequest(["02-exploit-00"], 0.5)) == []  # never recorded
    with pytest.raises(RunStoreError, match="is not a run folder"):
        ReplayProposer(tmp_path / "nothing")


def test_the_runner_makes_every_kind_of_proposer(tmp_path: Any, litellm: Any) -> None:
    task = load_task("elastic")
    run = recorded_run(tmp_path)

    def made(name: str) -> Proposer:
        return make_proposer(SearchConfig(task="elastic", proposer=name), task)

    builtin, replay, model = made("builtin"), made(f"replay:{run.path}"), made("openai/gpt-4o")
    assert isinstance(builtin, BuiltinAdapter) and builtin.name == "builtin:gp"
    assert isinstance(replay, ReplayProposer) and isinstance(model, LiteLLMProposer)
    assert all(isinstance(p, Proposer) for p in (builtin, replay, model))
    texts = builtin.propose(ProposalRequest(["01-exploit-00"], 0.5, seed=3))
    assert len(texts) == 1 and "class Physics" in texts[0].text
