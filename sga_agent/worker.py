"""The sandbox worker: ``python -m sga_agent.worker RESULT_PATH``, started by :mod:`.sandbox`.

It reads one JSON request from stdin::

    {"task": "elastic" or "module:callable", "solution": "...",
     "settings": {EvaluationSettings fields}, "limits": {SandboxLimits fields},
     "parent_pid": 1234}

applies the limits to itself, loads the task, runs ``task.evaluate(solution, settings)`` and
writes the :class:`~sga_agent.task.Evaluation` as JSON to ``RESULT_PATH``. Anything the task or
the candidate prints goes to the worker's stdout/stderr, which the parent captures separately,
so it cannot corrupt the result. A failure to load the task or an exception in ``evaluate``
becomes an invalid Evaluation (the traceback in ``extras["traceback"]``); the exit status is 0
whenever a result was written.
"""

from __future__ import annotations

import ctypes
import importlib
import json
import os
import re
import resource
import signal
import sys
import traceback
from pathlib import Path
from typing import Any

from sga_agent import registry
from sga_agent.sandbox import SandboxLimits
from sga_agent.task import Evaluation, EvaluationSettings, Task

_PR_SET_PDEATHSIG = 1
#: Native libraries report a failed allocation as a RuntimeError with one of these phrases.
_OUT_OF_MEMORY = re.compile(r"allocate memory|memory allocation", re.IGNORECASE)
_MAX_MESSAGE_CHARS = 300


def main(argv: list[str] | None = None) -> int:
    """Serve one request from stdin; returns the exit status."""
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        print("usage: python -m sga_agent.worker RESULT_PATH < request.json", file=sys.stderr)
        return 2
    result_path = Path(args[0]).resolve()
    request = json.loads(sys.stdin.read())
    limits = SandboxLimits(**request["limits"])
    apply_limits(limits, request["parent_pid"])
    evaluation = run(request["task"], request["solution"], request["settings"], limits)
    write_result(evaluation, result_path)
    return 0


def apply_limits(limits: SandboxLimits, parent_pid: int) -> None:
    """Limit this process's CPU time, memory and file sizes; die with the parent (Linux)."""
    cpu = limits.cpu_time_s
    resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu + 5))  # SIGXCPU first, SIGKILL 5 s later
    memory = limits.memory_mb * 2**20
    resource.setrlimit(resource.RLIMIT_DATA, (memory, memory))
    file_size = limits.file_size_mb * 2**20
    resource.setrlimit(resource.RLIMIT_FSIZE, (file_size, file_size))
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
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
        return Evaluation.invalid(str(error))
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
            "not an sga_agent.task.Evaluation"
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


def write_result(evaluation: Evaluation, result_path: Path) -> None:
    """Write the evaluation as JSON; a result that cannot be written becomes an invalid one."""
    try:
        text = evaluation.to_json()
    except (TypeError, ValueError) as error:
        reason = f"the task's Evaluation is not JSON-serialisable: {error}"
        text = Evaluation.invalid(reason).to_json()
    try:
        result_path.write_text(text, encoding="utf-8")
    except OSError as error:  # e.g. larger than the file-size limit
        reason = f"could not write the result ({len(text)} characters): {error}"
        result_path.write_text(Evaluation.invalid(reason).to_json(), encoding="utf-8")


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
    if isinstance(error, MemoryError) or _OUT_OF_MEMORY.search(str(error)):
        reason = f"exceeded the memory limit of {limits.memory_mb} MB ({described})"
    else:
        reason = f"{prefix} {described}"
    formatted = "".join(traceback.format_exception(error))
    return Evaluation.invalid(reason, extras={"traceback": formatted})


if __name__ == "__main__":
    sys.exit(main())
