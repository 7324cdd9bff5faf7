"""The sandbox: results come back, and every way a candidate can fail becomes a typed outcome.

The candidates here run in the capture step of :class:`tests.sga_agent.doubles.ExecTask` (which
executes them); its fit believes what they report, so these tests see the capture process from
inside. Real tasks check the captured data in the fit (see tests/hostile for forgery attempts).
"""

import json
import os
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import pytest

from sga_agent import sandbox
from sga_agent.helper_protocol import NOTE, FitSettings
from sga_agent.isolation import Isolation, detect_isolation
from sga_agent.sandbox import (
    EvaluationSlot,
    SandboxLimits,
    SandboxPool,
    evaluate_in_sandbox,
    looks_secret,
)
from sga_agent.task import EvaluationSettings
from tests.sga_agent import doubles
from tests.sga_agent.doubles import DoubleOptions

REPO_ROOT = Path(__file__).resolve().parents[2]
DOUBLE = "tests.sga_agent.doubles:ExecTask"
SETTINGS = EvaluationSettings()
LIMITS = SandboxLimits(timeout_s=60)
ISOLATED = not detect_isolation().processes.startswith("none:")

INFINITE_LOOP = "while True:\n    pass\n"
MEMORY_BOMB = "chunks = []\nwhile True:\n    chunks.append(bytearray(64 * 2**20))\n"
SEGFAULT = "import ctypes\nctypes.string_at(0)\n"


def sandboxed(solution, limits=LIMITS, settings=SETTINGS, task=DOUBLE):
    return evaluate_in_sandbox(task, solution, settings, limits, extra_python_path=[REPO_ROOT])


def writer(path: Path) -> str:
    """A candidate that writes ``path``, reporting the error if it cannot."""
    return (
        "try:\n"
        f"    open({str(path)!r}, 'w').write('escaped')\n"
        "    report = 'written'\n"
        "except OSError as error:\n"
        "    report = type(error).__name__\n"
        "    raise\n"
    )


def test_good_solution_is_evaluated_despite_its_prints():
    solution = "print('{\"valid\": false}')\nloss = 0.25\nparameters = {'E': 3.0}\n"
    options = DoubleOptions(label="seven")
    settings = EvaluationSettings(epochs=3, learning_rate=0.1, seed=7, options=options)
    evaluation = sandboxed(solution, settings=settings)
    assert evaluation.valid, evaluation.reason
    assert evaluation.status == "ok"
    assert evaluation.loss == 0.25
    assert evaluation.parameters == {"E": 3.0}
    assert evaluation.extras["settings"] == {
        "epochs": 3,
        "learning_rate": 0.1,
        "seed": 7,
        "options": {"label": "seven", "notes": None},  # the fit worker's DoubleOptions
        "fidelity": 1.0,
    }
    assert 0 < evaluation.extras["capture_seconds"] <= evaluation.seconds < 60
    assert evaluation.artifacts["captured"]["loss"] == 0.25  # what the fit was given


def test_infinite_loop_is_killed_at_the_time_limit():
    start = time.monotonic()
    limits = SandboxLimits(timeout_s=60, capture_timeout_s=1.5)
    evaluation = sandboxed(INFINITE_LOOP, limits)
    assert (evaluation.valid, evaluation.status) == (False, "timeout")
    assert evaluation.reason == "exceeded the time limit of 1.5 s"
    assert evaluation.loss == float("inf")
    assert time.monotonic() - start < 30


def test_memory_bomb_is_stopped_by_the_limit():
    evaluation = sandboxed(MEMORY_BOMB, SandboxLimits(timeout_s=60, memory_mb=256))
    assert (evaluation.valid, evaluation.status) == (False, "out_of_memory")
    assert evaluation.reason.startswith("exceeded the capture's memory limit of 256 MB")
    assert "MemoryError" in evaluation.reason


