"""Which kernels get short source positions in Taichi's front end: those of named folders.

Taichi 1.7 turns each kernel's Python into its IR in every process, even when the offline
cache already holds the compiled kernel. On each AST node it visits it formats a position
for error messages: the file and line, and the node's source lines wrapped by ``textwrap``
with a caret line under each. The bridge's step kernels visit tens of thousands of nodes once
their static loops are unrolled, and the formatting is a large share of their front end
(``benchmarks/evaluate_against.py`` times a lone evaluation against a checkout without it).

:func:`shorten_positions_under` registers a folder (it only records it: nothing of Taichi
changes); :func:`taichi_mpm.init` then installs the hook
(:func:`taichi_mpm._compat.shorten_source_positions`) that makes the positions of kernels
defined under a registered folder the file, the line and that line's source, without wrapping
or carets. Taichi's errors still name them. Kernels elsewhere keep Taichi's full positions,
and the compiled kernels (and their offline cache keys) do not change.
"""

from __future__ import annotations

import os
from pathlib import Path

_folders: set[str] = set()


def shorten_positions_under(folder: str | Path) -> None:
    """Give the kernels and functions defined in files under ``folder`` short positions (from
    :func:`taichi_mpm.init` on, or at once if it ran)."""
    _folders.add(os.path.join(Path(folder).resolve(), ""))


def is_short(file: str) -> bool:
    """Whether kernels defined in ``file`` get short positions."""
    return any(file.startswith(folder) for folder in _folders)
