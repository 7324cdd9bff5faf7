"""Option checks shared by the ``sga-agent`` commands."""

from __future__ import annotations

import click

from sga_agent import registry


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