def test_shared_memory_counts_against_the_limit():
    shared = (
        "import ctypes\n"
        "libc = ctypes.CDLL(None, use_errno=True)\n"
        "libc.mmap.restype = ctypes.c_void_p\n"
        "libc.mmap.argtypes = [ctypes.c_void_p, ctypes.c_size_t] + [ctypes.c_int] * 3 + "
        "[ctypes.c_long]\n"
        "address = libc.mmap(None, 6 * 2**30, 3, 0x01 | 0x20, -1, 0)  # shared, anonymous\n"
        "report = [address in (None, 2**64 - 1), ctypes.get_errno()]\n"
    )
    evaluation = sandboxed(shared, SandboxLimits(timeout_s=60, memory_mb=512))
    assert evaluation.valid, evaluation.reason
    assert evaluation.extras["report"] == [True, 12]  # MAP_FAILED, ENOMEM: RLIMIT_AS holds


def test_segfault_is_reported_as_a_crash():
    evaluation = sandboxed(SEGFAULT)
    assert (evaluation.valid, evaluation.status) == (False, "crashed")
    assert evaluation.reason.startswith("the capture process was killed by SIGSEGV")


def test_exception_in_capture_gives_reason_and_the_end_of_the_traceback():
    solution = "def law(n):\n    return law(n + 1) if n < 400 else 1 / 0\nlaw(0)\n"
    evaluation = sandboxed(solution)
    assert (evaluation.valid, evaluation.status) == (False, "error")
    assert evaluation.reason == "capturing the solution raised ZeroDivisionError: division by zero"
    trace = evaluation.extras["traceback"]
    assert len(trace) <= 4000
    assert trace.rstrip().endswith("ZeroDivisionError: division by zero")


def test_exit_calls_are_contained():
    evaluation = sandboxed("import sys\nsys.exit(3)\n")
    assert evaluation.reason == "capturing the solution raised SystemExit: 3"
    assert evaluation.status == "error"
    for code in (0, 4):
        evaluation = sandboxed(f"import os\nos._exit({code})\n")
        assert evaluation.reason == f"the capture process exited (status {code}) without a result"
        assert evaluation.status == "crashed"


def test_non_finite_loss_is_unstable():
    evaluation = sandboxed("loss = float('nan')\nparameters = {'E': 1.0}\n")
    assert (evaluation.valid, evaluation.status) == (False, "unstable")
    assert evaluation.reason == "the loss is nan (numerically unstable)"
    assert evaluation.loss == float("inf") and evaluation.parameters == {"E": 1.0}


def test_environment_is_scrubbed(monkeypatch):
    monkeypatch.setenv("FAKE_API_KEY", "sk-123")
    monkeypatch.setenv("TI_FAKE_TOKEN", "abc")  # a kept prefix does not let a secret through
    monkeypatch.setenv("SGA_UNRELATED", "1")
    monkeypatch.setenv("SGA_CACHE_DIR", str(Path.home() / ".cache" / "sga"))
    evaluation = sandboxed("", SandboxLimits(timeout_s=60, threads=2))
    environ = evaluation.extras["environ"]
    assert not {"FAKE_API_KEY", "TI_FAKE_TOKEN", "SGA_UNRELATED", "SGA_CACHE_DIR"} & set(environ)
    assert environ["HOME"] != os.environ["HOME"]  # the capture is not told where caches are
    assert environ["OMP_NUM_THREADS"] == environ["TI_CPU_MAX_NUM_THREADS"] == "1"
    assert environ["OMP_WAIT_POLICY"] == "PASSIVE"
    assert environ["PYTHONPATH"].split(os.pathsep)[0] == str(REPO_ROOT)


@pytest.mark.parametrize(
    ("name", "secret"),
    [
        ("OPENAI_BASE_URL", True),
        ("github_token", True),
        ("DB_PASSWORD", True),
        ("TI_ARCH", False),
        ("LC_ALL", False),
    ],
)
def test_secret_names(name, secret):
    assert looks_secret(name) is secret


