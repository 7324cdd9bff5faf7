"""Evaluating untrusted candidates: capture in a confined process, fit in a trusted one.

A candidate solution is code a model wrote, and code can forge anything in the process that
runs it: monkeypatch the loss, write the result file, poison caches. So it never runs where its
score is computed. Each evaluation has two steps, each in its own process:

1. **Capture** (untrusted). A capture server (``python -m sga_agent.capture_server TASK``), one
   per pool slot, has the task and its libraries loaded; per candidate it forks a confined
   process (:mod:`sga_agent.isolation`: user ``nobody``, PID, network, mount and IPC
   namespaces, read-only and private file systems, Landlock, resource limits) that runs the
   task's ``capture(solution)`` and sends back JSON data through a pipe the server owns.
2. **Fit** (trusted). A fit worker (``python -m sga_agent.fit_worker TASK``), one per pool slot
   and warm from one candidate to the next, runs the task's ``evaluate(data, settings)``. It
   never imports or runs candidate code; the task checks the data before using it. The
   progress notes it writes before its answer (its warm-up, the fit's epochs; see
   :mod:`sga_agent.helper_protocol`) go to the caller's ``progress`` callable, if any, and
   nowhere else: they are shown, never part of the result.

Whatever goes wrong comes back as an invalid ``Evaluation`` with a ``status`` and a one-line
``reason``, never as an exception in the caller. A helper that fails in a way the candidate may
not have caused (killed from outside, out of memory in a worker that had evaluated before)
first gets the candidate's step tried once more on a fresh helper (``extras["retried"]`` says
why; see :class:`EvaluationSlot`); a warm fit worker is replaced by a fresh one, warmed up
beforehand, once it has grown (:class:`Recycling`).

=================  ============================================================================
status             cause
=================  ============================================================================
``invalid``        the task refused the solution (in its capture, or its data in the fit)
``timeout``        the wall-clock limit (capture and fit together) or the CPU-time limit
``out_of_memory``  a failed allocation under the memory limit (capture or fit)
``crashed``        the capture process was killed by a signal or exited without a result; the
                   fit worker died
``error``          an exception in the capture or the fit (the end of the traceback in
                   ``extras["traceback"]``), or a capture process not isolated as
                   :func:`~sga_agent.isolation.detect_isolation` promised
``unstable``       a valid evaluation whose loss is NaN or infinite
=================  ============================================================================

Memory limits
-------------
The capture process's address space is limited (``RLIMIT_AS``: ``memory_mb`` beyond what the
server had mapped), which counts shared mappings too. The fit worker, which loads Taichi,
limits its *writable private memory* with ``RLIMIT_DATA`` instead: measured with Taichi 1.7 and
torch 2 on CPU, a process that has initialised Taichi and used torch has ~0.3 GB resident but
2.25 GB of address space (``ti.init`` alone reserves a 1 GiB pool), so ``RLIMIT_AS`` would fail
it. Allow ~1.2 GB for Taichi's pool and libraries on top of what a fit needs (the default,
4 GB, does). The fit runs only trusted code, so its shared mappings are the task's own.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import queue
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from sga_agent.helper_protocol import NOTE, FitSettings, note_of
from sga_agent.isolation import Isolation, detect_isolation
from sga_agent.task import STATUSES, Evaluation, EvaluationSettings, FitProgress
from sga_agent.task.device import VARIABLE as DEVICE_VARIABLE
from sga_agent.task.device import check_device_name

#: Told each progress note of an evaluation (:class:`~sga_agent.task.FitProgress`).
ProgressCallback = Callable[[FitProgress], None]

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
#: Variables naming caches, which the fit uses and the capture is not told about.
CACHE_VARIABLES = ("SGA_CACHE_DIR", "XDG_CACHE_HOME", "TI_OFFLINE_CACHE_FILE_PATH")
#: Prefixes of further kept variables (locale, Taichi settings, CUDA device selection).
KEPT_PREFIXES = ("LC_", "TI_", "CUDA_")
#: A variable whose name contains one of these (upper-cased) is dropped even if kept above.
SECRET_MARKERS = ("KEY", "TOKEN", "SECRET", "PASSWORD", "PASSWD", "CREDENTIAL", "AUTH", "COOKIE")
SECRET_PREFIXES = ("OPENAI_", "ANTHROPIC_", "AWS_", "AZURE_", "GOOGLE_", "GEMINI_", "HF_")

#: Characters of a helper process's log kept (its end), shown in ``extras["log"]`` of a failure.
LOG_TAIL_CHARS = 4000
#: Seconds of CPU time granted per thread and second of wall time, plus a fixed margin.
CPU_TIME_FACTOR = 1.5
CPU_TIME_MARGIN_S = 5
#: Seconds a capture server or fit worker may take to start (imports, warm-up captures).
START_TIMEOUT_S = 600.0
#: Seconds a helper may take to exit once its input is closed (Taichi writes its cache then).
CLOSE_TIMEOUT_S = 60.0
#: Longest reason taken from a capture process (untrusted text) into an Evaluation.
MAX_REASON_CHARS = 300
_READ_CHUNK = 2**16


@dataclass(frozen=True)
class SandboxLimits:
    """Resources one evaluation may use, and whether its capture process is confined.

    Parameters
    ----------
    timeout_s : float
        Wall-clock limit in seconds of one evaluation, capture and fit together.
    memory_mb : int
        Memory limit in MiB: the capture process's address space beyond what its server had
        mapped, and the fit worker's writable private memory (Taichi alone accounts for
        ~1.1 GiB of it); see the module docstring.
    file_size_mb : int
        Largest file the capture process may write, in MiB (it may write none anyway).
    threads : int
        Threads of Taichi's parallel loops in the fit; torch, OpenMP and BLAS run on one
        (their operations on an evaluation's tensors are too small to share), and so does the
        capture. A parallel loop runs only while other processes leave a core for each thread
        (:func:`taichi_mpm.runtime.parallel_worthwhile`), so a busy machine does not stall it.
        Searches and ``sga-agent evaluate`` give each evaluation the machine's cores divided
        by the evaluations running at once (:func:`threads_per_worker`), set when its fit
        worker starts. The CPU-time limit of a capture is
        ``CPU_TIME_FACTOR * timeout_s * threads + CPU_TIME_MARGIN_S``.
    isolation : bool
        Confine the capture process as :mod:`sga_agent.isolation` describes. Turn it off only
        to debug a task: candidate code then runs with the search's user and files.
    capture_timeout_s : float
        Wall-clock limit of the capture step alone (within ``timeout_s``).
    device : str
        Where the fit computes (:mod:`sga_agent.task.device`): ``cpu`` or ``cuda``, set in its
        fit worker's environment when it starts.
    """

    timeout_s: float = 900.0
    memory_mb: int = 4096
    file_size_mb: int = 64
    threads: int = 1
    isolation: bool = True
    capture_timeout_s: float = 120.0
    device: str = "cpu"

    def __post_init__(self) -> None:
        for name in ("timeout_s", "capture_timeout_s"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise TypeError(f"{name} must be a number of seconds, got {value!r}")
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive, finite number, got {value}")
        for name, minimum in (("memory_mb", 64), ("file_size_mb", 1), ("threads", 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int):
                raise TypeError(f"{name} must be an integer, got {value!r}")
            if value < minimum:
                raise ValueError(f"{name} must be at least {minimum}, got {value}")
        if not isinstance(self.isolation, bool):
            raise TypeError(f"isolation must be True or False, got {self.isolation!r}")
        check_device_name(self.device)

    @property
    def cpu_time_s(self) -> int:
        """Soft CPU-time limit (``RLIMIT_CPU``) in seconds, a backstop to the wall-clock one."""
        return math.ceil(CPU_TIME_FACTOR * self.timeout_s * self.threads) + CPU_TIME_MARGIN_S


class HelperFailure(RuntimeError):
    """A capture server or fit worker did not start, died or stopped answering.

    ``returncode`` is the helper's exit status when it ended by itself (negative: killed by
    that signal), None when it was killed for not answering in time or answering garbage.
    """

    def __init__(self, message: str, returncode: int | None = None) -> None:
        super().__init__(message)
        self.returncode = returncode


#: Every helper process started and not yet reaped, so that an interrupted caller can kill
#: them (a set changes atomically under the GIL: no lock, which a signal handler could not take).
_RUNNING: set[_LineProcess] = set()


def kill_every_helper() -> None:
    """SIGKILL every capture server and fit worker this process started (and their process
    groups): the last resort of an interrupted search, safe to call from a signal handler."""
    for helper in list(_RUNNING):
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(helper.process.pid, signal.SIGKILL)


class _LineProcess:
    """A helper process answering one JSON line per JSON line sent; its log in a file."""

    def __init__(self, command: list[str], env: dict[str, str], folder: Path, name: str) -> None:
        self.log_path = folder / f"{name}.log"
        with open(self.log_path, "wb") as log:
            self.process = subprocess.Popen(
                command,
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=log,
                cwd=folder,
                env=env,
                start_new_session=True,
            )
        _RUNNING.add(self)
        self._pending = bytearray()

    def ask(
        self,
        message: dict[str, Any] | None,
        timeout_s: float,
        last: bool = False,
        progress: ProgressCallback | None = None,
    ) -> dict[str, Any]:
        """Send ``message`` (None: just wait) and return the answer line, parsed; ``last``:
        close the input once it is sent (the process exits once it has answered). Progress
        notes that come before the answer go to ``progress`` (see :func:`_tell`).

        Raises :class:`HelperFailure` (after killing the process) when it does not answer in
        time, exits, or answers something that is not a JSON object.
        """
        assert self.process.stdin is not None and self.process.stdout is not None
        deadline = time.monotonic() + timeout_s
        try:
            if message is not None:
                self.process.stdin.write((json.dumps(message) + "\n").encode())
                self.process.stdin.flush()
            if last:
                self.end_input()
            while NOTE in (answer := _parsed(self._read_line(deadline))):
                _tell(progress, note_of(answer))
            return answer
        except (OSError, ValueError, HelperFailure) as error:
            raise self._failed(error) from None

    def send(self, message: dict[str, Any]) -> None:
        """Send ``message`` without waiting for its answer (read it with :meth:`poll` or
        :meth:`ask`); a process that has gone shows when its answer is read."""
        assert self.process.stdin is not None
        with contextlib.suppress(OSError):
            self.process.stdin.write((json.dumps(message) + "\n").encode())
            self.process.stdin.flush()

    def poll(self) -> dict[str, Any] | None:
        """The next answer if it has come, else None, without waiting (progress notes before
        it are dropped); raises :class:`HelperFailure` (after killing the process) as
        :meth:`ask` does."""
        try:
            while self._fill(0.0):
                if NOTE not in (answer := _parsed(self._read_line(time.monotonic()))):
                    return answer
        except (OSError, ValueError, HelperFailure) as error:
            raise self._failed(error) from None
        return None

    def _failed(self, error: Exception) -> HelperFailure:
        """Kill the process; the failure, with its exit status if it had ended by itself."""
        message = str(error) or type(error).__name__
        code = self.process.poll()
        if code is None and isinstance(error, BrokenPipeError):  # it is exiting: its status
            with contextlib.suppress(subprocess.TimeoutExpired):
                code = self.process.wait(1.0)
        if code is not None and not isinstance(error, HelperFailure):
            message = _ended(code)
        self.kill()
        return HelperFailure(message, code)

    def _read_line(self, deadline: float) -> bytes:
        while not self._fill(deadline - time.monotonic()):
            if deadline - time.monotonic() <= 0:
                raise HelperFailure("timeout")
        line, _, rest = bytes(self._pending).partition(b"\n")
        self._pending = bytearray(rest)
        return line

    def _fill(self, wait_s: float) -> bool:
        """Read what the process sent, waiting at most ``wait_s`` for it; whether a whole line
        is there. :class:`HelperFailure` once its output has ended."""
        assert self.process.stdout is not None
        fd = self.process.stdout.fileno()
        while b"\n" not in self._pending:
            ready, _, _ = select.select([fd], [], [], max(wait_s, 0.0))
            if not ready:
                return False
            chunk = os.read(fd, _READ_CHUNK)
            if not chunk:
                raise HelperFailure(_ended(self.process.wait()), self.process.returncode)
            self._pending += chunk
            wait_s = 0.0  # what is there already, no more waiting
        return True

    def rss_mb(self) -> float | None:
        """Its resident memory in MB (:func:`resident_mb`)."""
        return resident_mb(self.process.pid)

    @property
    def alive(self) -> bool:
        return self.process.poll() is None

    def log_tail(self) -> str:
        try:
            text = self.log_path.read_bytes()[-LOG_TAIL_CHARS:]
        except OSError:
            return ""
        return text.decode("utf-8", errors="replace")

    def end_input(self) -> None:
        """Close the process's input: it finishes what it does and exits normally."""
        with contextlib.suppress(OSError):
            if self.process.stdin is not None:
                self.process.stdin.close()

    def close(self, timeout_s: float = CLOSE_TIMEOUT_S) -> None:
        """End the process by closing its input, so that it exits normally (Taichi writes its
        kernel cache at exit); SIGKILL it if it has not exited after ``timeout_s``."""
        self.end_input()
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.process.wait(timeout_s)
        self.kill()

    def kill(self) -> None:
        """SIGKILL the process group, reap the process, close its pipes."""
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(self.process.pid, signal.SIGKILL)
        self.process.wait()
        _RUNNING.discard(self)
        for stream in (self.process.stdin, self.process.stdout):
            if stream is not None:
                with contextlib.suppress(OSError):
                    stream.close()


