"""Turning a law's source code into a ``Physics`` module, with one-line reasons when it fails.

Checks the code's shape first (:mod:`tasks.constitutive.law_shape`: a class ``Physics``
deriving from ``torch.nn.Module``, an ``__init__`` whose arguments all have defaults, and
``forward(self, F)``), then runs it (it is untrusted: call this only in the confined capture
process, see :mod:`tasks.constitutive.law_capture`) in a fresh module namespace and checks that
it did bind ``Physics`` to such a class.
"""

from __future__ import annotations

import ast
import types
import warnings

import torch
from torch import nn

from sga_agent.task import CodeRejected, InvalidSolution
from tasks.constitutive.law_shape import CLASS_NAME, law_problems


class LawCodeError(InvalidSolution):
    """The code does not define a usable law; the message is one line for the model."""


def load_law(code: str, dtype: torch.dtype) -> nn.Module:
    """Execute ``code`` and return ``Physics()`` with its parameters cast to ``dtype``."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", (DeprecationWarning, SyntaxWarning))
            tree = ast.parse(code)
            compiled = compile(tree, "<law>", "exec")
    except SyntaxError as error:
        raise LawCodeError(
            f"the code does not compile: SyntaxError: {error.msg} (line {error.lineno})"
        ) from None
    problems = law_problems(tree)
    if problems:
        raise LawCodeError(str(CodeRejected(problems)).replace("\n", "; "))
    module = types.ModuleType("law")
    try:
        exec(compiled, module.__dict__)  # noqa: S102 - confined capture process only
    except Exception as error:
        raise LawCodeError(f"running the code raised {describe_error(error)}") from None
    cls = module.__dict__.get(CLASS_NAME)
    if cls is None:
        raise LawCodeError(f"the code defines no class named {CLASS_NAME!r}")
    if not (isinstance(cls, type) and issubclass(cls, nn.Module)):
        raise LawCodeError(f"{CLASS_NAME} must be a class deriving from torch.nn.Module")
    try:
        law = cls()
    except Exception as error:
        raise LawCodeError(f"{CLASS_NAME}() raised {describe_error(error)}") from None
    return law.to(dtype)


def describe_error(error: BaseException) -> str:
    """``ErrorType: first line of the message``."""
    message = str(error).strip().splitlines()
    return f"{type(error).__name__}: {message[0] if message else ''}".rstrip(": ")