def test_stdin_is_closed_and_prints_go_nowhere():
    solution = (
        "import os, sys\nreport = [sys.stdin.read(), os.read(0, 10).decode()]\n"
        "for i in range(3000):\n    print('line', i, 'x' * 2000)\nloss = 0.5\n"
    )
    evaluation = sandboxed(solution)
    assert evaluation.valid, evaluation.reason
    assert evaluation.extras["report"] == ["", ""] and evaluation.loss == 0.5


@pytest.mark.skipif(not ISOLATED, reason=f"no isolation here: {detect_isolation().processes}")
def test_nothing_can_be_written_not_even_the_working_directory(tmp_path):
    evaluation = sandboxed(writer(Path("scratch.txt")))
    assert (
        evaluation.status == "error"
        and "OSError" in evaluation.reason
        or ("PermissionError" in evaluation.reason)
    )
    evaluation = sandboxed(writer(tmp_path / "outside.txt"))
    assert evaluation.status == "error"
    assert not (tmp_path / "outside.txt").exists()


def nobody_processes() -> set[int]:
    pids = set()
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                status = (entry / "status").read_text()
            except OSError:
                continue
            uid_line = next(line for line in status.splitlines() if line.startswith("Uid:"))
            if uid_line.split()[1] == "65534":
                pids.add(int(entry.name))
    return pids


@pytest.mark.skipif(os.getuid() != 0 or not ISOLATED, reason="needs root and namespaces")
def test_every_process_the_candidate_starts_dies_with_the_capture():
    before = nobody_processes()
    daemon = (
        "import os, time\n"
        "if os.fork() == 0:\n"
        "    os.setsid()\n"
        "    if os.fork() == 0:\n"
        "        time.sleep(120)\n"
        "    os._exit(0)\n"
        "report = os.getuid()\n"
    )
    evaluation = sandboxed(daemon)
    assert evaluation.valid, evaluation.reason
    assert evaluation.extras["report"] == 65534  # it ran as nobody
    deadline = time.monotonic() + 5
    while nobody_processes() - before and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not nobody_processes() - before


@pytest.mark.skipif(os.getuid() != 0 or not ISOLATED, reason="needs root and namespaces")
def test_a_fork_storm_hits_the_process_limit():
    storm = (
        "import os, time\npids = []\n"
        "try:\n"
        "    for _ in range(2000):\n"
        "        pid = os.fork()\n"
        "        if pid == 0:\n"
        "            time.sleep(30)\n"
        "            os._exit(0)\n"
        "        pids.append(pid)\n"
        "except OSError as error:\n"
        "    report = [len(pids), error.errno]\n"
    )
    evaluation = sandboxed(storm)
    assert evaluation.valid, evaluation.reason
    forked, errno = evaluation.extras["report"]
    assert forked < 300 and errno == 11  # EAGAIN: RLIMIT_NPROC


@pytest.mark.parametrize(
    ("task", "reason"),
    [
        ("no-such-task", "no task named 'no-such-task' is registered"),
        ("tests.sga_agent.doubles:not_a_task", "returned object, which does not satisfy"),
        ("tests.sga_agent.doubles:broken_task", "RuntimeError: this plugin is broken"),
        ("tests.sga_agent.no_module:Task", "ModuleNotFoundError"),
    ],
)
def test_task_that_cannot_be_loaded_is_an_error(task, reason):
    evaluation = sandboxed("", task=task)
    assert (evaluation.valid, evaluation.status) == (False, "error")
    assert reason in evaluation.reason


@pytest.mark.slow
def test_pool_survives_every_failure_and_keeps_input_order(tmp_path):
    outside = tmp_path / "outside.txt"
    solutions = [INFINITE_LOOP, MEMORY_BOMB, SEGFAULT, writer(outside), "loss = 0.5\n"]
    limits = SandboxLimits(timeout_s=30, capture_timeout_s=4, memory_mb=256)
    with SandboxPool(2, limits, extra_python_path=[REPO_ROOT]) as pool:
        evaluations = pool.map(DOUBLE, solutions, SETTINGS)
    statuses = [evaluation.status for evaluation in evaluations]
    assert statuses == ["timeout", "out_of_memory", "crashed", "error" if ISOLATED else "ok", "ok"]
    assert evaluations[-1].loss == 0.5
    assert outside.exists() is not ISOLATED