#: Signals that reach a process from outside (an operator, the OOM killer, a supervisor), as
#: opposed to a fault of the code it runs (SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT) or a
#: resource limit it exceeded (SIGXCPU, SIGXFSZ).
OUTSIDE_SIGNALS = frozenset(
    {signal.SIGKILL, signal.SIGTERM, signal.SIGINT, signal.SIGHUP, signal.SIGQUIT}
)
#: Evaluations a warm fit worker runs before a fresh one replaces it, a backstop (see
#: :class:`Recycling`).
FIT_RECYCLE_EVALUATIONS = 500
#: Growth of a fit worker's resident memory past its reference that gets it replaced.
FIT_RECYCLE_GROWTH = 1.15
#: Evaluations of a fit worker after which its resident memory is its reference.
FIT_RECYCLE_REFERENCE = 25


@dataclass(frozen=True)
class Recycling:
    """When a slot replaces its warm fit worker by a fresh process (see :class:`EvaluationSlot`).

    Measured with ``benchmarks/soak.py`` (elastic, 100 steps, one epoch, the GP's laws, two
    workers, 450 evaluations, on two busy cores): a fit worker's resident memory rises steeply
    over its first ~25 evaluations (to ~530 MB: first uses of torch and Taichi), then by
    ~0.5 MB per evaluation without end (~600 MB after 150 evaluations of the worker; its
    ``VmData``, which ``RLIMIT_DATA`` limits, grows alike). Each compiled law leaves Taichi
    kernels that Taichi 1.7 cannot free (~0.9 MB, see :class:`bridges.scalar_law.CompiledLaw`),
    so the growth follows the laws a worker compiles, not its evaluations: a count would
    replace workers needlessly where laws run in torch, and too late where they are large. So
    memory decides: a worker is replaced once its RSS exceeds 1.15 times what it had after its
    25th evaluation. In that soak each slot's worker was replaced once, after ~180 evaluations
    at ~610 MB; the slot's fit memory peaked at 1.15-1.16x its value after the run's first
    50 evaluations and ended at 0.98-1.0x; the evaluations per minute did not fall (46 for
    the first hundred, 51 for the last); the capture servers stayed at 340 MB. A count (500)
    stays as a backstop for growth RSS would not show. A replacement costs a start and a
    warm-up of the task (seconds of one core), spent beside the slot's evaluations.

    Parameters
    ----------
    evaluations : int or None
        Evaluations a fit worker runs before it is replaced (None: no count).
    growth : float or None
        Replace a fit worker whose resident memory exceeds ``growth`` times its reference (None:
        its memory is not watched).
    reference : int
        Evaluations after which a fit worker's resident memory is its reference: by then it
        has loaded and compiled what every evaluation needs.
    """

    evaluations: int | None = FIT_RECYCLE_EVALUATIONS
    growth: float | None = FIT_RECYCLE_GROWTH
    reference: int = FIT_RECYCLE_REFERENCE

    def __post_init__(self) -> None:
        if self.evaluations is not None and self.evaluations < 1:
            raise ValueError(f"evaluations must be at least 1 or None, got {self.evaluations}")
        if self.growth is not None and not self.growth > 1:
            raise ValueError(f"growth must be above 1 or None, got {self.growth}")
        if self.reference < 1:
            raise ValueError(f"reference must be at least 1, got {self.reference}")


