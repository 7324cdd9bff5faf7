"""The sandbox: results come back, and every way a candidate can fail becomes a reason."""

import os
import tempfile
import time
from pathlib import Path

import pytest

from sga_agent.sandbox import SandboxLimits, SandboxPool, evaluate_in_sandbox, looks_secret
from sga_agent.task import EvaluationSettings

REPO_ROOT = Path(__file__).resolve().parents[2]
DOUBLE = "tests.sga_agent.doubles:ExecTask"
SETTINGS = EvaluationSettings()
LIMITS = SandboxLimits(timeout_s=60)


def sandboxed(solution, limits=LIMITS, settings=SETTINGS, task=DOUBLE):
    return evaluate_in_sandbox(task, solution, settings, limits, extra_python_path=[REPO_ROOT])


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
    assert evaluation.loss == 0.25
    assert evaluation.parameters == {"E": 3.0}
    assert evaluation.extras["settings"] == {
        "epochs": 3,
        "learning_rate": 0.1,
        "seed": 7,
        "options": {"a": [1, 2]},
    }
    assert 0 < evaluation.seconds < 30


def test_sleeping_solution_is_killed_at_the_time_limit():
    start = time.monotonic()
    evaluation = sandboxed("import time\ntime.sleep(60)\n", SandboxLimits(timeout_s=1.5))
    assert not evaluation.valid
    assert evaluation.reason == "exceeded the time limit of 1.5 s"
    assert evaluation.loss == float("inf")
    assert time.monotonic() - start < 10
    assert 1.5 <= evaluation.seconds < 10


def test_memory_hog_is_stopped_with_a_clear_reason():
    hog = "chunks = []\nwhile True:\n    chunks.append(bytearray(64 * 2**20))\n"
    evaluation = sandboxed(hog, SandboxLimits(timeout_s=60, memory_mb=256))
    assert not evaluation.valid
    assert evaluation.reason.startswith("exceeded the memory limit of 256 MB"), evaluation.reason
    assert "MemoryError" in evaluation.reason


def test_exception_in_evaluate_gives_reason_and_traceback():
    evaluation = sandboxed("def law():\n    raise ValueError('bad law')\nlaw()\n")
    assert not evaluation.valid
    assert evaluation.reason == "evaluation raised ValueError: bad law"
    assert "in law" in evaluation.extras["traceback"]
    assert evaluation.extras["traceback"].rstrip().endswith("ValueError: bad law")


def test_exit_calls_are_contained():
    evaluation = sandboxed("import sys\nsys.exit(3)\n")
    assert evaluation.reason == "evaluation raised SystemExit: 3"
    evaluation = sandboxed("import os\nos._exit(0)\n")
    assert evaluation.reason == "the sandbox worker exited without writing a result"
    evaluation = sandboxed("import os\nos._exit(4)\n")
    assert evaluation.reason == "the sandbox worker exited with status 4"


def test_fatal_signal_is_named():
    evaluation = sandboxed("import os, signal\nos.kill(os.getpid(), signal.SIGSEGV)\n")
    assert not evaluation.valid
    assert evaluation.reason.startswith("killed by SIGSEGV"), evaluation.reason
    assert "Fatal Python error" in evaluation.extras["log"]  # faulthandler's traceback


def test_environment_is_scrubbed(monkeypatch):
    monkeypatch.setenv("FAKE_API_KEY", "sk-123")
    monkeypatch.setenv("TI_FAKE_TOKEN", "abc")  # a kept prefix does not let a secret through
    monkeypatch.setenv("SGA_UNRELATED", "1")
    monkeypatch.setenv("HOME", "/home/somebody")
    evaluation = sandboxed("", SandboxLimits(timeout_s=60, threads=2))
    environ = evaluation.extras["environ"]
    assert not {"FAKE_API_KEY", "TI_FAKE_TOKEN", "SGA_UNRELATED"} & set(environ)
    assert environ["HOME"] == "/home/somebody"
    assert environ["OMP_NUM_THREADS"] == environ["TI_CPU_MAX_NUM_THREADS"] == "2"
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


def test_working_directory_is_a_removed_temporary_directory():
    evaluation = sandboxed("open('scratch.txt', 'w').write('x')\n")
    cwd = Path(evaluation.extras["cwd"])
    assert cwd != Path.cwd()
    assert cwd.is_relative_to(Path(tempfile.gettempdir()).resolve())
    assert not cwd.exists()


def test_file_size_limit_is_contained():
    writer = "with open('big.bin', 'wb') as f:\n    f.write(b'0' * (3 * 2**20))\n"
    evaluation = sandboxed(writer, SandboxLimits(timeout_s=60, file_size_mb=1))
    assert not evaluation.valid
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
def test_task_that_cannot_be_loaded_is_reported(task, reason):
    evaluation = sandboxed("", task=task)
    assert not evaluation.valid
    assert reason in evaluation.reason


def test_pool_returns_evaluations_in_input_order():
    solutions = [f"import time\ntime.sleep({0.3 * (2 - i)})\nloss = {i}\n" for i in range(3)]
    with SandboxPool(2, SandboxLimits(timeout_s=60), extra_python_path=[REPO_ROOT]) as pool:
        evaluations = pool.map(DOUBLE, solutions, SETTINGS)
    assert [evaluation.loss for evaluation in evaluations] == [0.0, 1.0, 2.0]


def test_unserialisable_settings_are_a_caller_error():
    with pytest.raises(TypeError, match="settings.options must be JSON-serialisable"):
        sandboxed("", settings=EvaluationSettings(options={"f": object()}))


@pytest.mark.parametrize(
    ("kwargs", "error", "message"),
    [
        ({"timeout_s": 0}, ValueError, "timeout_s must be a positive"),
        ({"timeout_s": float("inf")}, ValueError, "timeout_s"),
        ({"timeout_s": "10"}, TypeError, "timeout_s must be a number"),
        ({"memory_mb": 10}, ValueError, "memory_mb must be at least 64"),
        ({"file_size_mb": 1.5}, TypeError, "file_size_mb must be an integer"),
        ({"threads": 0}, ValueError, "threads must be at least 1"),
    ],
)
def test_limits_are_validated(kwargs, error, message):
    with pytest.raises(error, match=message):
        SandboxLimits(**kwargs)
