"""One option picks where fits compute: ``--device cpu|cuda`` on ``search``, ``evaluate`` and
``resume``. On a machine without CUDA (this one), ``cuda`` is a usage error before anything
starts, naming what is missing; the choice reaches the fit workers' environment and Taichi's
arch. The GPU itself is never reached here: where a test needs CUDA to be present, it says so
by replacing the two availability probes."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from sga_agent import cuda, sandbox
from sga_agent.cli import main
from sga_agent.config import SearchConfig
from sga_agent.sandbox import SandboxLimits
from sga_agent.task import device
from tests.sga_agent.doubles import law_solution

REPOSITORY = Path(__file__).resolve().parents[2]


def _no_cuda_here() -> None:
    try:
        cuda.check_device("cuda")
    except cuda.DeviceUnavailable:
        return
    pytest.skip("this machine has CUDA: the refusal cannot be seen here")


def test_search_on_cuda_without_it_is_a_usage_error_and_starts_nothing(tmp_path: Path) -> None:
    _no_cuda_here()
    out = tmp_path / "runs"
    result = CliRunner().invoke(main, ["search", "--task", "elastic", "--device", "cuda",
                                       "--out-dir", str(out)])  # fmt: skip
    assert result.exit_code == 2, result.output
    assert "--device cuda cannot run here" in result.output
    assert "sees no CUDA device" in result.output and "leave --device out" in result.output
    assert not out.exists()


def test_evaluate_on_cuda_without_it_is_a_usage_error(tmp_path: Path) -> None:
    _no_cuda_here()
    law = tmp_path / "law.py"
    law.write_text(law_solution("pass"))
    result = CliRunner().invoke(main, ["evaluate", "--task", "elastic", "--device", "cuda",
                                       str(law)])  # fmt: skip
    assert result.exit_code == 2, result.output
    assert "--device cuda cannot run here" in result.output


def test_an_unknown_device_is_a_usage_error() -> None:
    result = CliRunner().invoke(main, ["search", "--task", "elastic", "--device", "tpu"])
    assert result.exit_code == 2 and "'tpu' is not one of 'cpu', 'cuda'" in result.output


def test_cuda_passes_the_check_where_torch_and_taichi_have_it(monkeypatch) -> None:
    monkeypatch.setattr(cuda, "_torch_cuda_problem", lambda: "")
    monkeypatch.setattr(cuda, "_taichi_cuda_problem", lambda: "")
    cuda.check_device("cuda")
    monkeypatch.setattr(cuda, "_taichi_cuda_problem", lambda: "Taichi 1.7 was built without")
    with pytest.raises(cuda.DeviceUnavailable, match="Taichi 1.7 was built without"):
        cuda.check_device("cuda")


def test_the_device_goes_from_the_config_to_the_fit_workers() -> None:
    config = SearchConfig.from_preset("quick", task="elastic", proposer="builtin",
                                      device="cuda")  # fmt: skip
    limits = config.sandbox.limits(threads=1)
    assert limits.device == "cuda"
    assert sandbox.worker_environment(limits)[device.VARIABLE] == "cuda"
    assert sandbox.worker_environment(SandboxLimits())[device.VARIABLE] == "cpu"
    with pytest.raises(ValueError, match="device must be one of cpu, cuda"):
        SandboxLimits(device="tpu")


def test_a_process_starts_taichi_on_its_selected_device(monkeypatch) -> None:
    monkeypatch.delenv(device.VARIABLE, raising=False)
    assert device.selected_device() == "cpu"
    device.select_device("cuda")
    assert os.environ[device.VARIABLE] == "cuda" and device.selected_device() == "cuda"
    code = ("from tasks.constitutive.evaluation import ensure_runtime; "
            "from taichi_mpm import runtime; ensure_runtime('float32'); "
            "print(runtime.current().arch)")  # fmt: skip
    for chosen in ("cpu", "cuda"):
        env = os.environ | {device.VARIABLE: chosen}
        done = subprocess.run([sys.executable, "-c", code], env=env, cwd=REPOSITORY,
                              capture_output=True, text=True, check=True)  # fmt: skip
        assert done.stdout.split()[-1] == chosen  # asked of Taichi (it falls back without CUDA)


def test_resume_on_cuda_without_it_is_a_usage_error_and_changes_nothing(tmp_path: Path) -> None:
    _no_cuda_here()
    from sga_agent.run_store import RunStore

    config = SearchConfig.from_preset("quick", task="elastic", proposer="builtin")
    store = RunStore.create(tmp_path, config, {"proposer": "builtin"})
    before = (store.path / "config.json").read_text()
    result = CliRunner().invoke(main, ["resume", str(store.path), "--device", "cuda"])
    assert result.exit_code == 2, result.output
    assert "--device cuda cannot run here" in result.output
    assert (store.path / "config.json").read_text() == before
