"""Task options from ``KEY=VALUE`` text, checked against the task's options dataclass.

A task declares its options as a dataclass (``Task.options_type``, see :mod:`sga_agent.task`):
each field's annotation gives the type (``int``, ``float``, ``bool``, ``str`` or a ``Literal``
of allowed strings, optionally ``| None``) and its ``__post_init__`` any further rule. Text is
converted field by field, then the dataclass is built so that its own checks run.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import types
import typing
from collections.abc import Mapping
from typing import Any

_TRUE, _FALSE = ("true", "yes", "on", "1"), ("false", "no", "off", "0")


class OptionError(ValueError):
    """An unknown option or a bad value; the message names the option and what it takes."""


def parse_options(options_type: type, raw: Mapping[str, str], task: str) -> dict[str, Any]:
    """The options in ``raw`` (text values) converted to their fields' types.

    Only the given keys are returned (the task's defaults stay the task's), as the dataclass
    holds them after its ``__post_init__`` (which may normalise a value, e.g. make a path
    absolute).

    Raises
    ------
    OptionError
        An unknown key (with the closest known one), or a value its field does not take.
    """
    hints = typing.get_type_hints(options_type)
    fields = {field.name: hints[field.name] for field in dataclasses.fields(options_type)}
    values: dict[str, Any] = {}
    for key, text in raw.items():
        if key not in fields:
            close = difflib.get_close_matches(key, fields, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            known = describe_options(options_type) or "none"
            raise OptionError(f"task {task!r} has no option {key!r}{hint} (its options: {known})")
        values[key] = _convert(key, text, fields[key])
    try:
        built = options_type(**values)
    except (TypeError, ValueError) as error:
        raise OptionError(str(error)) from None
    return {key: getattr(built, key) for key in values}


def describe_options(options_type: type) -> str:
    """Each option and what it takes, e.g. "steps (integer), optimizer (adam|lbfgs)"."""
    hints = typing.get_type_hints(options_type)
    return ", ".join(
        f"{field.name} ({_describe(hints[field.name])})"
        for field in dataclasses.fields(options_type)
    )


def _base(annotation: Any) -> Any:
    """``X`` of ``X | None``."""
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        rest = [arg for arg in typing.get_args(annotation) if arg is not type(None)]
        if len(rest) == 1:
            return rest[0]
    return annotation


def _describe(annotation: Any) -> str:
    base = _base(annotation)
    if typing.get_origin(base) is typing.Literal:
        return "|".join(str(choice) for choice in typing.get_args(base))
    names = {int: "integer", float: "number", bool: "true|false", str: "text"}
    return names.get(base, getattr(base, "__name__", str(base)))


def _convert(key: str, text: str, annotation: Any) -> Any:
    base = _base(annotation)
    takes = {int: "an integer", float: "a finite number", bool: "true or false"}.get(base)
    if typing.get_origin(base) is typing.Literal:
        takes = "one of " + ", ".join(str(choice) for choice in typing.get_args(base))
    wrong = OptionError(f"option {key!r} takes {takes}, got {text!r}")
    if typing.get_origin(base) is typing.Literal:
        choices = {str(choice): choice for choice in typing.get_args(base)}
        if text not in choices:
            raise wrong
        return choices[text]
    if base is bool:
        if text.lower() not in _TRUE + _FALSE:
            raise wrong
        return text.lower() in _TRUE
    if base is str:
        return text
    if base in (int, float):
        try:
            value = base(text)
        except ValueError:
            raise wrong from None
        if not math.isfinite(value):
            raise wrong
        return value
    raise TypeError(f"option {key!r} has a type options cannot be read as: {annotation!r}")
