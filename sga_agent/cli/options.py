"""Option checks shared by the ``sga-agent`` commands."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import click

from sga_agent import registry


def option_value(raw: str) -> int | float | str:
    """A task option's value from its text: an int, else a float, else the text."""
    for convert in (int, float):
        try:
            return convert(raw)
        except ValueError:
            continue
    return raw


def key_value_options(items: Iterable[str]) -> dict[str, Any]:
    """Task options from ``KEY=VALUE`` items (see :func:`option_value`).

    Raises
    ------
    ValueError
        An item is not ``KEY=VALUE``.
    """
    options: dict[str, Any] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        if not sep or not key:
            raise ValueError(f"{item!r} is not KEY=VALUE (e.g. steps=200)")
        options[key] = option_value(raw)
    return options


def task_options(ctx: click.Context, param: click.Parameter, items: tuple[str, ...]):
    """Click callback: repeated ``--option KEY=VALUE`` as a dict of task options."""
    try:
        return key_value_options(items)
    except ValueError as error:
        raise click.BadParameter(str(error), ctx, param) from None


def registered_task(ctx: click.Context, param: click.Parameter, name: str) -> str:
    """Click callback: reject an unregistered task name early, with "did you mean"."""
    try:
        registry.entry_point(name)  # imports nothing
    except registry.UnknownTaskError as error:
        raise click.BadParameter(str(error), ctx=ctx, param=param) from error
    return name


def task_or_factory(ctx: click.Context, param: click.Parameter, name: str) -> str:
    """As :func:`registered_task`, but a ``module:callable`` factory passes unchecked."""
    return name if ":" in name else registered_task(ctx, param, name)
