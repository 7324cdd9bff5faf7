"""Where evaluations compute: one choice, ``--device cpu`` or ``--device cuda``.

The device travels as the environment variable :data:`VARIABLE` from the command line into
every fit worker (:func:`sga_agent.sandbox.worker_environment`) and the search's own process,
where a task reads it with :func:`selected_device` when it starts its simulator (the
constitutive and observed tasks: Taichi's arch, whose names these are). The constitutive laws
(torch) compute on the CPU either way; on ``cuda`` Taichi copies a step's particle tensors to
the GPU and back around each kernel launch. No GPU has run this path yet.

The command line checks ``cuda`` before anything starts (:func:`sga_agent.cuda.check_device`).
"""

from __future__ import annotations

import os

#: The devices a search or evaluation may run on.
DEVICES = ("cpu", "cuda")
#: The environment variable that carries the choice into fit workers.
VARIABLE = "SGA_DEVICE"


def check_device_name(device: str) -> None:
    """A ``ValueError`` unless ``device`` is one of :data:`DEVICES`."""
    if device not in DEVICES:
        raise ValueError(f"device must be one of {', '.join(DEVICES)}, got {device!r}")


def select_device(device: str) -> None:
    """Make ``device`` this process's choice (read by :func:`selected_device`)."""
    check_device_name(device)
    os.environ[VARIABLE] = device


def selected_device() -> str:
    """This process's device: :data:`VARIABLE` as the command line or the fit worker's start
    set it, ``cpu`` when unset."""
    device = os.environ.get(VARIABLE, "cpu")
    if device not in DEVICES:
        raise ValueError(f"{VARIABLE}={device!r} is not a device; use one of {', '.join(DEVICES)}")
    return device