@dataclass
class _Blameless:
    """A helper's failure the candidate may not have caused: ``evaluation`` is its verdict
    unless its step, tried again on a fresh helper, ends otherwise; ``why`` is said in
    ``extras["retried"]``."""

    evaluation: Evaluation
    why: str


def _verdict(outcome: Any) -> Any:
    """``outcome``, with a :class:`_Blameless` failure that is not tried again as its verdict."""
    return outcome.evaluation if isinstance(outcome, _Blameless) else outcome


class EvaluationSlot:
    """One pool slot: a capture server and a trusted fit worker, started when first needed.

    The capture server is kept for as long as the task is the same; the fit worker for as long
    as the task and the settings' ``options`` are the same (a task may set up its process from
    them, e.g. the floating-point precision). Helpers that fail are started afresh.

    Warm fit workers are recycled (``recycling``, see :class:`Recycling`): once one is due, a
    fresh one starts and warms up in the background while the old one goes on evaluating; the
    first fit after the fresh one has finished its warm-up goes to it, and the old one exits
    normally. No candidate waits for the replacement.

    Blame only the candidate: a step whose helper fails in a way the candidate cannot have
    caused, or may not have, is tried once more on a fresh helper (the capture again, or the
    fit again with the same captured data), and ``extras["retried"]`` says why; what the retry
    ends with is the verdict. Each step is tried at most twice, so a candidate is never
    evaluated without end, and it gets one evaluation. Retried:

    * the fit worker died (any signal or exit status, while it starts or fits): it never runs
      candidate code, so a SIGKILL or SIGTERM came from outside (an operator, the OOM killer),
      and a death its data causes repeats on the fresh worker;
    * the fit ran out of memory in a worker that had evaluated earlier candidates, whose
      leftovers may be the cause (out of memory on a fresh worker is the verdict);
    * the capture server died, or was killed by a signal while it started: the server never
      runs candidate code and, isolated, the candidate cannot signal it (ambiguous without
      isolation: the retry decides);
    * the confined capture process was killed by a signal from outside (:data:`OUTSIDE_SIGNALS`:
      SIGKILL, SIGTERM, ...): an operator or the OOM killer, or the candidate (it may signal
      itself, or exceed the hard CPU limit, which is SIGKILL): ambiguous.

    Never retried, the candidate's own doing: the capture process faulted (SIGSEGV, SIGBUS,
    SIGABRT, ...), exceeded a limit (SIGXCPU, SIGXFSZ, a failed allocation: out of memory),
    exited without a result (``os._exit``), raised, or was refused; timeouts (a retry would
    double the wait); and a helper that answered garbage (killed by the slot).

    A ``one_shot`` slot evaluates one candidate: its fit worker warms up only the first stage
    of the task's warm-up (what every evaluation needs; see :mod:`.fit_worker`), and each
    helper's input is closed once its request is sent, so that both exit as soon as they have
    answered. It recycles nothing.
    """

    def __init__(
        self,
        limits: SandboxLimits,
        extra_python_path: Sequence[str | os.PathLike[str]] = (),
        one_shot: bool = False,
        recycling: Recycling = Recycling(),  # noqa: B008 (frozen)
    ) -> None:
        self.limits = limits
        self.extra_python_path = tuple(extra_python_path)
        self.one_shot = one_shot
        self.recycling = recycling
        self._folder = Path(tempfile.mkdtemp(prefix="sga-sandbox-"))
        self._capture: tuple[str, _LineProcess] | None = None
        self._capture_ready = False
        self._fit: tuple[str, _LineProcess] | None = None
        self._fit_awaiting = 0  # answers (ready, end of warm-up) before its first request
        self._fit_evaluations = 0  # by the current fit worker
        self._fit_reference: float | None = None  # its RSS after recycling.reference of them
        self._spare: tuple[str, _LineProcess] | None = None  # its replacement, warming up
        self._spare_awaiting = 0
        self._retired: list[tuple[float, _LineProcess]] = []  # exiting, since when
        self._fit_workers_started = 0
        self._stopped = False

    def evaluate(
        self,
        task: str,
        solution: str,
        settings: FitSettings,
        on_captured: Callable[[str, str], None] | None = None,
        captured: dict[str, Any] | None = None,
        progress: ProgressCallback | None = None,
    ) -> Evaluation:
        """Capture then fit one solution; every failure is an invalid Evaluation.

        A fit worker that is not running yet is started first, so that it loads while the
        capture runs. ``on_captured(task, options)`` (the options as JSON) is called once the
        capture step has ended. A step tried again (see the class docstring) has the time it
        had the first time. ``captured``, the data an earlier evaluation of this solution
        captured (its ``artifacts["captured"]``, inert data the fit checks again), skips the
        capture: the solution is fitted again, at another fidelity say. ``progress`` is told
        how far it has come: "capturing the solution", "starting the fit worker", then the
        fit worker's notes (warm-up, the fit's epochs); never what the evaluation returns.
        """
        start = time.monotonic()
        options, request = settings.options, settings.request()
        self._start_fit_worker(task, options)
        retried: list[str] = []
        attempt = start
        outcome: dict[str, Any] | Evaluation | _Blameless | None = captured
        if outcome is None:
            _tell(progress, FitProgress("capturing the solution"))
            outcome = self._captured(task, solution)
            if isinstance(outcome, _Blameless) and not self._stopped:
                retried.append(outcome.why)
                attempt = time.monotonic()
                outcome = self._captured(task, solution)
            outcome = _verdict(outcome)
        captured_at = time.monotonic()
        if on_captured is not None:
            on_captured(task, options)
        if isinstance(outcome, Evaluation):
            evaluation = outcome
        else:
            remaining = self.limits.timeout_s - (captured_at - attempt)
            fitted = self._fitted(outcome, request, remaining, progress)
            if isinstance(fitted, _Blameless) and not self._stopped:
                retried.append(fitted.why)
                self._start_fit_worker(task, options)
                fitted = self._fitted(outcome, request, remaining, progress)
            evaluation = _verdict(fitted)
        evaluation.seconds = time.monotonic() - start
        # to the millisecond below, never above the whole evaluation's seconds
        capture_ms = math.floor(1000 * (captured_at - start))
        evaluation.extras.setdefault("capture_seconds", capture_ms / 1000)
        if retried:
            evaluation.extras["retried"] = "; ".join(retried)
        return evaluation

    def start_helpers(self, task: str, options: str) -> None:
        """Start the helpers for ``task`` and ``options`` (JSON) unless they run, without
        waiting for them: they load, and the fit worker warms up, while others work."""
        self._start_fit_worker(task, options)
        self._start_capture_server(task)

    def close(self) -> None:
        """Stop the helper processes (letting them exit normally, all at once; a replacement
        still warming up is killed) and remove their folder."""
        self.end_input()
        for helper in self._helpers():
            helper.close()
        self._capture = self._fit = None
        self._retired = []
        shutil.rmtree(self._folder, ignore_errors=True)

    def end_input(self) -> None:
        """Close the helpers' input: they exit normally once done, without being waited for
        (:meth:`close` waits). A replacement fit worker still warming up is killed: it would
        finish its warm-up first, for nothing."""
        if self._spare is not None:
            self._spare[1].kill()
            self._spare = None
        for helper in self._helpers():
            helper.end_input()

    def _helpers(self) -> list[_LineProcess]:
        current = [helper[1] for helper in (self._capture, self._fit, self._spare) if helper]
        return current + [helper for _, helper in self._retired]

    def kill(self) -> None:
        """Kill the helper processes now and start no new ones: an evaluation running in
        another thread ends at once, invalid ("the pool was stopped")."""
        self._stopped = True
        for helper in self._helpers():
            helper.kill()

    # ------------------------------------------------------------------ capture

    def _captured(self, task: str, solution: str) -> dict[str, Any] | Evaluation | _Blameless:
        try:
            server = self._capture_server(task)
        except HelperFailure as error:
            failure = Evaluation.invalid(
                f"the capture server did not start: {error}", status="error"
            )
            return _blameless_start(failure, "the capture server", error)
        timeout = min(self.limits.capture_timeout_s, self.limits.timeout_s)
        request = {
            "solution": solution,
            "timeout_s": timeout,
            "limits": asdict(self.limits),
            "isolation": asdict(detect_isolation()) if self.limits.isolation else None,
        }
        try:
            reply = server.ask(request, timeout + 30, last=self.one_shot)
        except HelperFailure as error:
            self._capture = None
            if str(error) == "timeout":
                return _failure(f"exceeded the time limit of {timeout:g} s", "timeout", "")
            failure = _failure(f"the capture server failed: {error}", "crashed", server.log_tail())
            if error.returncode is None:  # killed here for answering garbage
                return failure
            return _Blameless(failure, _death("the capture server", error.returncode))
        outcome = _capture_outcome(reply, self.limits, timeout)
        number = int(reply.get("signal") or 0) if reply.get("status") == "crashed" else 0
        if number in OUTSIDE_SIGNALS:
            return _Blameless(outcome, _death("the capture process", -number))
        return outcome

    def _capture_server(self, task: str) -> _LineProcess:
        """The capture server for ``task``, started unless it runs, once it has said it is
        ready."""
        self._start_capture_server(task)
        if self._capture is None:
            raise HelperFailure("the pool was stopped")
        server = self._capture[1]
        if not self._capture_ready:
            try:
                ready = server.ask(None, START_TIMEOUT_S)
            except HelperFailure as error:
                self._capture = None
                message = _last_line(server.log_tail()) or str(error)
                raise HelperFailure(message, error.returncode) from None
            if not ready.get("ready"):
                self._capture = None
                server.kill()
                raise HelperFailure("no ready line")
            self._capture_ready = True
        return server

    def _start_capture_server(self, task: str) -> None:
        """Start a capture server for ``task`` unless one runs; do not wait for it."""
        if self._capture is not None and self._capture[0] == task and self._capture[1].alive:
            return
        if self._capture is not None:
            self._capture[1].kill()
            self._capture = None
        if self._stopped:
            return
        env = worker_environment(SandboxLimits(threads=1), self.extra_python_path)
        for name in CACHE_VARIABLES:  # a capture needs no cache: it finds none
            env.pop(name, None)
        env["HOME"] = str(self._folder)
        env["PYTHONSAFEPATH"] = "1"  # the working directory is not importable, nor readable
        command = [sys.executable, "-m", "sga_agent.capture_server", task]
        self._capture = (task, _LineProcess(command, env, self._folder, "capture"))
        self._capture_ready = False

    # ---------------------------------------------------------------------- fit

    def _fitted(
        self,
        data: dict[str, Any],
        settings: dict[str, Any],
        remaining: float,
        progress: ProgressCallback | None = None,
    ) -> Evaluation | _Blameless:
        if remaining <= 0:
            return _failure(
                f"exceeded the time limit of {self.limits.timeout_s:g} s", "timeout", ""
            )
        self._take_warm_spare()
        try:
            worker = self._ready_fit_worker(progress)
        except HelperFailure as error:
            failure = Evaluation.invalid(f"the fit worker did not start: {error}", status="error")
            return _blameless_start(failure, "the fit worker", error)
        earlier = self._fit_evaluations
        try:
            answer = worker.ask({"data": data, "settings": settings}, remaining,
                                last=self.one_shot, progress=progress)  # fmt: skip
        except HelperFailure as error:
            self._fit = None
            if str(error) == "timeout":
                reason = f"exceeded the time limit of {self.limits.timeout_s:g} s"
                return _failure(reason, "timeout", "")
            failure = _failure(f"the fit worker failed: {error}", "crashed", worker.log_tail())
            if error.returncode is None:  # killed here for answering garbage
                return failure
            return _Blameless(failure, _death("the fit worker", error.returncode))
        try:
            evaluation = Evaluation.from_dict(answer)
        except (TypeError, ValueError) as error:
            return Evaluation.invalid(
                f"unreadable answer of the fit worker: {error}", status="error"
            )
        self._fit_evaluations += 1
        if not worker.alive or evaluation.status == "out_of_memory":
            self._retire_fit_worker()  # it exits after a failed allocation
        else:
            self._tend_fit_worker(worker)
        if evaluation.valid:  # checked by the fit: what was scored, for an honest re-evaluation
            evaluation.artifacts["captured"] = data
        if evaluation.status == "out_of_memory" and earlier:
            plural = "s" if earlier > 1 else ""
            why = f"the fit worker ran out of memory after {earlier} earlier evaluation{plural}"
            return _Blameless(evaluation, why)
        return evaluation

    def _start_fit_worker(self, task: str, options: str) -> None:
        """Start a fit worker for ``task`` and its ``options`` (JSON) unless one runs (or its
        replacement does); do not wait (it warms up while the capture runs)."""
        key = f"{task}\n{options}"
        if self._fit is not None and self._fit[0] == key and self._fit[1].alive:
            return
        if self._fit is not None:
            self._fit[1].close()
            self._fit = None
        if self._spare is not None and (self._spare[0] != key or not self._spare[1].alive):
            self._spare[1].kill()
            self._spare = None
        if self._stopped:
            return
        if self._spare is not None:  # started already, perhaps warm
            self._fit, self._fit_awaiting, self._spare = self._spare, self._spare_awaiting, None
        else:
            self._fit, self._fit_awaiting = (key, self._new_fit_worker(task, options)), 1
        self._fit_evaluations, self._fit_reference = 0, None

    def _new_fit_worker(self, task: str, options: str) -> _LineProcess:
        env = worker_environment(self.limits, self.extra_python_path)
        command = [sys.executable, "-m", "sga_agent.fit_worker", task,
                   str(self.limits.memory_mb), options]  # fmt: skip
        if self.one_shot:
            command.append("1")  # warm-up stages run ahead of the request
        self._fit_workers_started += 1
        number = self._fit_workers_started
        return _LineProcess(command, env, self._folder, "fit" if number == 1 else f"fit-{number}")

    def _ready_fit_worker(self, progress: ProgressCallback | None = None) -> _LineProcess:
        """The started fit worker, once it has said it is ready (and, a replacement, that it
        has warmed up); ``progress`` hears of the wait."""
        if self._fit is None:
            raise HelperFailure("the pool was stopped")
        worker = self._fit[1]
        if self._fit_awaiting:
            _tell(progress, FitProgress("starting the fit worker"))
        try:  # not ready: a task that cannot load, each answer says why
            while self._fit_awaiting:
                worker.ask(None, START_TIMEOUT_S, progress=progress)
                self._fit_awaiting -= 1
        except HelperFailure as error:
            self._fit = None
            message = _last_line(worker.log_tail()) or str(error)
            raise HelperFailure(message, error.returncode) from None
        return worker

    # ------------------------------------------------------------------ recycling

    def _tend_fit_worker(self, worker: _LineProcess) -> None:
        """After a fit: note the worker's memory, start its replacement once it is due."""
        rss = worker.rss_mb()
        if self._fit_evaluations == self.recycling.reference:
            self._fit_reference = rss
        self._reap_retired()
        if self.one_shot or self._spare is not None or self._fit is None:
            return
        recycling, reference = self.recycling, self._fit_reference
        worn = recycling.evaluations is not None and self._fit_evaluations >= recycling.evaluations
        grown = (recycling.growth is not None and rss is not None and reference is not None
                 and rss > recycling.growth * reference)  # fmt: skip
        if worn or grown:
            key = self._fit[0]
            spare = self._new_fit_worker(*key.split("\n", 1))
            spare.send({"warm": True})  # it answers once its whole warm-up has run
            self._spare, self._spare_awaiting = (key, spare), 2

    def _take_warm_spare(self) -> None:
        """Put the replacement in the current worker's place if it has warmed up (the old one
        exits); one that failed to start is dropped (the next fit starts another)."""
        if self._spare is None:
            return
        key, spare = self._spare
        try:
            while self._spare_awaiting and (answer := spare.poll()) is not None:
                if self._spare_awaiting == 2 and not answer.get("ready"):
                    raise HelperFailure("not ready")
                self._spare_awaiting -= 1
        except HelperFailure:
            spare.kill()
            self._spare = None
            return
        if self._spare_awaiting:
            return  # still warming up: the current worker goes on
        self._retire_fit_worker()
        self._fit, self._fit_awaiting, self._spare = (key, spare), 0, None
        self._fit_evaluations, self._fit_reference = 0, None

    def _retire_fit_worker(self) -> None:
        """Let the current fit worker exit on its own (it is reaped later, or killed once
        :data:`CLOSE_TIMEOUT_S` have passed)."""
        if self._fit is not None:
            self._fit[1].end_input()
            self._retired.append((time.monotonic(), self._fit[1]))
            self._fit = None

    def _reap_retired(self) -> None:
        """Reap the retired workers that have exited; kill those that take too long."""
        now, kept = time.monotonic(), []
        for since, worker in self._retired:
            if worker.alive and now - since < CLOSE_TIMEOUT_S:
                kept.append((since, worker))
            else:
                worker.kill()
        self._retired = kept


