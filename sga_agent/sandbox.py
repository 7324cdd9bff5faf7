"""Evaluating untrusted candidates in a separate, limited, isolated worker process.

A candidate solution is code an LLM wrote. It never runs in the search process: each evaluation
starts a fresh ``python -m sga_agent.worker`` (see :mod:`sga_agent.worker`) that loads the task,
calls its ``evaluate`` and writes the :class:`~sga_agent.task.Evaluation` to a result file. The
child runs in its own session (so the whole process group can be killed), in an empty temporary
directory removed afterwards (also its ``TMPDIR``), with stdin on ``/dev/null``, a scrubbed
environment, resource limits and, unless ``SandboxLimits.isolation`` is off, no network and no
writes outside that directory and the task caches (:mod:`sga_agent.isolation`). Whatever goes
wrong comes back as an invalid ``Evaluation`` with a ``status`` and a one-line ``reason``, never
as an exception in the caller:

=================  ============================================================================
status             cause
=================  ============================================================================
``timeout``        the wall-clock limit (the process group is killed) or the CPU-time limit
``out_of_memory``  ``MemoryError`` or a failed native allocation under the memory limit
``crashed``        a fatal signal (segfault, abort, kill), or an exit without a result
``error``          an exception in the task's ``evaluate`` or while loading the task (the last
                   traceback lines in ``extras["traceback"]``), or a worker not isolated as
                   :func:`~sga_agent.isolation.detect_isolation` promised
``unstable``       a valid evaluation whose loss is NaN or infinite
=================  ============================================================================

Tasks themselves return ``invalid`` (and ``unstable``, ``error``) for candidates they reject.

Output
------
The worker's stdout and stderr go to a pipe the parent drains while it waits, keeping only the
last :data:`LOG_TAIL_CHARS` bytes (``extras["log"]`` of a failure). A chatty candidate therefore
neither fills the disk nor fails by printing, as it would with a file under the file-size limit
(``OSError: File too large``).

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
own limit). The worker drops its capabilities, so it cannot raise these limits again.

Resource limits are applied by the worker to itself before it reads the candidate, rather than
in a ``preexec_fn``, because ``preexec_fn`` is unsafe when the parent has threads (as a
:class:`SandboxPool` does).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import re
import selectors
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

from sga_agent.isolation import Isolation, detect_isolation
from sga_agent.task import Evaluation, EvaluationSettings

#: Environment variables the worker keeps (besides the prefixes below).
KEPT_VARIABLES = frozenset(
    {
        "PATH",
        "HOME",  # Taichi's offline kernel cache lives under ~/.cache
        "LANG",
        "LANGUAGE",
        "VIRTUAL_ENV",
        "PYTHONPATH",
        "XDG_CACHE_HOME",
        "SGA_CACHE_DIR",  # ground-truth trajectories of the constitutive tasks
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

#: Bytes of the worker's output kept (its end), shown in ``extras["log"]`` of a failure.
LOG_TAIL_CHARS = 4000
#: Seconds of CPU time granted per thread and second of wall time, plus a fixed margin.
CPU_TIME_FACTOR = 1.5
CPU_TIME_MARGIN_S = 5
#: How often the parent checks whether a worker whose output is still open has exited.
_POLL_S = 0.1
_READ_CHUNK = 2**16
#: Output of a worker killed by a signal that points to a failed allocation.
_ALLOCATION_FAILURE = re.compile(r"bad_alloc|out of memory|cannot allocate memory", re.I)


@dataclass(frozen=True)
class SandboxLimits:
    """Resources one evaluation may use, and whether its worker is isolated.

    Parameters
    ----------
    timeout_s : float
        Wall-clock limit in seconds, worker start-up included; the process group is then killed.
    memory_mb : int
        Limit on the worker's writable private memory (``RLIMIT_DATA``) in MiB. Taichi alone
        accounts for ~1.1 GiB of it (a reserved memory pool); see the module docstring.
    file_size_mb : int
        Largest file the worker may write, in MiB (``RLIMIT_FSIZE``), its result included.
    threads : int
        Threads for numerical libraries (OpenMP, MKL, OpenBLAS, torch, Taichi's CPU backend).
        The CPU-time limit is ``CPU_TIME_FACTOR * timeout_s * threads + CPU_TIME_MARGIN_S``.
    isolation : bool
        Confine the worker as :mod:`sga_agent.isolation` describes (no network, no writes
        outside its directory and the task caches). Turn it off only to debug a task.
    """

    timeout_s: float = 900.0
    memory_mb: int = 4096
    file_size_mb: int = 64
    threads: int = 1
    isolation: bool = True

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
        if not isinstance(self.isolation, bool):
            raise TypeError(f"isolation must be True or False, got {self.isolation!r}")

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
        Time, memory, file-size and thread limits, and whether to isolate the worker.
    extra_python_path : sequence of path-like
        Directories put in front of the worker's ``PYTHONPATH`` so that a ``"module:callable"``
        task outside the installed packages can be imported (plugin development, tests).

    Returns
    -------
    Evaluation
        The task's result, or an invalid one whose ``status`` and ``reason`` say what went wrong
        (see the module docstring); ``seconds`` is the wall time of the whole evaluation.
        Failures detected here (limits, signals) carry the end of the worker's output in
        ``extras["log"]``.

    Raises
    ------
    TypeError
        ``settings.options`` is not JSON-serialisable (a caller error, not a candidate's).
    """
    request = _request(task, solution, settings, limits)
    return _evaluate(request, limits, tuple(extra_python_path))


class SandboxPool:
    """Evaluate candidates concurrently, each in its own sandbox worker.

    Identical candidates are the caller's to skip: :func:`~sga_agent.fingerprint.fingerprint`
    tells them apart (the search loop evaluates each fingerprint once, across resumes too).

    Parameters
    ----------
    max_workers : int, optional
        Evaluations running at the same time; default: the number of CPU cores.
    limits : SandboxLimits
        Limits of every evaluation.
    extra_python_path : sequence of path-like
        As for :func:`evaluate_in_sandbox`.
    """

    def __init__(
        self,
        max_workers: int | None = None,
        limits: SandboxLimits = SandboxLimits(),  # noqa: B008 (frozen)
        *,
        extra_python_path: Sequence[str | os.PathLike[str]] = (),
    ) -> None:
        if max_workers is None:
            max_workers = os.cpu_count() or 1
        if isinstance(max_workers, bool) or not isinstance(max_workers, int) or max_workers < 1:
            raise ValueError(f"max_workers must be a positive integer, got {max_workers!r}")
        self.max_workers = max_workers
        self.limits = limits
        self.extra_python_path = tuple(extra_python_path)
        self._executor = ThreadPoolExecutor(max_workers, thread_name_prefix="sga-sandbox")

    def isolation(self) -> Isolation:
        """How the workers are isolated, for the run's record."""
        if not self.limits.isolation:
            return Isolation.none("disabled (SandboxLimits.isolation=False)")
        return detect_isolation()

    def submit(self, task: str, solution: str, settings: EvaluationSettings) -> Future[Evaluation]:
        """Start evaluating one solution; the future's result is its :class:`Evaluation`.

        Raises ``TypeError`` at once if ``settings.options`` is not JSON-serialisable; a bad
        candidate never raises: its future holds an invalid Evaluation.
        """
        request = _request(task, solution, settings, self.limits)
        return self._executor.submit(self._evaluate, request)

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

    def _evaluate(self, request: bytes) -> Evaluation:
        try:
            return _evaluate(request, self.limits, self.extra_python_path)
        except Exception as error:  # the sandbox itself failed, e.g. no space for its folder
            reason = f"the sandbox failed: {type(error).__name__}: {error}"
            return Evaluation.invalid(reason, status="error")


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
    env["TI_SKIP_VERSION_CHECK"] = "ON"  # else ti.init posts to taichi.graphics from a thread
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


def _request(
    task: str, solution: str, settings: EvaluationSettings, limits: SandboxLimits
) -> bytes:
    """The worker's request as JSON; ``TypeError`` if ``settings.options`` is not serialisable."""
    isolation = asdict(detect_isolation()) if limits.isolation else None
    try:
        request = {
            "task": task,
            "solution": solution,
            "settings": asdict(settings),
            "limits": asdict(limits),
            "isolation": isolation,
            "parent_pid": os.getpid(),
        }
        return json.dumps(request).encode()
    except (TypeError, ValueError) as error:
        raise TypeError(f"settings.options must be JSON-serialisable: {error}") from error


def _evaluate(
    request: bytes, limits: SandboxLimits, extra_python_path: Sequence[str | os.PathLike[str]]
) -> Evaluation:
    """Run one worker in a fresh temporary directory; its evaluation, timed."""
    start = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="sga-sandbox-", ignore_cleanup_errors=True) as root:
        evaluation = _run_worker(request, Path(root), limits, extra_python_path)
    evaluation.seconds = time.monotonic() - start
    return evaluation


