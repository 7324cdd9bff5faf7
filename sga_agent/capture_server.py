"""The capture server: ``python -m sga_agent.capture_server TASK``, started by :mod:`.sandbox`.

It loads the task and the libraries its captures need (the task's ``capture_modules``, e.g.
torch) once, captures the task's own ``warm_up_solutions()`` (default: its seed) so that later
captures find every module loaded, prints a ready line, then serves one request per line of its
standard input::

    {"solution": "...", "timeout_s": 60, "limits": {SandboxLimits fields},
     "isolation": {Isolation fields} or null}

For each, it forks a confined process (:func:`sga_agent.isolation.run_confined`) that runs
``task.capture(solution)`` and writes the outcome as JSON, and answers with one line::

    {"status": "ok" | "timeout" | "crashed" | "error", "output": "<the confined process's JSON>",
     "isolation": {...}, "signal": 0, "exit_code": 0, "detail": "..."}

The server itself never runs a candidate's code: only its forked, confined children do. What
they wrote (``output``) is untrusted: the caller parses it with limits and the trusted fit checks
the data again. Prints of the task go to standard error; answers go to the original standard
output only.
"""

from __future__ import annotations

import importlib
import json
import sys
from dataclasses import asdict
from typing import Any

from sga_agent import registry
from sga_agent.helper_protocol import answer, describe, first_line, start_helper
from sga_agent.isolation import Isolation, run_confined
from sga_agent.sandbox import SandboxLimits
from sga_agent.task import InvalidSolution, Task, is_out_of_memory

#: Imported before any capture (with the task's ``capture_modules``): a confined process may be
#: unable to read the files to import them later (as ``nobody``, Python under /root, say).
PRELOADED = ("math", "cmath", "numbers", "functools", "itertools", "collections", "typing",
             "dataclasses", "enum", "abc", "operator", "random", "json",
             "encodings.idna")  # fmt: skip
TRACEBACK_TAIL_CHARS = 2000


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        print("usage: python -m sga_agent.capture_server TASK", file=sys.stderr)
        return 2
    answers = start_helper()
    task = registry.resolve_task(args[0])
    for name in (*PRELOADED, *task.capture_modules):
        importlib.import_module(name)
    warm_up = task.warm_up_solutions()
    outcomes = [sorted(capture_outcome(task, solution)) for solution in warm_up]
    answer(answers, {"ready": True, "warm_up": outcomes})
    for line in sys.stdin:
        answer(answers, serve(task, json.loads(line)))
    return 0


def serve(task: Task, request: dict[str, Any]) -> dict[str, Any]:
    """Capture one solution in a confined process; the outcome, as the answer line."""
    limits = SandboxLimits(**request["limits"])
    expected = Isolation(**request["isolation"]) if request.get("isolation") else None

    def work() -> bytes:
        return json.dumps(capture_outcome(task, request["solution"])).encode()

    run = run_confined(
        work,
        timeout_s=float(request["timeout_s"]),
        memory_mb=limits.memory_mb,
        cpu_time_s=limits.cpu_time_s,
        file_size_mb=limits.file_size_mb,
        isolate=limits.isolation,
        expected=expected,
    )
    return {
        "status": run.status,
        "output": run.output.decode("utf-8", errors="replace"),
        "isolation": asdict(run.isolation) if run.isolation else None,
        "signal": run.signal,
        "exit_code": run.exit_code,
        "detail": run.detail,
    }


def capture_outcome(task: Task, solution: str) -> dict[str, Any]:
    """``{"data": ...}``, or why not: ``{"invalid" | "error" | "out_of_memory": reason}``."""
    try:
        data = task.capture(solution)
        json.dumps(data)  # what cannot be sent is the task's error, found here
        return {"data": data}
    except InvalidSolution as error:
        return {"invalid": first_line(str(error))}
    except BaseException as error:  # the candidate may even call sys.exit
        described, text = describe(error, TRACEBACK_TAIL_CHARS)
        if is_out_of_memory(error):
            return {"out_of_memory": described}
        return {"error": described, "traceback": text}


if __name__ == "__main__":
    sys.exit(main())