def test_pool_keeps_its_helpers_warm():
    with SandboxPool(1, LIMITS, extra_python_path=[REPO_ROOT]) as pool:
        first, second = pool.map(DOUBLE, ["loss = 1.0\n", "loss = 2.0\n"], SETTINGS)
    assert (first.loss, second.loss) == (1.0, 2.0)
    assert second.extras["capture_seconds"] < first.extras["capture_seconds"]


def test_captured_data_is_fitted_again_at_another_fidelity_without_a_capture():
    """A multi-fidelity search's promoted candidate: its screen's captured data, fitted in
    full by the same warm fit worker; the solution does not run again."""
    task = "tests.sga_agent.doubles:WarmingTask"  # reports its fit worker's process id
    with SandboxPool(1, LIMITS, extra_python_path=[REPO_ROOT]) as pool:
        screen = pool.submit(task, "loss = 1.0\n", EvaluationSettings(fidelity=0.2)).result()
        captured = screen.artifacts["captured"]
        full = pool.submit(task, "raise SystemExit('ran again')\n", SETTINGS,
                           captured=captured).result()  # fmt: skip
    assert (screen.extras["settings"]["fidelity"], full.extras["settings"]["fidelity"]) == (0.2, 1)
    assert full.valid and full.loss == 1.0  # the screen's data, not the text's capture
    assert full.extras["fit_pid"] == screen.extras["fit_pid"]
    assert full.extras["capture_seconds"] < 0.05


def test_a_pool_starts_its_idle_slots_once_its_first_capture_has_ended():
    with SandboxPool(2, LIMITS, extra_python_path=[REPO_ROOT]) as pool:
        (first,) = pool.map(DOUBLE, ["loss = 1.0\n"], SETTINGS)
        running = [[helper.alive for helper in slot._helpers()] for slot in pool._evaluators]
        later = pool.map(DOUBLE, ["loss = 2.0\n", "loss = 3.0\n"], SETTINGS)
    assert running == [[True, True], [True, True]]  # capture server and fit worker, each slot
    assert [first.loss] + [evaluation.loss for evaluation in later] == [1.0, 2.0, 3.0]


def test_an_idle_slot_that_cannot_start_costs_the_first_evaluation_nothing(monkeypatch):
    def no_processes(self, task, options):
        raise OSError(11, "Resource temporarily unavailable")

    monkeypatch.setattr(EvaluationSlot, "start_helpers", no_processes)
    with SandboxPool(2, LIMITS, extra_python_path=[REPO_ROOT]) as pool:
        evaluations = pool.map(DOUBLE, ["loss = 1.0\n"], SETTINGS)
        evaluations += pool.map(DOUBLE, ["loss = 2.0\n", "loss = 3.0\n"], SETTINGS)
    assert [evaluation.loss for evaluation in evaluations] == [1.0, 2.0, 3.0]


def test_the_fit_worker_warms_up_once_before_its_first_candidate():
    task = "tests.sga_agent.doubles:WarmingTask"
    with SandboxPool(1, LIMITS, extra_python_path=[REPO_ROOT]) as pool:
        first, second = pool.map(task, ["loss = 1.0\n", "loss = 2.0\n"], SETTINGS)
    defaults = {"type": "DoubleOptions", "label": "", "notes": None}  # no options: the defaults
    assert first.extras["warmed_with"] == defaults == second.extras["warmed_with"]
    assert first.extras["fit_pid"] == second.extras["fit_pid"]