def _blameless_start(failure: Evaluation, helper: str, error: HelperFailure) -> Any:
    """A helper that did not start: blameless if a signal killed it meanwhile (a task that
    cannot load exits with a status, which is the verdict)."""
    if error.returncode is not None and error.returncode < 0:
        return _Blameless(failure, f"{_death(helper, error.returncode)} while starting")
    return failure


def _death(helper: str, code: int) -> str:
    """How a helper ended, as a clause: "the fit worker was killed by SIGKILL"."""
    ended = _ended(code)
    return f"{helper} was {ended}" if code < 0 else f"{helper} {ended}"


def _capture_outcome(
    reply: dict[str, Any], limits: SandboxLimits, timeout: float
) -> dict[str, Any] | Evaluation:
    """The captured data, or the Evaluation that says why there is none."""
    status = reply.get("status")
    if status == "timeout":
        return _failure(f"exceeded the time limit of {timeout:g} s", "timeout", "")
    if status == "error":
        reason = "not evaluated: the capture process could not be isolated as detected at "
        return Evaluation.invalid(f"{reason}start-up ({reply.get('detail', '')})", status="error")
    if status == "crashed":
        return _crashed(reply, limits)
    try:
        outcome = json.loads(reply.get("output", ""))
        if not isinstance(outcome, dict) or len(outcome) not in (1, 2):
            raise ValueError("not an outcome")
        json.dumps(outcome)  # it must travel on to the fit worker
    except (ValueError, RecursionError):
        return Evaluation.invalid(
            "the capture process sent back no readable outcome", status="crashed"
        )
    if "data" in outcome and isinstance(outcome["data"], dict):
        return outcome["data"]
    for kind in ("invalid", "out_of_memory", "error"):
        if isinstance(outcome.get(kind), str):
            reason = _clean(outcome[kind])
            if kind == "error":
                reason = f"capturing the solution raised {reason}"
            elif kind == "out_of_memory":
                reason = f"exceeded the capture's memory limit of {limits.memory_mb} MB ({reason})"
            extras = {}
            if isinstance(outcome.get("traceback"), str):
                extras["traceback"] = outcome["traceback"][-LOG_TAIL_CHARS:]
            status = "invalid" if kind == "invalid" else kind
            return Evaluation.invalid(reason, status=status, extras=extras)
    return Evaluation.invalid("the capture process sent back no readable outcome", status="crashed")


