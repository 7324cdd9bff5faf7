"""Taichi runtime set-up: architecture and floating-point precision.

Nothing here runs on import. Call :func:`init` once per process before building a
:class:`~taichi_mpm.Simulator`; the precision chosen there is used by every array the
simulator allocates and by every kernel it compiles.
"""

from __future__ import annotations

from dataclasses import dataclass

import taichi as ti

from taichi_mpm import _compat, front_end
from taichi_mpm.spare_cores import SpareCores

_ARCHS = {"cpu": ti.cpu, "cuda": ti.cuda, "vulkan": ti.vulkan, "gpu": ti.gpu}
_PRECISIONS = {"float32": ti.f32, "float64": ti.f64}


class RuntimeNotInitialized(RuntimeError):
    """Raised when a simulator is built before :func:`init` was called."""


@dataclass(frozen=True)
class RuntimeInfo:
    """What :func:`init` selected."""

    arch: str
    precision: str
    backend: str  # what Taichi actually runs on (it falls back to the CPU without a GPU)
    threads: int = 1  # CPU threads of Taichi's parallel loops (TI_CPU_MAX_NUM_THREADS)

    @property
    def dtype(self):
        """The Taichi floating-point type of every simulator array."""
        return _PRECISIONS[self.precision]

    @property
    def spectral_tol(self) -> float:
        """Smallest singular-value gap resolved by the SVD gradient (see kernels.spectral)."""
        return 1e-6 if self.precision == "float64" else 1e-3


_current: RuntimeInfo | None = None
_spare_cores: SpareCores | None = None

#: Loops over at least this many items are worth running in parallel when Taichi has more
#: than one CPU thread (on smaller ones, waking the threads costs more than it saves).
PARALLEL_MIN_ITEMS = 4096


def init(
    arch: str = "cpu",
    precision: str = "float32",
    offline_cache: bool = True,
    debug: bool = False,
    **taichi_options,
) -> RuntimeInfo:
    """Initialise Taichi for taichi_mpm.

    Parameters
    ----------
    arch : {"cpu", "cuda", "vulkan", "gpu"}
        Backend. ``"gpu"`` lets Taichi pick any available GPU backend.
    precision : {"float32", "float64"}
        Floating-point type of all simulation arrays (float64 for gradient checks).
    offline_cache : bool
        Keep compiled kernels on disk (under ``~/.cache/taichi``) so that later
        processes skip the slow first compilation.
    debug : bool
        Taichi's bounds-checking debug mode (slow).
    **taichi_options
        Passed through to ``ti.init``.

    Calling ``init`` again re-initialises Taichi: every existing simulator becomes invalid.
    It also installs the short source positions of :mod:`taichi_mpm.front_end` (a hook on
    Taichi's front end, which nothing installs on import).
    """
    global _current
    if arch not in _ARCHS:
        raise ValueError(f"arch={arch!r} is not supported; use one of {sorted(_ARCHS)}")
    if precision not in _PRECISIONS:
        raise ValueError(f"precision={precision!r} is not supported; use 'float32' or 'float64'")
    ti.init(
        arch=_ARCHS[arch],
        default_fp=_PRECISIONS[precision],
        offline_cache=offline_cache,
        debug=debug,
        log_level=taichi_options.pop("log_level", ti.WARN),
        **taichi_options,
    )
    _compat.shorten_source_positions(front_end.is_short)
    backend = _compat.arch_name()
    backend = "cpu" if backend in ("x64", "arm64") else backend
    threads = _compat.cpu_threads()
    _current = RuntimeInfo(arch=arch, precision=precision, backend=backend, threads=threads)
    return _current


def current() -> RuntimeInfo:
    """The runtime chosen by the last :func:`init` call."""
    if _current is None:
        raise RuntimeNotInitialized(
            "taichi_mpm is not initialised: call taichi_mpm.init(arch='cpu') first"
        )
    return _current


def parallel_worthwhile(items: int, minimum: int = PARALLEL_MIN_ITEMS) -> bool:
    """Whether a loop over ``items`` particles should run in parallel on this runtime, now:
    always on a GPU; on a CPU from ``minimum`` items when Taichi has more than one thread and
    other processes leave a core for each of them (:class:`~taichi_mpm.spare_cores.SpareCores`;
    a parallel loop waits for its slowest thread, and a thread that shares a busy core is late
    by a time slice). Ask again before each launch: the answer follows the machine's load."""
    global _spare_cores
    info = current()
    if info.arch != "cpu":
        return True
    if info.threads <= 1 or items < minimum:
        return False
    if _spare_cores is None:
        _spare_cores = SpareCores()
    return _spare_cores.allow(info.threads)