def test_a_fit_worker_builds_its_options_object_once_for_all_its_evaluations():
    task = "tests.sga_agent.doubles:WarmingTask"
    settings = EvaluationSettings(options=DoubleOptions(label="once"))
    with SandboxPool(1, LIMITS, extra_python_path=[REPO_ROOT]) as pool:
        evaluations = pool.map(task, [f"loss = {i}.0\n" for i in range(3)], settings)
    assert len({e.extras["fit_pid"] for e in evaluations}) == 1  # one worker evaluated them
    assert [e.extras["options_built"] for e in evaluations] == [1, 1, 1]
    assert all(e.extras["settings"]["options"]["label"] == "once" for e in evaluations)


def _staged_fit_worker(notes: Path) -> tuple[subprocess.Popen, str]:
    """A fit worker of StagedWarmingTask, started with one request already waiting."""
    sent = FitSettings.of(EvaluationSettings(options=DoubleOptions(notes=str(notes))))
    data = doubles.StagedWarmingTask().capture("loss = 1.0\n")
    request = json.dumps({"data": data, "settings": sent.request()}) + "\n"
    command = [sys.executable, "-m", "sga_agent.fit_worker",
               "tests.sga_agent.doubles:StagedWarmingTask", "4096", sent.options]
    worker = subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                              env=os.environ | {"PYTHONPATH": str(REPO_ROOT)})  # fmt: skip
    worker.stdin.write(request)  # before the worker has even started Python
    worker.stdin.flush()
    assert json.loads(worker.stdout.readline()) == {"ready": True}
    return worker, request


def _answer(worker: subprocess.Popen) -> dict:
    """The worker's next answer, past its progress notes."""
    while NOTE in (line := json.loads(worker.stdout.readline())):
        pass
    return line


def _noted(notes: Path) -> list[str]:
    return notes.read_text().split() if notes.exists() else []


def test_a_waiting_candidate_goes_before_the_warm_up_stages_that_run_when_idle(tmp_path):
    notes = tmp_path / "stages"
    worker, request = _staged_fit_worker(notes)
    first = _answer(worker)
    deadline = time.monotonic() + 30
    while _noted(notes) != ["1", "2", "3"]:
        assert time.monotonic() < deadline, "the warm-up did not run while the worker waited"
        time.sleep(0.05)
    worker.stdin.write(request)
    worker.stdin.flush()
    second = _answer(worker)
    worker.stdin.close()
    assert worker.wait(timeout=30) == 0
    assert first["extras"]["stages_done"] == []
    assert second["extras"]["stages_done"] == ["1", "2", "3"]


def test_warm_up_stages_not_reached_when_the_input_ends_are_skipped(tmp_path):
    notes = tmp_path / "stages"
    worker, _ = _staged_fit_worker(notes)
    worker.stdin.close()
    assert _answer(worker)["extras"]["stages_done"] == []
    assert worker.wait(timeout=30) == 0
    assert not notes.exists()


def test_a_single_evaluation_warms_up_the_first_stage_only(tmp_path):
    notes = tmp_path / "stages"
    settings = EvaluationSettings(options=DoubleOptions(notes=str(notes)))
    evaluation = sandboxed("loss = 1.0\n", settings=settings,
                           task="tests.sga_agent.doubles:StagedWarmingTask")  # fmt: skip
    assert evaluation.status == "ok"
    assert evaluation.extras["stages_done"] in ([], ["1"])
    assert _noted(notes) in ([], ["1"])  # its helpers are gone: no stage ran after it


def test_a_failing_warm_up_leaves_the_evaluations_to_run():
    evaluation = sandboxed("loss = 0.25\n", task="tests.sga_agent.doubles:FailingWarmUpTask")
    assert evaluation.status == "ok" and evaluation.loss == 0.25


def test_threads_are_the_cores_shared_by_the_workers(monkeypatch):
    monkeypatch.setattr(os, "cpu_count", lambda: 8)
    assert [sandbox.threads_per_worker(n) for n in (1, 2, 3, 8, 16)] == [8, 4, 2, 1, 1]