def _crashed(reply: dict[str, Any], limits: SandboxLimits) -> Evaluation:
    number = int(reply.get("signal") or 0)
    if number == signal.SIGXCPU:
        reason = f"killed by SIGXCPU: exceeded the CPU-time limit of {limits.cpu_time_s} s"
        return Evaluation.invalid(reason, status="timeout")
    if number == signal.SIGXFSZ:
        reason = f"killed by SIGXFSZ: exceeded the file-size limit of {limits.file_size_mb} MB"
        return Evaluation.invalid(reason, status="crashed")
    if number:
        description = signal.strsignal(number) or "unknown signal"
        return Evaluation.invalid(
            f"the capture process was killed by {_signal_name(number)} ({description})",
            status="crashed",
        )
    code = reply.get("exit_code", 0)
    return Evaluation.invalid(
        f"the capture process exited (status {code}) without a result", status="crashed"
    )


def _parsed(line: bytes) -> dict[str, Any]:
    """A helper's line as the JSON object it must be (``ValueError`` otherwise)."""
    answer = json.loads(line)
    if not isinstance(answer, dict):
        raise ValueError("not a JSON object")
    return answer


def _tell(progress: ProgressCallback | None, note: FitProgress | None) -> None:
    """Hand ``note`` (None: a malformed one, dropped) to ``progress``; whatever ``progress``
    does (a display that fails) never reaches the evaluation."""
    if progress is not None and note is not None:
        with contextlib.suppress(Exception):
            progress(note)


