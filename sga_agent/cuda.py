"""Whether a device can run on this machine: ``cuda`` needs torch to see a CUDA device and
Taichi built with CUDA; the command line checks it before anything starts, so that a missing
GPU is a usage error that says what is missing (:mod:`sga_agent.task.device` carries the
choice)."""

from __future__ import annotations

from sga_agent.task.device import check_device_name


class DeviceUnavailable(ValueError):
    """The chosen device cannot run here; the message names what is missing."""


def check_device(device: str) -> None:
    """Raise :class:`DeviceUnavailable` unless ``device`` can run on this machine (``cpu``
    always can); a name outside :data:`~sga_agent.task.device.DEVICES` is a ``ValueError``."""
    check_device_name(device)
    if device == "cpu":
        return
    missing = [problem for problem in (_torch_cuda_problem(), _taichi_cuda_problem()) if problem]
    if missing:
        raise DeviceUnavailable(
            f"--device cuda cannot run here: {'; '.join(missing)}. Run on a machine with an "
            "NVIDIA GPU, its driver and CUDA builds of torch and Taichi, or leave --device out "
            "(cpu)"
        )


def _torch_cuda_problem() -> str:
    import torch

    if torch.cuda.is_available():
        return ""
    built = torch.version.cuda
    build = f"built with CUDA {built}" if built else "a CPU-only build"
    return f"torch {torch.__version__} ({build}) sees no CUDA device"


def _taichi_cuda_problem() -> str:
    import taichi

    if taichi._lib.core.with_cuda():
        return ""
    version = ".".join(map(str, taichi.__version__))
    return f"Taichi {version} was built without CUDA"