def _run_worker(
    request: bytes,
    root: Path,
    limits: SandboxLimits,
    extra_python_path: Sequence[str | os.PathLike[str]],
) -> Evaluation:
    """Start the worker in ``root/work``, wait for it, and read or explain its result."""
    workdir = root / "work"
    workdir.mkdir()
    request_path, result_path = root / "request.json", root / "result.json"
    request_path.write_bytes(request)
    env = worker_environment(limits, extra_python_path)
    env["TMPDIR"] = str(workdir)
    command = [sys.executable, "-m", "sga_agent.worker", str(request_path), str(result_path)]
    try:
        process = subprocess.Popen(
            command,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            cwd=workdir,
            env=env,
            start_new_session=True,
        )
    except OSError as error:
        return Evaluation.invalid(f"could not start the sandbox worker: {error}", status="error")
    output = _OutputTail()
    try:
        finished = output.collect(process, time.monotonic() + limits.timeout_s)
    finally:
        _kill_group(process)  # also stops anything the candidate left running
    log = output.text()
    if not finished:
        return _failure(f"exceeded the time limit of {limits.timeout_s:g} s", "timeout", log)
    if process.returncode < 0:
        return _killed(-process.returncode, limits, log)
    if process.returncode > 0:
        reason = f"the sandbox worker exited with status {process.returncode}"
        return _failure(_with_last_line(reason, log), "crashed", log)
    return _read_result(result_path, log)