def _clean(text: str) -> str:
    """Untrusted text made one printable line of bounded length."""
    printable = "".join(ch if ch.isprintable() else " " for ch in text)
    return printable[:MAX_REASON_CHARS]


def _failure(reason: str, status: str, log: str) -> Evaluation:
    assert status in STATUSES
    return Evaluation.invalid(reason, status=status, extras={"log": log} if log else {})


def _last_line(log: str) -> str:
    lines = [line.strip() for line in log.splitlines() if line.strip()]
    return lines[-1] if lines else ""


def _ended(code: int) -> str:
    """How a process with exit status ``code`` ended ("killed by SIGKILL")."""
    if code < 0:
        return f"killed by {_signal_name(-code)}"
    return f"exited with status {code}"


def _signal_name(number: int) -> str:
    try:
        return signal.Signals(number).name
    except ValueError:
        return f"signal {number}"


def evaluate_in_sandbox(
    task: str,
    solution: str,
    settings: EvaluationSettings,
    limits: SandboxLimits = SandboxLimits(),  # noqa: B008 (frozen, so sharing it is safe)
    *,
    extra_python_path: Sequence[str | os.PathLike[str]] = (),
    progress: ProgressCallback | None = None,
) -> Evaluation:
    """Evaluate ``solution`` for ``task``: capture it confined, fit it in a trusted process.

    Parameters
    ----------
    task : str
        A registered task name (see :mod:`sga_agent.registry`) or ``"module:callable"``, a
        zero-argument factory returning a :class:`~sga_agent.task.Task` (a plugin-development
        and testing aid: no entry point needed).
    solution : str
        The candidate's text (code), passed unchanged to the task's ``capture``.
    settings : EvaluationSettings
        Passed to the task's ``evaluate``; ``options`` must be the task's options object (or
        None), sent as JSON (:class:`~sga_agent.helper_protocol.FitSettings`).
    limits : SandboxLimits
        Time, memory, file-size and thread limits, and whether to confine the capture.
    extra_python_path : sequence of path-like
        Directories put in front of the helpers' ``PYTHONPATH`` so that a ``"module:callable"``
        task outside the installed packages can be imported (plugin development, tests).
    progress : callable, optional
        Told how far the evaluation has come (see :meth:`EvaluationSlot.evaluate`), in this
        thread: for a display only, it cannot change the result.

    Returns
    -------
    Evaluation
        The task's result, or an invalid one whose ``status`` and ``reason`` say what went wrong
        (see the module docstring); ``seconds`` is the wall time of the whole evaluation.

    Raises
    ------
    TypeError
        ``settings.options`` cannot be sent (a caller error, not a candidate's).
    """
    sent = FitSettings.of(settings)
    evaluator = EvaluationSlot(limits, extra_python_path, one_shot=True)
    try:
        return evaluator.evaluate(task, solution, sent, progress=progress)
    finally:
        evaluator.close()


