"""Evaluating untrusted candidates in a separate, limited worker process.

A candidate solution is code an LLM wrote. It never runs in the search process: each evaluation
starts a fresh ``python -m sga_agent.worker`` (see :mod:`sga_agent.worker`) that loads the task,
calls its ``evaluate`` and writes the :class:`~sga_agent.task.Evaluation` to a result file. The
child runs in its own session (so the whole process group can be killed), in an empty temporary
directory removed afterwards, with a scrubbed environment and resource limits. Whatever goes
wrong (time limit, memory limit, a crash, an exception in the task) comes back as an invalid
``Evaluation`` with a one-line reason, never as an exception in the caller.

Memory limit
------------
The worker limits its *writable private memory* with ``RLIMIT_DATA`` (on Linux >= 4.7 this
counts heap and private writable ``mmap`` regions, the ``VmData`` line of ``/proc/PID/status``),
not its address space with ``RLIMIT_AS``. Measured with Taichi 1.7 and torch 2 on CPU: a process
that has initialised Taichi and used torch has ~0.3 GB resident but 2.25 GB of address space
and 1.36 GB of ``VmData``; ``ti.init`` alone reserves a 1 GiB memory pool, so it fails under
``RLIMIT_AS`` = 2 GB once torch is loaded, and the address space grows further with every
thread (stacks, malloc arenas). GPU drivers reserve far more address space (inaccessible, so
not counted in ``VmData``). ``memory_mb`` therefore bounds ``VmData``; allow ~1.2 GB for
Taichi's pool and libraries on top of what a task really needs (the default, 4 GB, does).
Not covered: shared mappings and memory of processes the candidate spawns (each inherits its
own limit).

Resource limits are applied by the worker to itself before it reads the candidate, rather than
in a ``preexec_fn``, because ``preexec_fn`` is unsafe when the parent has threads (as a
:class:`SandboxPool` does).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from sga_agent.task import Evaluation, EvaluationSettings

#: Environment variables the worker keeps (besides the prefixes below).
KEPT_VARIABLES = frozenset(
    {
        "PATH",
        "HOME",  # Taichi's offline kernel cache lives under ~/.cache
        "LANG",
        "LANGUAGE",
        "TMPDIR",
        "VIRTUAL_ENV",
        "PYTHONPATH",
        "XDG_CACHE_HOME",
        "USER",
        "LOGNAME",
        "LD_LIBRARY_PATH",
    }
)
#: Prefixes of further kept variables (locale, Taichi settings, CUDA device selection).
KEPT_PREFIXES = ("LC_", "TI_", "CUDA_")
#: A variable whose name contains one of these (upper-cased) is dropped even if kept above.
SECRET_MARKERS = ("KEY", "TOKEN", "SECRET", "PASSWORD", "PASSWD", "CREDENTIAL", "AUTH", "COOKIE")
SECRET_PREFIXES = ("OPENAI_", "ANTHROPIC_", "AWS_", "AZURE_", "GOOGLE_", "GEMINI_", "HF_")

#: Bytes of the worker's output kept in ``extras["log"]`` when it fails.
LOG_TAIL_CHARS = 4000
#: Seconds of CPU time granted per thread and second of wall time, plus a fixed margin.
CPU_TIME_FACTOR = 1.5
CPU_TIME_MARGIN_S = 5


@dataclass(frozen=True)
class SandboxLimits:
    """Resources one evaluation may use.

    Parameters
    ----------
    timeout_s : float
        Wall-clock limit in seconds, worker start-up included; the process group is then killed.
    memory_mb : int
        Limit on the worker's writable private memory (``RLIMIT_DATA``) in MiB. Taichi alone
        accounts for ~1.1 GiB of it (a reserved memory pool); see the module docstring.
    file_size_mb : int
        Largest file the worker may write, in MiB (``RLIMIT_FSIZE``); also caps its captured
        output and its result.
    threads : int
        Threads for numerical libraries (OpenMP, MKL, OpenBLAS, torch, Taichi's CPU backend).
        The CPU-time limit is ``CPU_TIME_FACTOR * timeout_s * threads + CPU_TIME_MARGIN_S``.
    """

    timeout_s: float = 900.0
    memory_mb: int = 4096
    file_size_mb: int = 64
    threads: int = 1

    def __post_init__(self) -> None:
        if isinstance(self.timeout_s, bool) or not isinstance(self.timeout_s, (int, float)):
            raise TypeError(f"timeout_s must be a number of seconds, got {self.timeout_s!r}")
        if not (math.isfinite(self.timeout_s) and self.timeout_s > 0):
            raise ValueError(f"timeout_s must be a positive, finite number, got {self.timeout_s}")
        for name, minimum in (("memory_mb", 64), ("file_size_mb", 1), ("threads", 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int):
                raise TypeError(f"{name} must be an integer, got {value!r}")
            if value < minimum:
                raise ValueError(f"{name} must be at least {minimum}, got {value}")

    @property
    def cpu_time_s(self) -> int:
        """Soft CPU-time limit (``RLIMIT_CPU``) in seconds, a backstop to the wall-clock one."""
        return math.ceil(CPU_TIME_FACTOR * self.timeout_s * self.threads) + CPU_TIME_MARGIN_S


def evaluate_in_sandbox(
    task: str,
    solution: str,
    settings: EvaluationSettings,
    limits: SandboxLimits = SandboxLimits(),  # noqa: B008 (frozen, so sharing it is safe)
    *,
    extra_python_path: Sequence[str | os.PathLike[str]] = (),
) -> Evaluation:
    """Evaluate ``solution`` for ``task`` in a fresh, limited worker process.

    Parameters
    ----------
    task : str
        A registered task name (see :mod:`sga_agent.registry`) or ``"module:callable"``, a
        zero-argument factory returning a :class:`~sga_agent.task.Task` (a plugin-development
        and testing aid: no entry point needed).
    solution : str
        The candidate's text (code), passed unchanged to the task's ``evaluate``.
    settings : EvaluationSettings
        Passed to the task's ``evaluate``; ``options`` must be JSON-serialisable.
    limits : SandboxLimits
        Time, memory, file-size and thread limits.
    extra_python_path : sequence of path-like
        Directories put in front of the worker's ``PYTHONPATH`` so that a ``"module:callable"``
        task outside the installed packages can be imported (plugin development, tests).

    Returns
    -------
    Evaluation
        The task's result, or an invalid one whose ``reason`` says what went wrong; ``seconds``
        is the wall time of the whole evaluation. Failures detected here (time limit, signal,
        exit status) carry the end of the worker's output in ``extras["log"]``.

    Raises
    ------
    TypeError
        ``settings.options`` is not JSON-serialisable (a caller error, not a candidate's).
    """
    try:
        request = json.dumps(
            {
                "task": task,
                "solution": solution,
                "settings": asdict(settings),
                "limits": asdict(limits),
                "parent_pid": os.getpid(),
            }
        ).encode()
    except (TypeError, ValueError) as error:
        raise TypeError(f"settings.options must be JSON-serialisable: {error}") from error
    start = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="sga-sandbox-", ignore_cleanup_errors=True) as root:
        evaluation = _run_worker(request, Path(root), limits, extra_python_path)
    evaluation.seconds = time.monotonic() - start
    return evaluation


class SandboxPool:
    """Run several sandboxed evaluations at once (one thread waits on each worker process).

    Parameters
    ----------
    max_workers : int
        Evaluations running at the same time.
    limits : SandboxLimits
        Limits of every evaluation.
    extra_python_path : sequence of path-like
        As for :func:`evaluate_in_sandbox`.
    """

    def __init__(
        self,
        max_workers: int = 1,
        limits: SandboxLimits = SandboxLimits(),  # noqa: B008 (frozen)
        *,
        extra_python_path: Sequence[str | os.PathLike[str]] = (),
    ) -> None:
        if isinstance(max_workers, bool) or not isinstance(max_workers, int) or max_workers < 1:
            raise ValueError(f"max_workers must be a positive integer, got {max_workers!r}")
        self.limits = limits
        self.extra_python_path = tuple(extra_python_path)
        self._executor = ThreadPoolExecutor(max_workers, thread_name_prefix="sga-sandbox")

    def submit(self, task: str, solution: str, settings: EvaluationSettings) -> Future[Evaluation]:
        """Start evaluating one solution; the future's result is its :class:`Evaluation`."""
        return self._executor.submit(
            evaluate_in_sandbox,
            task,
            solution,
            settings,
            self.limits,
            extra_python_path=self.extra_python_path,
        )

    def map(
        self, task: str, solutions: Iterable[str], settings: EvaluationSettings
    ) -> list[Evaluation]:
        """Evaluate every solution (concurrently); the evaluations in input order."""
        futures = [self.submit(task, solution, settings) for solution in solutions]
        return [future.result() for future in futures]

    def close(self) -> None:
        """Wait for running evaluations and release the threads."""
        self._executor.shutdown(wait=True)

    def __enter__(self) -> SandboxPool:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


def worker_environment(
    limits: SandboxLimits, extra_python_path: Sequence[str | os.PathLike[str]] = ()
) -> dict[str, str]:
    """The scrubbed environment of a worker: kept variables, thread counts, import path."""
    env = {
        name: value
        for name, value in os.environ.items()
        if (name in KEPT_VARIABLES or name.startswith(KEPT_PREFIXES)) and not looks_secret(name)
    }
    threads = str(limits.threads)
    for name in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        env[name] = threads
    env["TI_CPU_MAX_NUM_THREADS"] = threads
    env["PYTHONUNBUFFERED"] = "1"  # the last lines before a crash reach the log
    env["PYTHONFAULTHANDLER"] = "1"  # a Python traceback for a fatal signal, in the log
    path = [os.path.abspath(entry) for entry in extra_python_path]
    if env.get("PYTHONPATH"):
        path.append(env["PYTHONPATH"])
    if path:
        env["PYTHONPATH"] = os.pathsep.join(path)
    return env


def looks_secret(name: str) -> bool:
    """Whether an environment variable's name suggests a credential."""
    upper = name.upper()
    return any(marker in upper for marker in SECRET_MARKERS) or upper.startswith(SECRET_PREFIXES)


def _run_worker(
    request: bytes,
    root: Path,
    limits: SandboxLimits,
    extra_python_path: Sequence[str | os.PathLike[str]],
) -> Evaluation:
    """Start the worker in ``root/work``, wait for it, and read or explain its result."""
    workdir = root / "work"
    workdir.mkdir()
    log_path = root / "output.log"
    result_path = root / "result.json"
    with open(log_path, "wb") as log:
        try:
            process = subprocess.Popen(
                [sys.executable, "-m", "sga_agent.worker", str(result_path)],
                stdin=subprocess.PIPE,
                stdout=log,
                stderr=subprocess.STDOUT,
                cwd=workdir,
                env=worker_environment(limits, extra_python_path),
                start_new_session=True,
            )
        except OSError as error:
            return Evaluation.invalid(f"could not start the sandbox worker: {error}")
        timed_out = False
        try:
            process.communicate(request, timeout=limits.timeout_s)
        except subprocess.TimeoutExpired:
            timed_out = True
        finally:
            _kill_group(process)  # also stops anything the candidate left running
    if timed_out:
        return _failure(f"exceeded the time limit of {limits.timeout_s:g} s", log_path)
    if process.returncode < 0:
        return _failure(_signal_reason(-process.returncode, limits), log_path)
    if process.returncode > 0:
        reason = f"the sandbox worker exited with status {process.returncode}"
        return _failure(_with_last_line(reason, log_path), log_path)
    return _read_result(result_path, log_path)


def _kill_group(process: subprocess.Popen[bytes]) -> None:
    """SIGKILL the worker's process group (its session) and reap the worker."""
    with contextlib.suppress(ProcessLookupError, PermissionError):  # the group is already gone
        os.killpg(process.pid, signal.SIGKILL)
    process.wait()


_SIGNAL_CAUSES = {
    signal.SIGKILL: "possibly the system's out-of-memory killer",
    signal.SIGABRT: "a native library aborted, possibly on a failed memory allocation",
    signal.SIGSEGV: "a crash in native code",
    signal.SIGBUS: "a crash in native code",
}


def _signal_reason(number: int, limits: SandboxLimits) -> str:
    try:
        name = signal.Signals(number).name
    except ValueError:
        name = f"signal {number}"
    if number == signal.SIGXCPU:
        return f"killed by {name}: exceeded the CPU-time limit of {limits.cpu_time_s} s"
    if number == signal.SIGXFSZ:
        return f"killed by {name}: exceeded the file-size limit of {limits.file_size_mb} MB"
    description = signal.strsignal(number) or "unknown signal"
    cause = _SIGNAL_CAUSES.get(number)
    return f"killed by {name} ({description}{'; ' + cause if cause else ''})"


def _read_result(result_path: Path, log_path: Path) -> Evaluation:
    if not result_path.is_file():
        reason = _with_last_line("the sandbox worker exited without writing a result", log_path)
        return _failure(reason, log_path)
    try:
        data: Any = json.loads(result_path.read_text(encoding="utf-8"))
        evaluation = Evaluation.from_dict(data)
        if not isinstance(evaluation.valid, bool) or not isinstance(evaluation.reason, str):
            raise TypeError("'valid' must be a bool and 'reason' a string")
    except (OSError, ValueError, TypeError, AttributeError) as error:
        return _failure(f"unreadable result from the sandbox worker: {error}", log_path)
    return evaluation


def _failure(reason: str, log_path: Path) -> Evaluation:
    return Evaluation.invalid(reason, extras={"log": _log_tail(log_path)})


def _log_tail(log_path: Path) -> str:
    try:
        with open(log_path, "rb") as log:
            log.seek(max(0, log.seek(0, os.SEEK_END) - LOG_TAIL_CHARS))
            return log.read().decode("utf-8", errors="replace")
    except OSError:
        return ""


def _with_last_line(reason: str, log_path: Path) -> str:
    lines = [line.strip() for line in _log_tail(log_path).splitlines() if line.strip()]
    return f"{reason}: {lines[-1]}" if lines else reason
