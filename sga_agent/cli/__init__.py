"""Command line interface: ``sga-agent``.

One module per command: :mod:`.tasks`, :mod:`.evaluate`, :mod:`.search`, :mod:`.resume`,
:mod:`.report`.
"""

from __future__ import annotations

import os
import time

import click

from sga_agent.cli.clock import STARTED, process_started


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="sga-agent", prog_name="sga-agent")
@click.pass_context
def main(context: click.Context) -> None:
    """sga-agent: LLM-driven bilevel search for physics code and molecules.

    `sga-agent tasks` lists the registered tasks; `sga-agent evaluate` scores one solution
    file in the sandbox, exactly as the search does; `sga-agent search` runs the search and
    `sga-agent resume` continues a stopped one.
    """
    # A task that imports Taichi in this process (its findings, its report) under the
    # progress bar would take rich's stdout proxy for a notebook's and log "Graphical python
    # shell detected" through its own logger, straight onto the bar; its kernels print nothing.
    os.environ.setdefault("TI_ENABLE_PYBUF", "0")
    context.ensure_object(dict).setdefault(STARTED, time.monotonic())


def run() -> None:
    """The ``sga-agent`` program: :func:`main`, its wall time counted from the process's start
    (a ``--time-budget`` covers the start-up)."""
    main(obj={STARTED: process_started()}, prog_name="sga-agent")


# The commands register themselves on ``main`` when imported.
from sga_agent.cli import evaluate, report, resume, search, tasks  # noqa: E402, F401
