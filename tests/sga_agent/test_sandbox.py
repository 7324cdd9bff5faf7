"""The sandbox: results come back, and every way a candidate can fail becomes a typed outcome."""

import os
import tempfile
import time
from pathlib import Path

import pytest

from sga_agent import sandbox
from sga_agent.isolation import Isolation, detect_isolation
from sga_agent.sandbox import (
    LOG_TAIL_CHARS,
    SandboxLimits,
    SandboxPool,
    evaluate_in_sandbox,
    looks_secret,
)
from sga_agent.task import EvaluationSettings

REPO_ROOT = Path(__file__).resolve().parents[2]
DOUBLE = "tests.sga_agent.doubles:ExecTask"
SETTINGS = EvaluationSettings()
LIMITS = SandboxLimits(timeout_s=60)

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


def is_running(pid: int) -> bool:
    """Whether ``pid`` exists and is not a zombie waiting to be reaped."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except FileNotFoundError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def test_good_solution_is_evaluated_despite_its_prints():
    solution = "print('{\"valid\": false}')\nloss = 0.25\nparameters = {'E': 3.0}\n"
    settings = EvaluationSettings(epochs=3, learning_rate=0.1, seed=7, options={"a": [1, 2]})
    evaluation = sandboxed(solution, settings=settings)
    assert evaluation.valid, evaluation.reason
    assert evaluation.status == "ok"
    assert evaluation.loss == 0.25
    assert evaluation.parameters == {"E": 3.0}
    assert evaluation.extras["settings"] == {
        "epochs": 3,
        "learning_rate": 0.1,
        "seed": 7,
        "options": {"a": [1, 2]},
    }
    assert 0 < evaluation.seconds < 30


def test_infinite_loop_is_killed_at_the_time_limit():
    start = time.monotonic()
    evaluation = sandboxed(INFINITE_LOOP, SandboxLimits(timeout_s=1.5))
    assert (evaluation.valid, evaluation.status) == (False, "timeout")
    assert evaluation.reason == "exceeded the time limit of 1.5 s"
    assert evaluation.loss == float("inf")
    assert time.monotonic() - start < 10
    assert 1.5 <= evaluation.seconds < 10


def test_memory_bomb_is_stopped_by_the_limit():
    evaluation = sandboxed(MEMORY_BOMB, SandboxLimits(timeout_s=60, memory_mb=256))
    assert (evaluation.valid, evaluation.status) == (False, "out_of_memory")
    assert evaluation.reason.startswith("exceeded the memory limit of 256 MB"), evaluation.reason
    assert "MemoryError" in evaluation.reason


def test_segfault_is_reported_as_a_crash():
    evaluation = sandboxed(SEGFAULT)
    assert (evaluation.valid, evaluation.status) == (False, "crashed")
    assert evaluation.reason.startswith("killed by SIGSEGV"), evaluation.reason
    assert "Fatal Python error" in evaluation.extras["log"]  # faulthandler's traceback


def test_exception_in_evaluate_gives_reason_and_the_end_of_the_traceback():
    solution = "def law(n):\n    return law(n + 1) if n < 400 else 1 / 0\nlaw(0)\n"
    evaluation = sandboxed(solution)
    assert (evaluation.valid, evaluation.status) == (False, "error")
    assert evaluation.reason == "evaluation raised ZeroDivisionError: division by zero"
    trace = evaluation.extras["traceback"]
    assert len(trace) <= 4000 and "in law" in trace
    assert trace.rstrip().endswith("ZeroDivisionError: division by zero")


def test_exit_calls_are_contained():
    evaluation = sandboxed("import sys\nsys.exit(3)\n")
    assert (evaluation.reason, evaluation.status) == ("evaluation raised SystemExit: 3", "error")
    evaluation = sandboxed("import os\nos._exit(0)\n")
    assert evaluation.reason == "the sandbox worker exited without writing a result"
    assert evaluation.status == "crashed"
    evaluation = sandboxed("import os\nos._exit(4)\n")
    assert evaluation.reason == "the sandbox worker exited with status 4"
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
    assert not {"FAKE_API_KEY", "TI_FAKE_TOKEN", "SGA_UNRELATED"} & set(environ)
    assert environ["HOME"] == os.environ["HOME"]
    assert environ["SGA_CACHE_DIR"] == os.environ["SGA_CACHE_DIR"]
    assert environ["OMP_NUM_THREADS"] == environ["TI_CPU_MAX_NUM_THREADS"] == "2"
    assert environ["TMPDIR"] == evaluation.extras["cwd"]
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


def test_stdin_is_closed():
    solution = "import os, sys\nreport = [sys.stdin.read(), os.read(0, 10).decode()]\n"
    evaluation = sandboxed(solution)
    assert evaluation.valid, evaluation.reason
    assert evaluation.extras["report"] == ["", ""]


def test_printing_is_capped_and_cannot_fail_the_evaluation():
    chatty = "for i in range(3000):\n    print('line', i, 'x' * 2000)\n"
    limits = SandboxLimits(timeout_s=60, file_size_mb=1)  # prints 6 MB
    evaluation = sandboxed(chatty + "loss = 0.5\n", limits)
    assert (evaluation.valid, evaluation.loss) == (True, 0.5), evaluation.reason
    evaluation = sandboxed(chatty + "import os\nos._exit(5)\n", limits)
    assert evaluation.status == "crashed"
    log = evaluation.extras["log"]
    assert log.startswith("[") and "earlier bytes dropped]" in log.splitlines()[0]
    assert log.rstrip().endswith("line 2999 " + "x" * 2000)
    assert len(log.encode()) < LOG_TAIL_CHARS + 100


def test_working_directory_is_a_removed_temporary_directory():
    evaluation = sandboxed("open('scratch.txt', 'w').write('x')\n")
    cwd = Path(evaluation.extras["cwd"])
    assert cwd != Path.cwd()
    assert cwd.is_relative_to(Path(tempfile.gettempdir()).resolve())
    assert not cwd.exists()


def test_file_size_limit_is_contained():
    big = "with open('big.bin', 'wb') as f:\n    f.write(b'0' * (3 * 2**20))\n"
    evaluation = sandboxed(big, SandboxLimits(timeout_s=60, file_size_mb=1))
    assert (evaluation.valid, evaluation.status) == (False, "error")
    assert evaluation.reason == "evaluation raised OSError: [Errno 27] File too large"


def test_processes_left_behind_are_killed():
    spawner = (
        "import subprocess, sys\n"
        "child = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(60)'])\n"
        "parameters = {'pid': child.pid}\n"
    )
    evaluation = sandboxed(spawner)
    assert evaluation.valid, evaluation.reason
    pid = int(evaluation.parameters["pid"])
    deadline = time.monotonic() + 5
    while is_running(pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not is_running(pid)


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


def test_pool_survives_every_failure_and_keeps_input_order(tmp_path):
    outside = tmp_path / "outside.txt"
    solutions = [INFINITE_LOOP, MEMORY_BOMB, SEGFAULT, writer(outside), "loss = 0.5\n"]
    limits = SandboxLimits(timeout_s=4, memory_mb=256)
    with SandboxPool(3, limits, extra_python_path=[REPO_ROOT]) as pool:
        evaluations = pool.map(DOUBLE, solutions, SETTINGS)
    statuses = [evaluation.status for evaluation in evaluations]
    assert statuses == ["timeout", "out_of_memory", "crashed", "error", "ok"]
    assert evaluations[-1].loss == 0.5
    assert not outside.exists()


def test_pool_defaults_to_one_worker_per_core():
    with SandboxPool() as pool:
        assert pool.max_workers == os.cpu_count()


def test_pool_never_raises_for_a_failing_sandbox(monkeypatch):
    def broken(*args):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(sandbox, "_run_worker", broken)
    with SandboxPool(1, LIMITS) as pool:
        [evaluation] = pool.map(DOUBLE, [""], SETTINGS)
    assert evaluation.status == "error"
    assert evaluation.reason == "the sandbox failed: OSError: [Errno 28] No space left on device"


def test_pool_records_its_isolation():
    with SandboxPool(1, LIMITS) as pool:
        assert pool.isolation() == detect_isolation()
    with SandboxPool(1, SandboxLimits(isolation=False)) as pool:
        assert pool.isolation() == Isolation.none("disabled (SandboxLimits.isolation=False)")


def test_worker_not_isolated_as_detected_refuses_to_evaluate(monkeypatch):
    promised = Isolation("a firewall", "read-only disk", "a jail")
    monkeypatch.setattr(sandbox, "detect_isolation", lambda: promised)
    evaluation = sandboxed("loss = 0.0\n")
    assert (evaluation.valid, evaluation.status) == (False, "error")
    assert evaluation.reason.startswith("not evaluated: the worker could not be isolated")
    assert "network: " in evaluation.reason


def test_isolation_can_be_disabled_for_debugging(tmp_path):
    outside = tmp_path / "outside.txt"
    evaluation = sandboxed(writer(outside), SandboxLimits(timeout_s=60, isolation=False))
    assert evaluation.valid, evaluation.reason
    assert outside.read_text() == "escaped"


def test_unserialisable_settings_are_a_caller_error():
    with pytest.raises(TypeError, match="settings.options must be JSON-serialisable"):
        sandboxed("", settings=EvaluationSettings(options={"f": object()}))
    with SandboxPool(1, LIMITS) as pool, pytest.raises(TypeError, match="settings.options"):
        pool.submit(DOUBLE, "", EvaluationSettings(options={"f": object()}))


@pytest.mark.parametrize(
    ("kwargs", "error", "message"),
    [
        ({"timeout_s": 0}, ValueError, "timeout_s must be a positive"),
        ({"timeout_s": float("inf")}, ValueError, "timeout_s"),
        ({"timeout_s": "10"}, TypeError, "timeout_s must be a number"),
        ({"memory_mb": 10}, ValueError, "memory_mb must be at least 64"),
        ({"file_size_mb": 1.5}, TypeError, "file_size_mb must be an integer"),
        ({"threads": 0}, ValueError, "threads must be at least 1"),
        ({"isolation": "yes"}, TypeError, "isolation must be True or False"),
    ],
)
def test_limits_are_validated(kwargs, error, message):
    with pytest.raises(error, match=message):
        SandboxLimits(**kwargs)
