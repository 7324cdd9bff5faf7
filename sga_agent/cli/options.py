"""Option checks shared by the ``sga-agent`` commands."""

from __future__ import annotations

import re
from collections.abc import Iterable
from typing import Any

import click

from sga_agent import registry, runner
from sga_agent.cuda import DeviceUnavailable, check_device
from sga_agent.options import OptionError
from sga_agent.task import TaskBase
from sga_agent.task.device import select_device

_DURATION = re.compile(r"(?:(\d+(?:\.\d*)?)h)?(?:(\d+(?:\.\d*)?)m)?(?:(\d+(?:\.\d*)?)s?)?")


class Duration(click.ParamType):
    """A wall time as ``15m``, ``1h30m``, ``90s`` or a number of seconds; its value is the
    seconds, a float."""

    name = "duration"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None):
        if isinstance(value, (int, float)):
            seconds = float(value)
        else:
            match = _DURATION.fullmatch(str(value).strip().lower())
            if match is None or not any(match.groups()):
                self.fail(f"{value!r} is not a duration: write e.g. 15m, 1h30m, 90s or 900",
                          param, ctx)  # fmt: skip
            hours, minutes, rest = (float(part or 0) for part in match.groups())
            seconds = 3600 * hours + 60 * minutes + rest
        if not seconds > 0:
            self.fail(f"{value!r} is not a positive duration", param, ctx)
        return seconds


def key_value_options(items: Iterable[str]) -> dict[str, str]:
    """``KEY=VALUE`` items as a dict of texts (typed later, against the task's options).

    Raises
    ------
    ValueError
        An item is not ``KEY=VALUE``.
    """
    options: dict[str, str] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        if not sep or not key:
            raise ValueError(f"{item!r} is not KEY=VALUE (e.g. steps=200)")
        options[key] = raw
    return options


def task_options(ctx: click.Context, param: click.Parameter, items: tuple[str, ...]):
    """Click callback: repeated ``--option KEY=VALUE`` as a dict of texts."""
    try:
        return key_value_options(items)
    except ValueError as error:
        raise click.BadParameter(str(error), ctx, param) from None


def typed_task_options(task: TaskBase, raw: dict[str, str], proposer: str = "") -> Any:
    """The task's options object read from ``raw`` (with its built-in proposer's options,
    when ``proposer`` is that: :func:`sga_agent.runner.task_options`); a usage error if
    ``raw`` does not fit the task's options."""
    try:
        return runner.task_options(task, raw, proposer)
    except OptionError as error:
        raise click.BadParameter(str(error), param_hint="'--option'") from None


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


class Price(click.ParamType):
    """``IN,OUT``: USD per million input and output tokens."""

    name = "price"

    def convert(self, value: object, param: click.Parameter | None, ctx: click.Context | None):
        if isinstance(value, tuple):
            return value
        parts = str(value).replace(" ", "").split(",")
        try:
            prices = tuple(float(part) for part in parts)
        except ValueError:
            prices = ()
        if len(prices) != 2 or not all(0 <= p < float("inf") for p in prices):
            self.fail(
                f"{value!r} is not two prices: give USD per million input and output tokens "
                "as IN,OUT, e.g. --price 2.5,10",
                param, ctx,
            )  # fmt: skip
        return prices


def check_device_here(device: str) -> None:
    """A device this machine cannot run is a usage error, before anything starts; the chosen
    one is then this process's (its findings) as well as the fit workers'."""
    try:
        check_device(device)
    except DeviceUnavailable as error:
        raise click.UsageError(str(error)) from error
    select_device(device)
