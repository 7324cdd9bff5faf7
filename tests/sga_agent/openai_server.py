"""A scripted OpenAI-compatible chat server on 127.0.0.1, for tests that use a real HTTP client.

Each POST to ``/v1/chat/completions`` (or ``/chat/completions``) takes the next entry of the
script and answers with it; every request body is recorded. A script entry is

- a string: every one of the ``n`` choices gets this text;
- a list of strings: choice ``i`` gets ``texts[i % len(texts)]``;
- a :class:`Reply`: full control (HTTP status, delay, texts);
- or the script is a callable ``body -> entry`` answering every request.

Usage is reported as whitespace-separated word counts of the messages and of the choices.

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
from typing import Any

CHAT_PATHS = ("/v1/chat/completions", "/chat/completions")
_ERROR_TYPES = {400: "invalid_request_error", 401: "authentication_error", 429: "rate_limit_error"}


@dataclass(frozen=True)
class Reply:
    """One scripted answer.

    Parameters
    ----------
    texts : str or list of str
        Content of the choices (a string for all of them, a list cycled over them).
    status : int
        HTTP status; anything but 200 answers with an OpenAI-style error body.
    delay_s : float
        Seconds to wait before answering (longer than the client's timeout makes it time out).
    message : str
        The error message of a non-200 answer.
    """

    texts: str | list[str] = ""
    status: int = 200
    delay_s: float = 0.0
    message: str = ""

    @classmethod
    def error(cls, status: int, message: str = "", delay_s: float = 0.0) -> Reply:
        """An error answer, e.g. ``Reply.error(429)`` or ``Reply.error(500, "overloaded")``."""
        return cls(status=status, message=message or f"scripted error {status}", delay_s=delay_s)


Entry = str | list[str] | Reply
Script = Sequence[Entry] | Callable[[dict[str, Any]], Entry]


class ScriptedOpenAIServer:
    """An OpenAI-compatible ``/chat/completions`` endpoint answering from a script.

    Parameters
    ----------
    script : sequence of entries, or callable
        Answers, one per request in arrival order, or a function of the request body. When a
        sequence runs out the server answers 400 "script exhausted", which clients do not retry.

    Attributes
    ----------
    url : str
        ``http://127.0.0.1:PORT/v1`` once started.
    requests : list of dict
        The JSON body of every chat request received, in arrival order.
    """

    def __init__(self, script: Script) -> None:
        self._script = script if callable(script) else list(script)
        self._next = 0
        self._lock = threading.Lock()
        self._closing = threading.Event()
        self.requests: list[dict[str, Any]] = []
        self._httpd: ThreadingHTTPServer | None = None
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        if self._httpd is None:
            raise RuntimeError("the server is not running; use it as a context manager")
        host, port = self._httpd.server_address[:2]
        return f"http://{host}:{port}/v1"

    def __enter__(self) -> ScriptedOpenAIServer:
        self._httpd = ThreadingHTTPServer(("127.0.0.1", 0), _handler_for(self))
        self._httpd.daemon_threads = True
        self._httpd.block_on_close = False
        self._thread = threading.Thread(
            target=self._httpd.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True
        )
        self._thread.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self._closing.set()  # cuts short any scripted delay
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

    def _wait(self, seconds: float) -> None:
        self._closing.wait(seconds)


def _completion(body: dict[str, Any], reply: Reply) -> dict[str, Any]:
    """An OpenAI chat.completion object with ``n`` choices taken from the reply."""
    texts = [reply.texts] if isinstance(reply.texts, str) else reply.texts or [""]
    n = int(body.get("n") or 1)
    contents = [texts[i % len(texts)] for i in range(n)]
    prompt_tokens = sum(len(str(m.get("content", "")).split()) for m in body.get("messages", []))
    completion_tokens = sum(len(text.split()) for text in contents)
    return {
        "id": f"chatcmpl-scripted-{time.monotonic_ns()}",
        "object": "chat.completion",
        "created": int(time.time()),
        "model": body.get("model", "scripted"),
        "choices": [
            {
                "index": i,
                "message": {"role": "assistant", "content": text},
                "finish_reason": "stop",
            }
            for i, text in enumerate(contents)
        ],
        "usage": {
            "prompt_tokens": prompt_tokens,
            "completion_tokens": completion_tokens,
            "total_tokens": prompt_tokens + completion_tokens,
        },
    }


def _error(reply: Reply) -> dict[str, Any]:
    kind = _ERROR_TYPES.get(reply.status, "server_error")
    return {"error": {"message": reply.message, "type": kind, "param": None, "code": None}}


def _handler_for(server: ScriptedOpenAIServer) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        def do_POST(self) -> None:
            if self.path.rstrip("/") not in CHAT_PATHS:
                self._send(404, {"error": {"message": f"no route {self.path}", "type": "404"}})
                return
            length = int(self.headers.get("Content-Length", 0))
            body = json.loads(self.rfile.read(length) or b"{}")
            reply = server._take(body)
            server._wait(reply.delay_s)
            if reply.status == 200:
                self._send(200, _completion(body, reply))
            else:
                self._send(reply.status, _error(reply))

        def _send(self, status: int, payload: dict[str, Any]) -> None:
            data = json.dumps(payload).encode()
            try:
                self.send_response(status)
                self.send_header("Content-Type", "application/json")
                self.send_header("Content-Length", str(len(data)))
                self.end_headers()
                self.wfile.write(data)
            except (BrokenPipeError, ConnectionResetError):
                pass  # the client gave up (a timeout test)

        def log_message(self, format: str, *args: Any) -> None:
            """Keep test output quiet."""

    return Handler
