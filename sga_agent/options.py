"""A task's typed options: read from ``KEY=VALUE`` text once, at the edge (the command line, a
run's config), and sent as JSON to the processes that evaluate.

A task declares its options as a dataclass (``Task.options_type``, see :mod:`sga_agent.task`):
each field's annotation gives the type (``int``, ``float``, ``bool``, ``str`` or a ``Literal``
of allowed strings, optionally ``| None``) and its ``__post_init__`` any further rule. Text is
converted field by field, then the dataclass is built once, so that its own checks run; from
then on the options are that object. :func:`options_json` is its one serialisation (the run's
config, the fit worker's command line) and :func:`options_from_data` builds it back, once, on
the other side.
"""

from __future__ import annotations

import dataclasses
import difflib
import json
import math
import types
import typing
from collections.abc import Mapping
from typing import Any

_TRUE, _FALSE = ("true", "yes", "on", "1"), ("false", "no", "off", "0")


class OptionError(ValueError):
    """An unknown option or a bad value; the message names the option and what it takes."""


def parse_options(options_type: type, raw: Mapping[str, str], task: str) -> Any:
    """The ``options_type`` object of the text values in ``raw`` (the rest by default).

    Raises
    ------
    OptionError
        An unknown key (with the closest known one), or a value its field does not take.
    """
    return _built(options_type, typed_values(options_type, raw, task))


def typed_values(options_type: type, raw: Mapping[str, str], task: str) -> dict[str, Any]:
    """The text values in ``raw`` converted to their fields' types (the dataclass's own checks
    are not run: :func:`parse_options` builds it).

    Raises
    ------
    OptionError
        An unknown key (with the closest known one), or a value its field does not take.
    """
    hints = typing.get_type_hints(options_type)
    fields = {field.name: hints[field.name] for field in dataclasses.fields(options_type)}
    _check_known(options_type, raw, task)
    return {key: _convert(key, text, fields[key]) for key, text in raw.items()}


def options_from_data(options_type: type, data: Mapping[str, Any], task: str) -> Any:
    """The ``options_type`` object of ``data``, values typed already (what :func:`options_data`
    gave, read back from JSON).

    Raises
    ------
    OptionError
        A key the options do not have (a run recorded by another version of the task), or a
        value they refuse.
    """
    _check_known(options_type, data, task)
    return _built(options_type, dict(data))


def options_data(options: Any) -> dict[str, Any]:
    """The options object as a dict of its fields (JSON values: its fields' types are)."""
    if not dataclasses.is_dataclass(options) or isinstance(options, type):
        raise TypeError(
            f"task options must be the task's options dataclass (its options_type), got "
            f"{type(options).__name__}: build it with parse_options or the dataclass itself"
        )
    return dataclasses.asdict(options)


def options_json(options: Any) -> str:
    """The options as JSON text (sorted keys: equal options, equal text); ``TypeError`` when
    they are not a dataclass or hold a value JSON cannot write."""
    data = options_data(options)
    try:
        return json.dumps(data, sort_keys=True, allow_nan=False)
    except (TypeError, ValueError) as error:
        raise TypeError(f"task options must be JSON-serialisable: {error}") from error


def option_names(options_type: type) -> tuple[str, ...]:
    """The names of the options ``options_type`` (a task's options dataclass) declares."""
    return tuple(field.name for field in dataclasses.fields(options_type))


def _check_known(options_type: type, given: Mapping[str, Any], task: str) -> None:
    names = option_names(options_type)
    for key in given:
        if key not in names:
            close = difflib.get_close_matches(key, names, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            known = describe_options(options_type) or "none"
            raise OptionError(f"task {task!r} has no option {key!r}{hint} (its options: {known})")


def _built(options_type: type, values: dict[str, Any]) -> Any:
    try:
        return options_type(**values)
    except (TypeError, ValueError) as error:
        raise OptionError(str(error)) from None


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