def test_pool_defaults_to_one_worker_per_core():
    with SandboxPool() as pool:
        assert pool.max_workers == os.cpu_count()


def test_pool_never_raises_for_a_failing_sandbox(monkeypatch):
    def broken(*args):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(EvaluationSlot, "evaluate", broken)
    with SandboxPool(1, LIMITS) as pool:
        [evaluation] = pool.map(DOUBLE, [""], SETTINGS)
    assert evaluation.status == "error"
    assert evaluation.reason == "the sandbox failed: OSError: [Errno 28] No space left on device"


def test_pool_records_its_isolation():
    with SandboxPool(1, LIMITS) as pool:
        assert pool.isolation() == detect_isolation()
    with SandboxPool(1, SandboxLimits(isolation=False)) as pool:
        assert pool.isolation() == Isolation.none("disabled (SandboxLimits.isolation=False)")


def test_capture_not_isolated_as_detected_refuses_to_evaluate(monkeypatch):
    promised = Isolation("a firewall", "read-only disk", "a jail")
    monkeypatch.setattr(sandbox, "detect_isolation", lambda: promised)
    evaluation = sandboxed("loss = 0.0\n")
    assert (evaluation.valid, evaluation.status) == (False, "error")
    assert evaluation.reason.startswith("not evaluated: the capture process could not be isolated")
    assert "network: " in evaluation.reason


def test_isolation_can_be_disabled_for_debugging(tmp_path):
    outside = tmp_path / "outside.txt"
    evaluation = sandboxed(writer(outside), SandboxLimits(timeout_s=60, isolation=False))
    assert evaluation.valid, evaluation.reason
    assert outside.read_text() == "escaped"


@dataclass(frozen=True)
class Unsendable:
    f: object = None


def test_options_that_cannot_be_sent_are_a_caller_error():
    with pytest.raises(TypeError, match="task options must be JSON-serialisable"):
        sandboxed("", settings=EvaluationSettings(options=Unsendable(object())))
    with SandboxPool(1, LIMITS) as pool, pytest.raises(TypeError, match="options dataclass"):
        pool.submit(DOUBLE, "", EvaluationSettings(options={"label": "a dict"}))


def test_options_a_fit_worker_cannot_build_fail_every_evaluation_with_the_reason():
    settings = EvaluationSettings(options=Unsendable())  # not the double's DoubleOptions
    evaluation = sandboxed("loss = 1.0\n", settings=settings)
    assert (evaluation.valid, evaluation.status) == (False, "error")
    assert "the options of task 'tests.sga_agent.doubles:ExecTask' failed" in evaluation.reason
    assert "has no option 'f'" in evaluation.reason


@pytest.mark.parametrize(
    ("kwargs", "error", "message"),
    [
        ({"timeout_s": 0}, ValueError, "timeout_s must be a positive"),
        ({"timeout_s": float("inf")}, ValueError, "timeout_s"),
        ({"timeout_s": "10"}, TypeError, "timeout_s must be a number"),
        ({"capture_timeout_s": -1}, ValueError, "capture_timeout_s must be a positive"),
        ({"memory_mb": 10}, ValueError, "memory_mb must be at least 64"),
        ({"file_size_mb": 1.5}, TypeError, "file_size_mb must be an integer"),
        ({"threads": 0}, ValueError, "threads must be at least 1"),
        ({"isolation": "yes"}, TypeError, "isolation must be True or False"),
    ],
)
def test_limits_are_validated(kwargs, error, message):
    with pytest.raises(error, match=message):
        SandboxLimits(**kwargs)


def test_fit_threads_go_to_taichi_and_torch_runs_on_one():
    environ = sandbox.worker_environment(SandboxLimits(threads=4))
    assert environ["TI_CPU_MAX_NUM_THREADS"] == "4"
    assert environ["OMP_NUM_THREADS"] == environ["MKL_NUM_THREADS"] == "1"
    assert environ["OMP_WAIT_POLICY"] == "PASSIVE"  # no OpenMP thread spins for a core