class SandboxPool:
    """Evaluate candidates concurrently: ``max_workers`` slots, each an :class:`EvaluationSlot`.

    Once the pool's first capture has ended, the slots no evaluation holds start their helpers,
    which load beside that first fit, so that no slot's first candidate waits for them.

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
    recycling : Recycling
        When each slot replaces its warm fit worker.
    """

    def __init__(
        self,
        max_workers: int | None = None,
        limits: SandboxLimits = SandboxLimits(),  # noqa: B008 (frozen)
        *,
        extra_python_path: Sequence[str | os.PathLike[str]] = (),
        recycling: Recycling = Recycling(),  # noqa: B008 (frozen)
    ) -> None:
        if max_workers is None:
            max_workers = os.cpu_count() or 1
        if isinstance(max_workers, bool) or not isinstance(max_workers, int) or max_workers < 1:
            raise ValueError(f"max_workers must be a positive integer, got {max_workers!r}")
        self.max_workers = max_workers
        self.limits = limits
        self.extra_python_path = tuple(extra_python_path)
        self._executor = ThreadPoolExecutor(max_workers, thread_name_prefix="sga-sandbox")
        self._slots: queue.SimpleQueue[EvaluationSlot] = queue.SimpleQueue()
        self._evaluators = [
            EvaluationSlot(limits, self.extra_python_path, recycling=recycling)
            for _ in range(max_workers)
        ]
        for evaluator in self._evaluators:
            self._slots.put(evaluator)
        self._lock = threading.Lock()
        self._idle_started = False  # see _start_idle_slots

    def isolation(self) -> Isolation:
        """How the capture processes are isolated, for the run's record."""
        if not self.limits.isolation:
            return Isolation.none("disabled (SandboxLimits.isolation=False)")
        return detect_isolation()

    def submit(
        self,
        task: str,
        solution: str,
        settings: EvaluationSettings,
        captured: dict[str, Any] | None = None,
        progress: ProgressCallback | None = None,
    ) -> Future[Evaluation]:
        """Start evaluating one solution; the future's result is its :class:`Evaluation`.

        ``captured`` (see :meth:`EvaluationSlot.evaluate`) fits it again without a capture;
        ``progress`` is told how far it has come, from the pool's thread that evaluates it.
        Raises ``TypeError`` at once if ``settings.options`` cannot be sent (see
        :func:`evaluate_in_sandbox`); a bad candidate never raises: its future holds an invalid
        Evaluation.
        """
        sent = FitSettings.of(settings)
        return self._executor.submit(self._evaluate, task, solution, sent, captured, progress)

    def map(
        self, task: str, solutions: Iterable[str], settings: EvaluationSettings
    ) -> list[Evaluation]:
        """Evaluate every solution (concurrently); the evaluations in input order."""
        futures = [self.submit(task, solution, settings) for solution in solutions]
        return [future.result() for future in futures]

    def close(self) -> None:
        """Wait for running evaluations, then stop every helper process (all at once)."""
        self._executor.shutdown(wait=True)
        for evaluator in self._evaluators:
            evaluator.end_input()
        for evaluator in self._evaluators:
            evaluator.close()

    def terminate(self) -> None:
        """Stop now: cancel queued evaluations, kill the running ones' helper processes and
        wait for their threads (which then end at once). Futures of evaluations that were
        running hold invalid evaluations ("the pool was stopped" or a killed helper): a caller
        that terminates must not record them."""
        self._executor.shutdown(wait=False, cancel_futures=True)
        for evaluator in self._evaluators:
            evaluator.kill()
        self._executor.shutdown(wait=True)
        for evaluator in self._evaluators:
            evaluator.close()

    def __enter__(self) -> SandboxPool:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, *exc_info: object) -> None:
        """Wait for running evaluations after a normal exit; after an exception (Ctrl-C, a
        stopped search) terminate instead."""
        if exc_type is None:
            self.close()
        else:
            self.terminate()

    def _evaluate(
        self,
        task: str,
        solution: str,
        settings: FitSettings,
        captured: dict[str, Any] | None,
        progress: ProgressCallback | None,
    ) -> Evaluation:
        evaluator = self._slots.get()
        try:
            return evaluator.evaluate(
                task, solution, settings, self._start_idle_slots, captured, progress
            )
        except Exception as error:  # the sandbox itself failed, e.g. no space for its folder
            reason = f"the sandbox failed: {type(error).__name__}: {error}"
            return Evaluation.invalid(reason, status="error")
        finally:
            self._slots.put(evaluator)

    def _start_idle_slots(self, task: str, options: str) -> None:
        """Start the helpers of the slots no evaluation holds, once: when the pool's first
        capture has ended, so that they load beside the first fit (fewer processes compete
        than if every slot started at once) and no slot's first candidate waits for them."""
        with self._lock:
            if self._idle_started:
                return
            self._idle_started = True
        idle: list[EvaluationSlot] = []
        with contextlib.suppress(queue.Empty):
            while True:
                idle.append(self._slots.get_nowait())
        try:
            for evaluator in idle:
                # a slot that cannot start now (no processes left, say) reports it when it
                # gets a candidate: the evaluation that triggered this one is not lost
                with contextlib.suppress(OSError):
                    evaluator.start_helpers(task, options)
        finally:
            for evaluator in idle:
                self._slots.put(evaluator)


