"""Every use of Taichi 1.7's private API in this project, in one place.

Taichi has no public way to do what these functions do: build a kernel's body from plain
Python while it compiles, read the compile configuration, forget a kernel, or change how its
front end formats source positions, or release an argument pack safely at exit. Each function
here names what it reaches into, so that a Taichi upgrade is checked here alone
(``tests/test_import_rules.py`` keeps every other module away from ``taichi.lang``).

Nothing here runs on import: a hook on Taichi's classes is installed only by the call that asks
for it (:func:`shorten_source_positions` from :func:`taichi_mpm.init`, :func:`on_kernel_launch`
and :func:`on_compile` from the benchmark and the test that measure with them).
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Callable, Iterator
from typing import Any

from taichi.lang import impl
from taichi.lang.argpack import ArgPack, ArgPackType
from taichi.lang.kernel_impl import Kernel

# ------------------------------------------------------------- building a kernel's body


def local(value: Any) -> Any:
    """A kernel-local variable holding ``value`` (an expression of the kernel being compiled),
    as an assignment in the kernel's own code makes one (``impl.expr_init``)."""
    return impl.expr_init(value)


def element(array: Any, *index: Any) -> Any:
    """``array[index]`` inside the kernel being compiled (``impl.subscript``)."""
    return impl.subscript(None, array, *index)


def store(target: Any, value: Any) -> None:
    """``target = value`` for an element ``target`` of an array (``Expr._assign``)."""
    target._assign(value)


# ------------------------------------------------------------------------ the runtime


def arch_name() -> str:
    """The running backend, as Taichi names it (``x64``, ``arm64``, ``cuda``...)."""
    return impl.current_cfg().arch.name


def cpu_threads() -> int:
    """Threads of the running CPU backend's parallel loops."""
    return impl.current_cfg().cpu_max_num_threads


@contextlib.contextmanager
def without_offline_cache() -> Iterator[None]:
    """Kernels compiled inside are not written to (nor read from) Taichi's offline cache."""
    config = impl.current_cfg()
    cached, config.offline_cache = config.offline_cache, False
    try:
        yield
    finally:
        config.offline_cache = cached


def runtime_kernels() -> list:
    """Taichi's Python runtime's list of every kernel made (``Kernel`` objects, adjoints too)."""
    return impl.get_runtime().kernels


def forget(kernels: list) -> None:
    """Remove ``kernels`` (functions made by ``ti.kernel``) from :func:`runtime_kernels`, with
    their adjoints, and drop their compiled handles: what Taichi 1.7 allows to free of a
    kernel (its C++ side stays until ``ti.reset()``)."""
    listed = runtime_kernels()
    for wrapper in kernels:
        for kernel in (wrapper._primal, wrapper._adjoint):
            kernel.compiled_kernels.clear()
            for index, other in enumerate(listed):
                if other is kernel:
                    del listed[index]
                    break


# --------------------------------------------------------------------------- hooks


def on_kernel_launch(wrap: Callable[[Callable, Any], Any]) -> None:
    """From now on, every kernel launch in this process runs as ``wrap(launch, kernel)``:
    ``launch()`` launches, and ``kernel.func.__name__`` names the kernel's Python function."""
    launch = Kernel.__call__

    def wrapped(kernel, *args, **kwargs):
        return wrap(lambda: launch(kernel, *args, **kwargs), kernel)

    Kernel.__call__ = wrapped


def on_compile(record: Callable[[str], None]) -> None:
    """From now on, ``record(name)`` is called with a kernel's function name whenever one is
    compiled in this process (a new specialisation, not one Taichi already holds)."""
    materialize = Kernel.materialize

    def counting(kernel, *args, **kwargs):
        key = kwargs.get("key", args[0] if args else None)
        if key not in kernel.compiled_kernels:
            record(kernel.func.__name__)
        return materialize(kernel, *args, **kwargs)

    Kernel.materialize = counting


def _none_short(file: str) -> bool:
    return False


_short: Callable[[str], bool] = _none_short


def shorten_source_positions(is_short: Callable[[str], bool]) -> None:
    """Format the source positions of kernels in files where ``is_short(file)`` holds as the
    file, the line and that line's source, without Taichi's wrapping and carets.

    Taichi 1.7 formats a position for each AST node its front end visits, even when the offline
    cache holds the compiled kernel; for the bridge's unrolled step kernels that is a large
    share of their front end. Compiled kernels and their cache keys do not change. Where
    Taichi's front end lacks the method replaced (``ASTTransformerContext.get_pos_info``),
    nothing is changed. Calling it again replaces ``is_short``.
    """
    global _short
    _short = is_short
    try:
        from taichi.lang.ast.ast_transformer_utils import ASTTransformerContext
    except ImportError:
        return
    full = getattr(ASTTransformerContext, "get_pos_info", None)
    if full is None or getattr(full, "_shortened", False):
        return

    def get_pos_info(context, node) -> str:
        file = str(context.file)
        if not _short(file):
            return full(context, node)
        line = node.lineno + context.lineno_offset
        source = context.src[node.lineno - 1].strip()
        return f'File "{file}", line {line}, in {context.func.func.__name__}:\n{source}\n'

    get_pos_info._shortened = True
    ASTTransformerContext.get_pos_info = get_pos_info


class _Pack(ArgPack):
    """An argument pack that leaves its memory to the process's end once the interpreter is
    finalizing: Taichi 1.7's own release then reads module state already cleared and prints an
    ignored exception for every pack still alive (one held by a module-level simulator)."""

    def __del__(self, finalizing=sys.is_finalizing) -> None:
        if not finalizing():
            super().__del__()


class PackType(ArgPackType):
    """``ti.types.argpack`` whose instances are :class:`_Pack` (same members and checks)."""

    def __call__(self, *args, **kwargs) -> ArgPack:
        checked = super().__call__(*args, **kwargs)  # Taichi's conversions and checks
        return _Pack(self.members, self.dtype, dict(checked.items))
