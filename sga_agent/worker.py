"""The sandbox worker: ``python -m sga_agent.worker REQUEST_PATH RESULT_PATH``, run by .sandbox.

``REQUEST_PATH`` holds one JSON request::

    {"task": "elastic" or "module:callable", "solution": "...",
     "settings": {EvaluationSettings fields}, "limits": {SandboxLimits fields},
     "isolation": {Isolation fields} or null, "parent_pid": 1234}

The worker applies the limits to itself, then the isolation (see :mod:`.isolation`; before the
task is imported, while the process has one thread) and refuses to go on if it differs from
the requested one, loads the task, runs ``task.evaluate(solution, settings)`` and writes the
:class:`~sga_agent.task.Evaluation` as JSON to ``RESULT_PATH``, which it opened before the
isolation forbade writing there. Its stdin is ``/dev/null``; what the task or the candidate
prints goes to stdout/stderr, which the parent captures separately, so it cannot corrupt the
result. Failures to load the task or to evaluate become an invalid Evaluation with a status
(the last traceback lines in ``extras["traceback"]``); the exit status is 0 whenever a result
was written.
"""

from __future__ import annotations

import ctypes
import dataclasses
import importlib
import json
import math
import os
import re
import resource
import signal
import sys
import traceback
from pathlib import Path
from typing import IO, Any

from sga_agent import isolation, registry
from sga_agent.sandbox import SandboxLimits
from sga_agent.task import Evaluation, EvaluationSettings, Task

_PR_SET_PDEATHSIG = 1
#: Native libraries report a failed allocation as a RuntimeError with one of these phrases.
_OUT_OF_MEMORY = re.compile(r"allocate memory|memory allocation", re.IGNORECASE)
_MAX_MESSAGE_CHARS = 300
#: Characters kept from the end of a traceback.
TRACEBACK_TAIL_CHARS = 4000


def main(argv: list[str] | None = None) -> int:
    """Serve the request in REQUEST_PATH; returns the exit status."""
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 2:
        print("usage: python -m sga_agent.worker REQUEST_PATH RESULT_PATH", file=sys.stderr)
        return 2
    request = json.loads(Path(args[0]).read_text(encoding="utf-8"))
    limits = SandboxLimits(**request["limits"])
    with open(args[1], "w", encoding="utf-8") as result:
        apply_limits(limits)
        evaluation = isolate(request["isolation"])
        _die_with_parent(request["parent_pid"])
        if evaluation is None:
            evaluation = run(request["task"], request["solution"], request["settings"], limits)
        write_result(evaluation, result)
    return 0


def apply_limits(limits: SandboxLimits) -> None:
    """Limit this process's CPU time, memory and file sizes; no core dumps."""
    cpu = limits.cpu_time_s
    resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu + 5))  # SIGXCPU first, SIGKILL 5 s later
    memory = limits.memory_mb * 2**20
    resource.setrlimit(resource.RLIMIT_DATA, (memory, memory))
    file_size = limits.file_size_mb * 2**20
    resource.setrlimit(resource.RLIMIT_FSIZE, (file_size, file_size))
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))


def isolate(expected: dict[str, str] | None) -> Evaluation | None:
    """Apply the isolation; an error Evaluation if it is not the ``expected`` one.

    ``None`` (isolation disabled) applies nothing. Writes stay allowed in the working
    directory (also ``TMPDIR``) and the task caches, see :func:`.isolation.writable_paths`.
    """
    if expected is None:
        return None
    writable = isolation.writable_paths(Path.cwd(), os.environ)
    applied = dataclasses.asdict(isolation.isolate(writable))
    differences = [f"{key}: {applied[key]}" for key in expected if applied[key] != expected[key]]
    if not differences:
        return None
    return Evaluation.invalid(
        "not evaluated: the worker could not be isolated as detected at start-up "
        f"({'; '.join(differences)})",
        status="error",
    )


