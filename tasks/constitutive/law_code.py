"""Turning a law's source code into a ``Physics`` module, with one-line reasons when it fails.

Runs the code (it is untrusted: call this only in the confined capture process, see
:mod:`tasks.constitutive.law_capture`) in a fresh module namespace, then checks what the prompt
asks for: a class ``Physics`` deriving from ``torch.nn.Module``, an ``__init__`` whose arguments
all have defaults, and ``forward(self, F)``.
"""

from __future__ import annotations

import inspect
import types

import torch
from torch import nn

from sga_agent.task import InvalidSolution

CLASS_NAME = "Physics"


class LawCodeError(InvalidSolution):
    """The code does not define a usable law; the message is one line for the model."""


def load_law(code: str, dtype: torch.dtype) -> nn.Module:
    """Execute ``code`` and return ``Physics()`` with its parameters cast to ``dtype``."""
    try:
        compiled = compile(code, "<law>", "exec")
    except SyntaxError as error:
        raise LawCodeError(
            f"the code does not compile: SyntaxError: {error.msg} (line {error.lineno})"
        ) from None
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
    _check_init(cls)
    _check_forward(cls)
    try:
        law = cls()
    except Exception as error:
        raise LawCodeError(f"{CLASS_NAME}() raised {describe_error(error)}") from None
    return law.to(dtype)


def _check_init(cls: type) -> None:
    missing = [
        name
        for name, p in list(inspect.signature(cls.__init__).parameters.items())[1:]
        if p.default is inspect.Parameter.empty
        and p.kind not in (inspect.Parameter.VAR_POSITIONAL, inspect.Parameter.VAR_KEYWORD)
    ]
    if missing:
        raise LawCodeError(
            f"{CLASS_NAME}.__init__ arguments need default values (missing for: "
            f"{', '.join(missing)})"
        )


def _check_forward(cls: type) -> None:
    if cls.forward is nn.Module.forward:
        raise LawCodeError(f"{CLASS_NAME} defines no forward(self, F) method")
    params = list(inspect.signature(cls.forward).parameters.values())[1:]
    required = [p for p in params if p.default is inspect.Parameter.empty
                and p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]  # fmt: skip
    if len(required) != 1 and not any(p.kind == p.VAR_POSITIONAL for p in params):
        names = ", ".join(p.name for p in params) or "nothing"
        raise LawCodeError(
            f"{CLASS_NAME}.forward must take exactly one tensor F (B, 3, 3); it takes {names}"
        )


def describe_error(error: BaseException) -> str:
    """``ErrorType: first line of the message``."""
    message = str(error).strip().splitlines()
    return f"{type(error).__name__}: {message[0] if message else ''}".rstrip(": ")
