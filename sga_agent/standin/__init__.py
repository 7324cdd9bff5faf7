"""A stand-in LLM provider: an OpenAI-compatible chat server on 127.0.0.1 and a corpus of
realistic model answers for it, for tests, benchmarks and offline trials.

``python -m sga_agent.standin --port 8765`` serves the corpus until interrupted; see
:mod:`sga_agent.standin.__main__`.
"""

from sga_agent.standin.corpus import Answer, CorpusScript, load_corpus, load_index, task_of
from sga_agent.standin.server import CHAT_PATHS, PROXY_ERROR_PAGE, Reply, ScriptedOpenAIServer

__all__ = [
    "CHAT_PATHS",
    "PROXY_ERROR_PAGE",
    "Answer",
    "CorpusScript",
    "Reply",
    "ScriptedOpenAIServer",
    "load_corpus",
    "load_index",
    "task_of",
]
