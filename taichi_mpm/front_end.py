"""Short source positions in Taichi's front end for the kernels of named source folders.

Taichi 1.7 turns each kernel's Python into its IR in every process, even when the offline
cache already holds the compiled kernel. On each AST node it visits it formats a position
for error messages: the file and line, and the node's source lines wrapped by ``textwrap``
with a caret line under each. The bridge's step kernels visit tens of thousands of nodes once
their static loops are unrolled, and the formatting is a large share of their front end
(``benchmarks/evaluate_against.py`` times a lone evaluation against a checkout without it).

:func:`shorten_positions_under` makes the positions of kernels defined under a folder the
file, the line and that line's source, without wrapping or carets. Taichi's errors still name
them. Kernels elsewhere keep Taichi's full positions, and the compiled kernels (and their
offline cache keys) do not change. Where Taichi's front end lacks the method this replaces,
nothing is changed.
"""

from __future__ import annotations

import os
from pathlib import Path

_folders: set[str] = set()


def shorten_positions_under(folder: str | Path) -> None:
    """Give the kernels and functions defined in files under ``folder`` short positions."""
    _folders.add(os.path.join(Path(folder).resolve(), ""))
    _install()


def _install() -> None:
    try:
        from taichi.lang.ast.ast_transformer_utils import ASTTransformerContext
    except ImportError:
        return
    full = getattr(ASTTransformerContext, "get_pos_info", None)
    if full is None or getattr(full, "_shortened", False):
        return

    def get_pos_info(context, node) -> str:
        file = str(context.file)
        if not any(file.startswith(folder) for folder in _folders):
            return full(context, node)
        line = node.lineno + context.lineno_offset
        source = context.src[node.lineno - 1].strip()
        return f'File "{file}", line {line}, in {context.func.func.__name__}:\n{source}\n'

    get_pos_info._shortened = True
    ASTTransformerContext.get_pos_info = get_pos_info
