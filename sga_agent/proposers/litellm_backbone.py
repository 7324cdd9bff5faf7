"""The LLM backbone: any model litellm can reach, asked for batches of samples at one temperature.

litellm is imported on first use (it takes seconds), with its price map read from the installed
package rather than the internet; a missing key of a provider in :data:`PROVIDER_KEYS` is
reported before that. Keys come from the environment under each provider's usual
name (OPENAI_API_KEY, ANTHROPIC_API_KEY, MISTRAL_API_KEY, ...) and never appear in the errors and
log lines written here.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import difflib
import logging
import math
import os
import random
import socket
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from types import ModuleType
from typing import Any

from sga_agent.proposers.base import Proposal, ProposalRequest, ProposerError
from sga_agent.proposers.redact import RedactingFilter, redact

log = logging.getLogger(__name__)

MODEL_EXAMPLES = (
    '"openai/gpt-4o", "anthropic/claude-3-5-sonnet-20240620", "mistral/mistral-large-latest", '
    'or "hosted_vllm/NAME" / "openai/NAME" with api_base for a local OpenAI-compatible server'
)
#: Providers whose chat API returns ``n`` choices from one request.
N_PROVIDERS = frozenset({"openai", "azure", "hosted_vllm"})
#: Longest wait between two attempts, in seconds.
MAX_BACKOFF_S = 60.0
#: HTTP statuses worth another attempt (besides litellm's rate-limit and server-error classes).
RETRY_STATUSES = frozenset({408, 429})
#: HTTP statuses of a key the provider refused (unauthenticated, forbidden).
AUTH_STATUSES = frozenset({401, 403})
LITELLM_LOGGERS = ("LiteLLM", "LiteLLM Router", "LiteLLM Proxy")
NO_PRICE_NOTE = "model not in litellm's price map: cost counted as 0 (give --price)"
#: Tokens of the one-word reply asked before a search starts (:meth:`check_reachable`).
PING_TOKENS = 5
#: The API-key variables of common providers, any one of which will do (as litellm's
#: ``validate_environment`` names them; ``()``: no key needed), so that a missing key is
#: reported without importing litellm. Other providers are asked of litellm.
PROVIDER_KEYS: dict[str, tuple[str, ...]] = {
    "openai": ("OPENAI_API_KEY",),
    "anthropic": ("ANTHROPIC_API_KEY",),
    "mistral": ("MISTRAL_API_KEY",),
    "gemini": ("GOOGLE_API_KEY", "GEMINI_API_KEY"),
    "groq": ("GROQ_API_KEY",),
    "deepseek": ("DEEPSEEK_API_KEY",),
    "together_ai": ("TOGETHERAI_API_KEY",),
    "openrouter": ("OPENROUTER_API_KEY",),
    "cohere": ("COHERE_API_KEY",),
    "xai": ("XAI_API_KEY",),
    "fireworks_ai": ("FIREWORKS_AI_API_KEY",),
    "deepinfra": ("DEEPINFRA_API_KEY",),
    "hosted_vllm": (),
}
_MAX_ERROR_CHARS = 500

Completion = Callable[..., Any]


class BackboneSettingsError(ValueError):
    """A backbone setting is invalid; the message names it and the fix."""


def import_litellm() -> ModuleType:
    """litellm, imported on first call, reading prices locally and printing no help banners."""
    os.environ.setdefault("LITELLM_LOCAL_MODEL_COST_MAP", "True")
    import litellm

    litellm.suppress_debug_info = True
    for name in LITELLM_LOGGERS:
        logger = logging.getLogger(name)
        if not any(isinstance(f, RedactingFilter) for f in logger.filters):
            logger.addFilter(RedactingFilter())
    return litellm


@dataclass(frozen=True)
class BackboneSettings:
    """How to reach the model and how patiently.

    Parameters
    ----------
    model : str
        litellm model string "provider/name", e.g. "openai/gpt-4o".
    api_base : str, optional
        Base URL of an OpenAI-compatible server, e.g. "http://127.0.0.1:8000/v1".
    timeout_s : float
        Seconds one request may take before it counts as failed (and is retried).
    max_retries : int
        Further attempts after a rate limit, server error, lost connection or timeout.
    backoff_s : float
        Wait before the first retry; it doubles per retry, jittered, up to ``MAX_BACKOFF_S``.
    max_tokens : int, optional
        Cap on the tokens of one response (default: the provider's).
    concurrency : int
        Requests in flight at once when samples are asked one per request.
    use_n : bool, optional
        Ask for all samples in one request with ``n``; None decides by provider
        (``N_PROVIDERS``), else one request per sample.
    drop_params : bool
        Let litellm drop parameters a model refuses (e.g. temperature for some reasoning
        models) instead of failing.
    price_per_million : (float, float), optional
        USD per million input and output tokens, for a model litellm's price map lacks (or to
        override it); None: litellm's price, 0 with a note where it has none.
    """

    model: str
    api_base: str | None = None
    timeout_s: float = 120.0
    max_retries: int = 4
    backoff_s: float = 2.0
    max_tokens: int | None = None
    concurrency: int = 4
    use_n: bool | None = None
    drop_params: bool = True
    price_per_million: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        provider, _, name = self.model.partition("/")
        if not provider or not name:
            raise BackboneSettingsError(
                f"model {self.model!r} needs a provider prefix, 'provider/name', "
                f"e.g. {MODEL_EXAMPLES}"
            )
        if self.api_base is not None and not self.api_base.startswith(("http://", "https://")):
            raise BackboneSettingsError(
                f"api_base must be an http(s) URL such as http://127.0.0.1:8000/v1, "
                f"got {redact(self.api_base)!r}"
            )
        if not (math.isfinite(self.timeout_s) and self.timeout_s > 0):
            raise BackboneSettingsError(f"timeout_s must be positive, got {self.timeout_s}")
        if not (math.isfinite(self.backoff_s) and self.backoff_s >= 0):
            raise BackboneSettingsError(f"backoff_s must be >= 0, got {self.backoff_s}")
        if self.max_retries < 0:
            raise BackboneSettingsError(f"max_retries must be >= 0, got {self.max_retries}")
        if self.concurrency < 1:
            raise BackboneSettingsError(f"concurrency must be at least 1, got {self.concurrency}")
        if self.max_tokens is not None and self.max_tokens < 1:
            raise BackboneSettingsError(f"max_tokens must be at least 1, got {self.max_tokens}")
        price = self.price_per_million
        if price is not None and not (
            len(price) == 2 and all(math.isfinite(p) and p >= 0 for p in price)
        ):
            raise BackboneSettingsError(
                f"price_per_million must be two numbers >= 0 (USD per million input and output "
                f"tokens), got {price!r}"
            )

    @property
    def provider(self) -> str:
        return self.model.partition("/")[0]


def backoff_wait(retry: int, first_s: float, cap_s: float = MAX_BACKOFF_S) -> float:
    """Seconds to wait before retry number ``retry`` (0-based).

    The ceiling doubles from ``first_s`` up to ``cap_s``; the wait is drawn from the upper half
    of it so that parallel requests hitting one rate limit do not retry in lockstep.
    """
    ceiling = min(cap_s, first_s * 2.0**retry)
    return random.uniform(ceiling / 2, ceiling)


class LiteLLMProposer:
    """A :class:`~sga_agent.proposers.base.Proposer` backed by ``litellm.completion``.

    Parameters
    ----------
    settings : BackboneSettings
        The model and how to reach it.
    completion : callable, optional
        Stand-in for ``litellm.completion`` (tests); same keyword arguments and response.
    sleep : callable
        Waits between attempts (tests pass a recorder so nothing really waits).

    Notes
    -----
    ``sample`` (and ``propose``, which asks it with the request's messages) returns the
    proposals that succeeded: all ``n``, or fewer when some requests
    failed for good (logged as warnings); it raises ``ProposerError`` only when none did. With
    ``n`` in one request, a provider that returns fewer choices is topped up with single
    requests.
    """

    def __init__(
        self,
        settings: BackboneSettings,
        completion: Completion | None = None,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        self.settings = settings
        if settings.provider not in PROVIDER_KEYS:
            _check_provider(settings.provider, import_litellm())
        self._given_completion = completion
        self._sleep = sleep
        use_n = settings.use_n
        self.use_n = settings.provider in N_PROVIDERS if use_n is None else use_n

    @property
    def _litellm(self) -> ModuleType:
        """litellm, imported at the first request (a missing key is found without it)."""
        return import_litellm()

    @property
    def _completion(self) -> Completion:
        given = self._given_completion
        return given if given is not None else self._litellm.completion

    @property
    def name(self) -> str:
        return f"litellm:{self.settings.model}"

    def describe(self) -> dict[str, Any]:
        """Settings for the run config; URL credentials in api_base are masked."""
        settings = asdict(self.settings)
        if self.settings.api_base is not None:
            settings["api_base"] = redact(self.settings.api_base)
        return {"name": self.name, **settings, "use_n": self.use_n}

    def propose(self, request: ProposalRequest) -> list[Proposal]:
        """Up to ``request.n`` responses to the request's messages at its temperature."""
        return self.sample(request.messages(), request.temperature, request.n)

    def sample(self, messages: list[dict[str, str]], temperature: float, n: int) -> list[Proposal]:
        """Up to ``n`` sampled responses to ``messages`` at ``temperature``; an answer cut off
        at the token limit is asked once more, alone, with twice the room.

        Raises
        ------
        ProposerError
            No request succeeded; the message says why and what to change.
        """
        if n < 0:
            raise ValueError(f"n must be >= 0, got {n}")
        if n == 0:
            return []
        if not (self.use_n and n > 1):
            proposals = self._singles(messages, temperature, n)
        else:
            proposals = self._request(messages, temperature, n)
            if len(proposals) < n:
                log.info("%s returned %d of %d choices", self.settings.model, len(proposals), n)
                proposals += self._singles(
                    messages, temperature, n - len(proposals), required=False
                )
        return [self._finished(messages, temperature, p) for p in proposals[:n]]

    def check_reachable(self) -> None:
        """Ask the model for one short reply, with the run's timeout and retries, so that a
        provider that is down, refuses the key or does not know the model is found before
        anything else starts.

        Raises
        ------
        ProposerError
            The request failed; the message names the model, the cause and the fix.
        """
        self.check_keys()
        ping = [{"role": "user", "content": "Reply with the single word: ready"}]
        self._request(ping, 0.0, 1, max_tokens=PING_TOKENS)

    def _finished(
        self, messages: list[dict[str, str]], temperature: float, proposal: Proposal
    ) -> Proposal:
        """``proposal``, or, when it was cut off at the token limit, the answer to one more
        request with twice its room (its tokens and cost added); the cut-off one if that
        request fails."""
        if proposal.finish_reason != "length":
            return proposal
        room = 2 * max(proposal.completion_tokens, self.settings.max_tokens or 0, 1024)
        log.warning(
            "an answer of %s was cut off after %d tokens; asking again with max_tokens=%d",
            self.settings.model, proposal.completion_tokens, room,
        )  # fmt: skip
        try:
            (again,) = self._request(messages, temperature, 1, max_tokens=room)
        except ProposerError as error:
            log.warning("asking again failed (%s); keeping the cut-off answer", error)
            return proposal
        return dataclasses.replace(
            again,
            prompt_tokens=again.prompt_tokens + proposal.prompt_tokens,
            completion_tokens=again.completion_tokens + proposal.completion_tokens,
            cost_usd=again.cost_usd + proposal.cost_usd,
            seconds=again.seconds + proposal.seconds,
            truncated_before=proposal.truncated_before + 1,
        )

    def _singles(
        self, messages: list[dict[str, str]], temperature: float, count: int, required: bool = True
    ) -> list[Proposal]:
        """``count`` one-sample requests, ``concurrency`` at a time."""
        if count == 1 and required:
            return self._request(messages, temperature, 1)
        workers = min(self.settings.concurrency, count)
        with concurrent.futures.ThreadPoolExecutor(max_workers=workers) as pool:
            futures = [pool.submit(self._request, messages, temperature, 1) for _ in range(count)]
            proposals: list[Proposal] = []
            errors: list[ProposerError] = []
            for future in futures:
                try:
                    proposals += future.result()
                except ProposerError as error:
                    errors.append(error)
        if errors and not proposals and required:
            raise ProposerError(
                f"all {count} requests failed; the first: {errors[0]}",
                transient=all(error.transient for error in errors),
            )
        if errors:
            log.warning("%d of %d requests failed; the first: %s", len(errors), count, errors[0])
        return proposals

    def _request(
        self,
        messages: list[dict[str, str]],
        temperature: float,
        n: int,
        max_tokens: int | None = None,
    ) -> list[Proposal]:
        """One request for ``n`` choices, retried on transient failures (an answer with no
        choices among them); ``max_tokens`` overrides the settings'."""
        settings = self.settings
        kwargs: dict[str, Any] = {
            "model": settings.model,
            "messages": messages,
            "temperature": temperature,
            "timeout": settings.timeout_s,
            "max_retries": 0,  # the provider SDK's own retries would hide ours
            "drop_params": settings.drop_params,
        }
        if n > 1:
            kwargs["n"] = n
        if settings.api_base is not None:
            kwargs["api_base"] = settings.api_base
        if (max_tokens or settings.max_tokens) is not None:
            kwargs["max_tokens"] = max_tokens or settings.max_tokens
        attempts = settings.max_retries + 1
        start = time.monotonic()
        for attempt in range(attempts):
            try:
                response = self._completion(**kwargs)
                if not getattr(response, "choices", None):
                    raise EmptyAnswer(f"{settings.model} answered with no choices")
                break
            except Exception as error:
                retry, message = self._diagnose(error)
                if not retry:
                    raise ProposerError(message) from None
                if attempt + 1 == attempts:
                    raise ProposerError(
                        f"gave up on {settings.model} after {attempts} attempts: {message}",
                        transient=True,
                    ) from None
                wait = backoff_wait(attempt, settings.backoff_s)
                log.warning(
                    "attempt %d of %d failed: %s; retrying in %.1f s",
                    attempt + 1,
                    attempts,
                    message,
                    wait,
                )
                self._sleep(wait)
        return self._proposals(response, temperature, time.monotonic() - start)

    def _diagnose(self, error: Exception) -> tuple[bool, str]:
        """Whether ``error`` is worth another attempt, and a key-free message with the fix."""
        lm = self._litellm
        model = self.settings.model
        text = _describe_error(error)
        if isinstance(error, EmptyAnswer):
            return True, str(error)
        if isinstance(error, lm.Timeout):
            return True, (
                f"{model} did not answer within {self.settings.timeout_s:g} s "
                f"(--request-timeout; or check the server): {text}"
            )
        missing = self._missing_key_message()
        if missing:
            return False, f"{missing}. {text}"
        unreachable = _unreachable(error)
        if unreachable:
            if self.settings.api_base is None:
                where, fix = f"the {self.settings.provider} API", "check the network connection"
            else:
                where, fix = self.settings.api_base, "start the server or correct --api-base"
            return False, f"cannot reach {where} for {model} ({unreachable}): {fix}"
        status = getattr(error, "status_code", None)
        if isinstance(error, lm.AuthenticationError) or status in AUTH_STATUSES:
            return False, (
                f"authentication failed for {model}: the provider rejected the API key in the "
                f"environment; check it. {text}"
            )
        transient = (
            lm.RateLimitError,
            lm.APIConnectionError,
            lm.InternalServerError,
            lm.ServiceUnavailableError,
            lm.BadGatewayError,
        )
        if isinstance(error, transient) or (
            isinstance(status, int) and (status in RETRY_STATUSES or status >= 500)
        ):
            return True, text
        if isinstance(error, lm.NotFoundError):
            return False, f"{model} was not found: check the model name and api_base. {text}"
        return False, f"{model} rejected the request: {text}"

    def check_keys(self) -> None:
        """Raise :class:`ProposerError` naming the variable to set when an API key is missing
        (no request is sent)."""
        missing = self._missing_key_message()
        if missing:
            raise ProposerError(missing)

    def _missing_key_message(self) -> str:
        """Which API-key variable to set, when the provider expects one (:data:`PROVIDER_KEYS`,
        else litellm's ``validate_environment``) that the environment lacks; empty otherwise."""
        missing = missing_keys(self.settings.model, self.settings.api_base)
        if not missing:
            return ""
        hint = ""
        if self.settings.api_base is not None:
            hint = " (any value does for a local server that ignores keys)"
        return f"no API key for {self.settings.model}: set {' or '.join(missing)}{hint}"

    def _proposals(self, response: Any, temperature: float, seconds: float) -> list[Proposal]:
        """One proposal per choice, sharing the response's tokens and cost among them, each
        with its finish reason and the provider's reasoning, if it sent any."""
        choices = response.choices
        usage = getattr(response, "usage", None)
        prompt_total = int(getattr(usage, "prompt_tokens", 0) or 0)
        completion_total = int(getattr(usage, "completion_tokens", 0) or 0)
        prompt = _shares(prompt_total, len(choices))
        completion = _shares(completion_total, len(choices))
        cost, note = self._cost(response, prompt_total, completion_total)
        return [
            Proposal(
                text=choice.message.content or "",
                model=self.settings.model,
                temperature=temperature,
                prompt_tokens=prompt[i],
                completion_tokens=completion[i],
                cost_usd=cost / len(choices),
                cost_note=note,
                seconds=seconds,
                finish_reason=str(getattr(choice, "finish_reason", "") or ""),
                reasoning=str(getattr(choice.message, "reasoning_content", "") or ""),
            )
            for i, choice in enumerate(choices)
        ]

    def _cost(self, response: Any, prompt_tokens: int, completion_tokens: int) -> tuple[float, str]:
        """The response's price in USD: from the given price per million tokens, else from
        litellm's local price map, else 0 with a note."""
        price = self.settings.price_per_million
        if price is not None:
            return (prompt_tokens * price[0] + completion_tokens * price[1]) / 1e6, ""
        try:
            return float(self._litellm.completion_cost(completion_response=response)), ""
        except Exception:
            return 0.0, NO_PRICE_NOTE


class EmptyAnswer(RuntimeError):
    """The provider answered without choices (retried like a server error)."""


def is_priced(model: str) -> bool:
    """Whether litellm's local price map prices ``model`` (its cost can be counted)."""
    try:
        info = import_litellm().get_model_info(model=model)
    except Exception:
        return False
    return bool(info.get("input_cost_per_token") or info.get("output_cost_per_token"))


def missing_keys(model: str, api_base: str | None = None) -> list[str]:
    """The API-key variables ``model`` needs, when none of them is set (empty otherwise);
    litellm is imported only for a provider outside :data:`PROVIDER_KEYS`."""
    provider = model.partition("/")[0]
    if provider in PROVIDER_KEYS:
        names = PROVIDER_KEYS[provider]
        return [] if not names or any(name in os.environ for name in names) else list(names)
    report = import_litellm().validate_environment(model=model, api_base=api_base)
    return [name for name in report.get("missing_keys", []) if name.endswith("_API_KEY")]


def _check_provider(provider: str, litellm: ModuleType) -> None:
    known = [getattr(p, "value", p) for p in litellm.provider_list]
    if provider not in known:
        close = difflib.get_close_matches(provider, known, n=1)
        hint = f" Did you mean {close[0]!r}?" if close else ""
        raise BackboneSettingsError(
            f"unknown provider {provider!r} in the model string.{hint} Examples: {MODEL_EXAMPLES}"
        )


def _unreachable(error: BaseException) -> str:
    """Why no connection could be made, if that is what ``error`` (or its cause) says: nothing
    listens at the address, or its host name does not resolve. Empty otherwise."""
    seen: set[int] = set()
    cause: BaseException | None = error
    while cause is not None and id(cause) not in seen:
        seen.add(id(cause))
        if isinstance(cause, ConnectionRefusedError):
            return "connection refused"
        if isinstance(cause, socket.gaierror):
            return f"host name not resolved: {cause.strerror or cause}"
        cause = cause.__cause__ or cause.__context__
    return ""


def _shares(total: int, parts: int) -> list[int]:
    """``total`` split into ``parts`` integers that differ by at most one and sum to it."""
    base, extra = divmod(total, parts)
    return [base + (i < extra) for i in range(parts)]


def _describe_error(error: Exception) -> str:
    """The error's type and message, redacted and shortened."""
    text = str(error)
    if type(error).__name__ not in text:
        text = f"{type(error).__name__}: {text}"
    text = redact(" ".join(text.split()))
    return text if len(text) <= _MAX_ERROR_CHARS else text[: _MAX_ERROR_CHARS - 1] + "…"
