"""Turning a law's source code into a ``Physics`` module, with one-line reasons when it fails.

Checks the code's shape first (:mod:`tasks.constitutive.law_shape`: a class ``Physics``
deriving from ``torch.nn.Module``, an ``__init__`` whose arguments all have defaults, and
``forward(self, F)``), then runs it (it is untrusted: call this only in the confined capture
process, see :mod:`tasks.constitutive.law_capture`) in a fresh module namespace and checks that
it did bind ``Physics`` to such a class. An error while it runs is explained by
:mod:`tasks.constitutive.law_errors` (its cause, its line of the code, the fix).
"""

from __future__ import annotations

import ast
import sys
import types
import warnings

import torch
from torch import nn

from sga_agent.task import CodeRejected, InvalidSolution
from tasks.constitutive.law_errors import LAW_FILENAME, describe_error, explain, quote_line
from tasks.constitutive.law_shape import CLASS_NAME, law_problems

__all__ = ["LawCodeError", "describe_error", "load_law"]


#: The name of the module a law's code runs in.
LAW_MODULE = "sga_law"


class LawCodeError(InvalidSolution):
    """The code does not define a usable law; the message is one line for the model."""


def load_law(code: str, dtype: torch.dtype) -> nn.Module:
    """Execute ``code`` and return ``Physics()`` with its parameters cast to ``dtype``."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", (DeprecationWarning, SyntaxWarning))
            tree = ast.parse(code)
            compiled = compile(tree, LAW_FILENAME, "exec")
    except SyntaxError as error:
        where = quote_line(code, error.lineno) or f"line {error.lineno}"
        raise LawCodeError(
            f"the code does not compile: SyntaxError: {error.msg}, at {where}"
        ) from None
    problems = law_problems(tree)
    if problems:
        raise LawCodeError(str(CodeRejected(problems)).replace("\n", "; "))
    module = types.ModuleType(LAW_MODULE)
    sys.modules[LAW_MODULE] = module  # what @dataclass and typing look a class's module up in
    try:
        exec(compiled, module.__dict__)  # noqa: S102 - confined capture process only
    except Exception as error:
        raise LawCodeError(f"running the code failed: {explain(error, code)}") from None
    finally:
        sys.modules.pop(LAW_MODULE, None)
    cls = module.__dict__.get(CLASS_NAME)
    if cls is None:
        raise LawCodeError(f"the code defines no class named {CLASS_NAME!r}")
    if not (isinstance(cls, type) and issubclass(cls, nn.Module)):
        raise LawCodeError(f"{CLASS_NAME} must be a class deriving from torch.nn.Module")
    try:
        law = cls()
    except Exception as error:
        raise LawCodeError(f"{CLASS_NAME}() failed: {explain(error, code)}") from None
    return law.to(dtype)