class _OutputTail:
    """The last :data:`LOG_TAIL_CHARS` bytes of a worker's output, and how many came before."""

    def __init__(self) -> None:
        self._tail = bytearray()
        self._dropped = 0

    def collect(self, process: subprocess.Popen[bytes], deadline: float) -> bool:
        """Drain the worker's output until it exits; False if ``deadline`` comes first."""
        assert process.stdout is not None  # Popen with stdout=PIPE
        fd = process.stdout.fileno()
        os.set_blocking(fd, False)
        with selectors.DefaultSelector() as selector:
            selector.register(fd, selectors.EVENT_READ)
            while process.poll() is None:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return False
                if selector.select(min(remaining, _POLL_S)) and not self._read(fd):
                    try:  # the output is closed: only the exit is left to wait for
                        process.wait(max(0.0, deadline - time.monotonic()))
                    except subprocess.TimeoutExpired:
                        return False
        self._read(fd)  # what it wrote just before exiting
        return True

    def text(self) -> str:
        """The kept output, decoded, after a note of how much was dropped."""
        text = self._tail.decode("utf-8", errors="replace")
        return f"[{self._dropped} earlier bytes dropped]\n{text}" if self._dropped else text

    def _read(self, fd: int, chunks: int = 16) -> bool:
        """Read what is available (``chunks`` reads at most); False at the end of the output."""
        for _ in range(chunks):
            try:
                chunk = os.read(fd, _READ_CHUNK)
            except BlockingIOError:
                return True
            if not chunk:
                return False
            self._tail += chunk
            excess = len(self._tail) - LOG_TAIL_CHARS
            if excess > 0:
                del self._tail[:excess]
                self._dropped += excess
        return True


def _kill_group(process: subprocess.Popen[bytes]) -> None:
    """SIGKILL the worker's process group (its session), reap the worker, close its output."""
    with contextlib.suppress(ProcessLookupError, PermissionError):  # the group is already gone
        os.killpg(process.pid, signal.SIGKILL)
    process.wait()
    if process.stdout is not None:
        process.stdout.close()


_SIGNAL_CAUSES = {
    signal.SIGKILL: "possibly the system's out-of-memory killer",
    signal.SIGABRT: "a native library aborted, possibly on a failed memory allocation",
    signal.SIGSEGV: "a crash in native code",
    signal.SIGBUS: "a crash in native code",
}


def _killed(number: int, limits: SandboxLimits, log: str) -> Evaluation:
    """The evaluation of a worker killed by signal ``number``."""
    try:
        name = signal.Signals(number).name
    except ValueError:
        name = f"signal {number}"
    if number == signal.SIGXCPU:
        reason = f"killed by {name}: exceeded the CPU-time limit of {limits.cpu_time_s} s"
        return _failure(reason, "timeout", log)
    if number == signal.SIGXFSZ:
        reason = f"killed by {name}: exceeded the file-size limit of {limits.file_size_mb} MB"
        return _failure(reason, "crashed", log)
    if _ALLOCATION_FAILURE.search(log):
        reason = f"killed by {name} after a failed allocation (memory limit {limits.memory_mb} MB)"
        return _failure(reason, "out_of_memory", log)
    description = signal.strsignal(number) or "unknown signal"
    cause = _SIGNAL_CAUSES.get(number)
    reason = f"killed by {name} ({description}{'; ' + cause if cause else ''})"
    return _failure(reason, "crashed", log)


def _read_result(result_path: Path, log: str) -> Evaluation:
    try:
        text = result_path.read_text(encoding="utf-8")
    except OSError:
        text = ""
    if not text:  # the worker creates the file first and writes it last
        reason = "the sandbox worker exited without writing a result"
        return _failure(_with_last_line(reason, log), "crashed", log)
    try:
        data: Any = json.loads(text)
        evaluation = Evaluation.from_dict(data)
        if not isinstance(evaluation.valid, bool) or not isinstance(evaluation.reason, str):
            raise TypeError("'valid' must be a bool and 'reason' a string")
    except (ValueError, TypeError, AttributeError) as error:
        return _failure(f"unreadable result from the sandbox worker: {error}", "error", log)
    return evaluation


def _failure(reason: str, status: str, log: str) -> Evaluation:
    return Evaluation.invalid(reason, status=status, extras={"log": log})


def _with_last_line(reason: str, log: str) -> str:
    lines = [line.strip() for line in log.splitlines() if line.strip()]
    return f"{reason}: {lines[-1]}" if lines else reason