def resident_mb(pid: int | str = "self") -> float | None:
    """Resident memory of process ``pid`` in MB (``VmRSS`` of /proc), None where it cannot be
    read (the process has gone, or there is no /proc)."""
    try:
        with open(f"/proc/{pid}/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def threads_per_worker(workers: int) -> int:
    """The machine's cores shared by ``workers`` evaluations at once (at least 1 each)."""
    return max(1, (os.cpu_count() or 1) // max(1, workers))


def worker_environment(
    limits: SandboxLimits, extra_python_path: Sequence[str | os.PathLike[str]] = ()
) -> dict[str, str]:
    """The scrubbed environment of a worker: kept variables, thread counts, import path."""
    env = {
        name: value
        for name, value in os.environ.items()
        if (name in KEPT_VARIABLES or name.startswith(KEPT_PREFIXES)) and not looks_secret(name)
    }
    # torch and BLAS compute on the calling thread: an evaluation's tensors are small, and a
    # pool's threads that spin or sleep between operations lose their core to any busy process
    for name in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        env[name] = "1"
    env["OMP_WAIT_POLICY"] = "PASSIVE"
    # Taichi's parallel loops take the thread budget, each launch only while the cores are free
    # (taichi_mpm.runtime.parallel_worthwhile)
    env["TI_CPU_MAX_NUM_THREADS"] = str(limits.threads)
    env[DEVICE_VARIABLE] = limits.device
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