def _die_with_parent(parent_pid: int) -> None:
    """Have the kernel kill this worker when the search process dies (Linux)."""
    if sys.platform.startswith("linux"):
        ctypes.CDLL(None).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
        if os.getppid() != parent_pid:  # the parent died before prctl took effect
            os._exit(1)


def run(
    task_name: str, solution: str, settings: dict[str, Any], limits: SandboxLimits
) -> Evaluation:
    """Load the task and evaluate the solution; every failure becomes an invalid Evaluation."""
    try:
        task = load(task_name)
    except registry.UnknownTaskError as error:
        return Evaluation.invalid(str(error), status="error")
    except Exception as error:  # a plugin may fail to import in any way
        return _from_exception(f"could not load task {task_name!r}:", error, limits)
    _limit_torch_threads(limits.threads)
    try:
        evaluation = task.evaluate(solution, EvaluationSettings(**settings))
    except BaseException as error:  # the candidate may even call sys.exit
        return _from_exception("evaluation raised", error, limits)
    if not isinstance(evaluation, Evaluation):
        return Evaluation.invalid(
            f"task {task_name!r} returned {type(evaluation).__name__} from evaluate, "
            "not an sga_agent.task.Evaluation",
            status="error",
        )
    if evaluation.valid and not math.isfinite(evaluation.loss):
        reason = f"the loss is {evaluation.loss} (numerically unstable)"
        return dataclasses.replace(
            evaluation, valid=False, loss=math.inf, reason=reason, status="unstable"
        )
    return evaluation


def load(task_name: str) -> Task:
    """A registered task, or the result of ``module:callable`` (a zero-argument factory)."""
    if ":" not in task_name:
        return registry.load_task(task_name)
    module_name, _, attribute = task_name.partition(":")
    factory = importlib.import_module(module_name)
    for part in attribute.split("."):
        factory = getattr(factory, part)
    task = factory()
    if not isinstance(task, Task):
        raise TypeError(
            f"{task_name} returned {type(task).__name__}, which does not satisfy "
            "sga_agent.task.Task"
        )
    return task


def write_result(evaluation: Evaluation, result: IO[str]) -> None:
    """Write the evaluation as JSON; a result that cannot be written becomes an error."""
    try:
        text = evaluation.to_json()
    except (TypeError, ValueError) as error:
        reason = f"the task's Evaluation is not JSON-serialisable: {error}"
        text = Evaluation.invalid(reason, status="error").to_json()
    try:
        result.write(text)
        result.flush()
    except OSError as error:  # e.g. larger than the file-size limit
        reason = f"could not write the result ({len(text)} characters): {error}"
        result.seek(0)
        result.truncate()
        result.write(Evaluation.invalid(reason, status="error").to_json())


def _limit_torch_threads(threads: int) -> None:
    """Apply the thread count to torch if the task has imported it.

    A later import reads ``OMP_NUM_THREADS``; importing torch here just for this call would add
    a second or more to every worker's start-up.
    """
    torch = sys.modules.get("torch")
    if torch is not None:
        torch.set_num_threads(threads)


def _from_exception(prefix: str, error: BaseException, limits: SandboxLimits) -> Evaluation:
    traceback.clear_frames(error.__traceback__)  # free the candidate's memory before formatting
    lines = str(error).strip().splitlines()
    message = lines[0][:_MAX_MESSAGE_CHARS] if lines else ""
    described = f"{type(error).__name__}: {message}" if message else type(error).__name__
    formatted = "".join(traceback.format_exception(error))
    if len(formatted) > TRACEBACK_TAIL_CHARS:  # keep whole lines from the end
        formatted = formatted[-TRACEBACK_TAIL_CHARS:].partition("\n")[2]
    extras = {"traceback": formatted}
    if isinstance(error, MemoryError) or _OUT_OF_MEMORY.search(str(error)):
        reason = f"exceeded the memory limit of {limits.memory_mb} MB ({described})"
        return Evaluation.invalid(reason, status="out_of_memory", extras=extras)
    return Evaluation.invalid(f"{prefix} {described}", status="error", extras=extras)


if __name__ == "__main__":
    sys.exit(main())
