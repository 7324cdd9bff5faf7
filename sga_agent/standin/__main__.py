"""``python -m sga_agent.standin``: serve the stand-in provider until interrupted.

Example::

    python -m sga_agent.standin --port 8765 --mode corpus
    OPENAI_API_KEY=anything sga-agent search --task elastic --model openai/standin \\
        --api-base http://127.0.0.1:8765/v1

``--mode`` takes one mode or several, comma-separated, used in turn per request
(``--mode down,corpus`` fails every other request).
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import threading
from collections.abc import Callable
from typing import Any

from sga_agent.standin.corpus import CorpusScript
from sga_agent.standin.server import Entry, Reply, ScriptedOpenAIServer

#: Every mode but "corpus": what the server answers each request with.
FIXED: dict[str, Reply] = {
    "hang": Reply.hang(),
    "empty": Reply.empty(),
    "malformed": Reply.malformed(),
    "down": Reply.error(503, "The server is overloaded or not ready yet."),
    "ratelimit": Reply.error(429, "Rate limit reached for requests."),
}
MODES = ("corpus", *FIXED)


def make_script(modes: list[str]) -> Callable[[dict[str, Any]], Entry]:
    """A script answering successive requests with ``modes`` in turn."""
    corpus = CorpusScript() if "corpus" in modes else None
    turns = itertools.cycle(modes)
    lock = threading.Lock()

    def answer(body: dict[str, Any]) -> Entry:
        with lock:
            mode = next(turns)
        if mode == "corpus":
            assert corpus is not None
            return corpus(body)
        return FIXED[mode]

    return answer


def _modes(text: str) -> list[str]:
    modes = [mode.strip() for mode in text.split(",") if mode.strip()]
    unknown = [mode for mode in modes if mode not in MODES]
    if unknown or not modes:
        raise argparse.ArgumentTypeError(
            f"unknown mode {', '.join(unknown) or repr(text)}; choose from {', '.join(MODES)}"
        )
    return modes


def main(argv: list[str] | None = None) -> None:
    """Parse the arguments, print the api_base and serve until Ctrl-C."""
    parser = argparse.ArgumentParser(
        prog="python -m sga_agent.standin",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--port", type=int, default=8765, help="port on 127.0.0.1 (0: any free)")
    parser.add_argument(
        "--mode",
        type=_modes,
        default=["corpus"],
        help=f"one of {', '.join(MODES)}, or several comma-separated in turn",
    )
    args = parser.parse_args(argv)
    with ScriptedOpenAIServer(make_script(args.mode), port=args.port) as server:
        print(server.url, flush=True)
        print(
            f"stand-in provider ({','.join(args.mode)}): use --model openai/standin "
            f"--api-base {server.url} with OPENAI_API_KEY=anything; Ctrl-C stops it",
            flush=True,
        )
        with contextlib.suppress(KeyboardInterrupt):
            threading.Event().wait()


if __name__ == "__main__":
    main()
