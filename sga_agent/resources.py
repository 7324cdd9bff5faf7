"""Access to data files shipped with :mod:`sga_agent`.

The prompt templates live in the ``prompts/`` folder at the repository root. ``sga_agent/prompts``
is a symlink to it, so it is the package ``sga_agent.prompts``, and every file in it is shipped as
that package's data (see ``pyproject.toml``). The same call therefore finds it in a source
checkout, an editable install and an installed wheel.
"""

from __future__ import annotations

import sys
from importlib.resources import files
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    if sys.version_info >= (3, 11):
        from importlib.resources.abc import Traversable
    else:
        from importlib.abc import Traversable

PROMPTS_PACKAGE = "sga_agent.prompts"


def prompts_dir() -> Traversable:
    """Return the folder that holds the LLM prompt templates.

    The result is an :class:`importlib.abc.Traversable` (a :class:`pathlib.Path` for ordinary
    installs); read a template with ``prompts_dir().joinpath("name.md").read_text()``. Besides the
    templates it holds ``__init__.py`` (and, once installed, possibly ``__pycache__``).
    """
    return files(PROMPTS_PACKAGE)
