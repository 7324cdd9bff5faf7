"""A scripted OpenAI-compatible chat server on 127.0.0.1 (standard library only).

Each POST to ``/v1/chat/completions`` (or ``/chat/completions``) takes the next entry of the
script and answers with it; every request body is recorded. A script entry is

- a string: every one of the ``n`` choices gets this text;
- a list of strings: choice ``i`` gets ``texts[i % len(texts)]``;
- a :class:`Reply`: full control (status, delay, finish reasons, reasoning, usage, or one of
  the failures real providers show: no choices, a body that is not JSON, no answer at all);
- or the script is a callable ``body -> entry`` answering every request.

Usage counts whitespace-separated words of the messages and of the choices (reasoning
included), unless the reply gives the token counts itself.

Example
-------
>>> with ScriptedOpenAIServer(["first answer", Reply.error(429), "second"]) as server:
...     server.url  # "http://127.0.0.1:PORT/v1", the api_base for litellm's "openai/..." models
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any, Literal

CHAT_PATHS = ("/v1/chat/completions", "/chat/completions")
_ERROR_TYPES = {400: "invalid_request_error", 401: "authentication_error", 429: "rate_limit_error"}
#: What a reverse proxy in front of a model server sends when the model is gone.
PROXY_ERROR_PAGE = (
    "<html>\r\n<head><title>502 Bad Gateway</title></head>\r\n<body>\r\n"
    "<center><h1>502 Bad Gateway</h1></center>\r\n<hr><center>nginx</center>\r\n"
    "</body>\r\n</html>\r\n"
)
ReplyKind = Literal["chat", "empty", "malformed", "hang"]
PerChoice = str | list[str]


@dataclass(frozen=True)
class Reply:
    """One scripted answer.

    Parameters
    ----------
    texts : str or list of str
        Content of the choices (a string for all of them, a list cycled over them).
    status : int
        HTTP status; anything but 200 answers with an OpenAI-style error body (or with
        ``body`` for a malformed reply).
    delay_s : float
        Seconds to wait before answering (longer than the client's timeout makes it time out).
    message : str
        The error message of a non-200 answer.
    finish_reason : str or list of str
        Per choice, cycled like ``texts``: "stop", or "length" for an answer cut off.
    reasoning_content : str, list of str or None
        Per choice, sent as ``message.reasoning_content`` (DeepSeek-R1, vLLM reasoning
        parsers); None leaves the field out.
    prompt_tokens, completion_tokens : int or None
        Reported usage; None counts words.
    kind : {"chat", "empty", "malformed", "hang"}
        A chat completion, one with ``"choices": []``, a body that is not JSON, or no answer
        until the server closes. Use the constructors below rather than setting it.
    body : str
        The raw body of a malformed reply.
    """

    texts: PerChoice = ""
    status: int = 200
    delay_s: float = 0.0
    message: str = ""
    finish_reason: PerChoice = "stop"
    reasoning_content: PerChoice | None = None
    prompt_tokens: int | None = None
    completion_tokens: int | None = None
    kind: ReplyKind = "chat"
    body: str = ""

    @classmethod
    def error(cls, status: int, message: str = "", delay_s: float = 0.0) -> Reply:
        """An error answer, e.g. ``Reply.error(429)`` or ``Reply.error(500, "overloaded")``."""
        return cls(status=status, message=message or f"scripted error {status}", delay_s=delay_s)

    @classmethod
    def empty(cls, delay_s: float = 0.0) -> Reply:
        """HTTP 200 with a well-formed completion holding no choices."""
        return cls(kind="empty", delay_s=delay_s)

    @classmethod
    def malformed(cls, body: str = PROXY_ERROR_PAGE, status: int = 200) -> Reply:
        """A body that is not JSON (by default a proxy's HTML error page), sent as text/html."""
        return cls(kind="malformed", body=body, status=status)

    @classmethod
    def hang(cls) -> Reply:
        """No answer at all: the request is held until the server closes."""
        return cls(kind="hang")


Entry = str | list[str] | Reply
Script = Sequence[Entry] | Callable[[dict[str, Any]], Entry]


class ScriptedOpenAIServer:
    """An OpenAI-compatible ``/chat/completions`` endpoint answering from a script.

    Parameters
    ----------
    script : sequence of entries, or callable
        Answers, one per request in arrival order, or a function of the request body. When a
        sequence runs out the server answers 400 "script exhausted", which clients do not retry.
    port : int
        Port on 127.0.0.1; 0 picks a free one.

    Attributes
    ----------
    url : str
        ``http://127.0.0.1:PORT/v1`` once started.
    requests : list of dict
        The JSON body of every chat request received, in arrival order.
    """

    def __init__(self, script: Script, port: int = 0) -> None:
        self._script = script if callable(script) else list(script)
        self._port = port
        self._next = 0
        self._lock = threading.Lock()
        self._closing = threading.Event()
        self.requests: list[dict[str, Any]] = []
        self._httpd: ThreadingHTTPServer | None = None
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        """The api_base of the running server."""
        if self._httpd is None:
            raise RuntimeError("the server is not running; use it as a context manager")
        host, port = self._httpd.server_address[:2]
        return f"http://{host}:{port}/v1"

    def __enter__(self) -> ScriptedOpenAIServer:
        self._closing.clear()
        self._httpd = ThreadingHTTPServer(("127.0.0.1", self._port), _handler_for(self))
        self._httpd.daemon_threads = True
        self._httpd.block_on_close = False
        self._thread = threading.Thread(
            target=self._httpd.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True
        )
        self._thread.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self._closing.set()  # cuts short any scripted delay and releases hanging requests
        assert self._httpd is not None and self._thread is not None
        self._httpd.shutdown()
        self._httpd.server_close()
        self._thread.join()
        self._httpd = None

    def _take(self, body: dict[str, Any]) -> Reply:
        """Record the request and return its scripted answer."""
        with self._lock:
            self.requests.append(body)
            if callable(self._script):
                entry = self._script(body)
            elif self._next < len(self._script):
                entry = self._script[self._next]
                self._next += 1
            else:
                entry = Reply.error(400, f"script exhausted after {len(self._script)} requests")
        return entry if isinstance(entry, Reply) else Reply(texts=entry)

    def _wait(self, seconds: float | None) -> None:
        """Sleep ``seconds`` (None: until the server closes), cut short when it closes."""
        self._closing.wait(seconds)


def _per_choice(value: PerChoice, n: int) -> list[str]:
    """``value`` for each of ``n`` choices (a list is cycled)."""
    values = [value] if isinstance(value, str) else value or [""]
    return [values[i % len(values)] for i in range(n)]


def _words(text: str) -> int:
    """The usage stand-in for a token count."""
    return len(text.split())


def _completion(body: dict[str, Any], reply: Reply) -> dict[str, Any]:
    """An OpenAI chat.completion object with ``n`` choices taken from the reply."""
    n = 0 if reply.kind == "empty" else int(body.get("n") or 1)
    contents = _per_choice(reply.texts, n)
    reasons = _per_choice(reply.finish_reason, n)
    thoughts = None if reply.reasoning_content is None else _per_choice(reply.reasoning_content, n)
    choices = []
    for i in range(n):
        message: dict[str, Any] = {"role": "assistant", "content": contents[i]}
        if thoughts is not None:
            message["reasoning_content"] = thoughts[i]
        choices.append({"index": i, "message": message, "finish_reason": reasons[i]})
    prompt_tokens = reply.prompt_tokens
    if prompt_tokens is None:
        prompt_tokens = sum(_words(str(m.get("content", ""))) for m in body.get("messages", []))
    reasoning_tokens = sum(_words(t) for t in thoughts or [])
    completion_tokens = reply.completion_tokens
    if completion_tokens is None:
        completion_tokens = sum(_words(text) for text in contents) + reasoning_tokens
    usage: dict[str, Any] = {
        "prompt_tokens": prompt_tokens,
        "completion_tokens": completion_tokens,
        "total_tokens": prompt_tokens + completion_tokens,
    }
    if thoughts is not None:
        usage["completion_tokens_details"] = {"reasoning_tokens": reasoning_tokens}
    return {
        "id": f"chatcmpl-scripted-{time.monotonic_ns()}",
        "object": "chat.completion",
        "created": int(time.time()),
        "model": body.get("model", "scripted"),
        "choices": choices,
        "usage": usage,
    }


def _error(reply: Reply) -> dict[str, Any]:
    """An OpenAI-style error body."""
    kind = _ERROR_TYPES.get(reply.status, "server_error")
    return {"error": {"message": reply.message, "type": kind, "param": None, "code": None}}


def _handler_for(server: ScriptedOpenAIServer) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        def do_POST(self) -> None:
            length = int(self.headers.get("Content-Length", 0))
            body = json.loads(self.rfile.read(length) or b"{}")
            if self.path.rstrip("/") not in CHAT_PATHS:
                self._send_json(404, _error(Reply.error(404, f"no route {self.path}")))
                return
            reply = server._take(body)
            if reply.kind == "hang":
                server._wait(None)  # until the server closes; the connection closes unanswered
                return
            server._wait(reply.delay_s)
            if reply.kind == "malformed":
                self._send(reply.status, reply.body.encode(), "text/html")
            elif reply.status == 200:
                self._send_json(200, _completion(body, reply))
            else:
                self._send_json(reply.status, _error(reply))

        def _send_json(self, status: int, payload: dict[str, Any]) -> None:
            self._send(status, json.dumps(payload).encode(), "application/json")

        def _send(self, status: int, data: bytes, content_type: str) -> None:
            try:
                self.send_response(status)
                self.send_header("Content-Type", content_type)
                self.send_header("Content-Length", str(len(data)))
                self.end_headers()
                self.wfile.write(data)
            except (BrokenPipeError, ConnectionResetError):
                self.close_connection = True  # the client gave up (a timeout test)

        def log_message(self, format: str, *args: Any) -> None:
            """Keep test output quiet."""

    return Handler
