"""``sga-agent report``: a static report (Markdown and HTML with PNG figures) of one run folder.

:mod:`.data` reads the run folder into plain records, :mod:`.findings` states what the run
found (with the task's own assessment), :mod:`.plots` draws the search figures,
:mod:`.candidates` tables every candidate, :mod:`.render` writes ``report.md`` and
``report.html``; :func:`build_report` ties them together. What is
specific to a task (its free run, its molecules) comes from the task's report hooks
(:class:`sga_agent.task.TaskBase`): this package imports no task.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from sga_agent.report.build import build_report

__all__ = ["build_report"]


def __getattr__(name: str) -> Any:
    """``build_report``, imported when first asked for: it brings matplotlib, which a command
    that only reaches this package's :mod:`.heartbeat` (every ``sga-agent`` command line)
    should not pay for."""
    if name == "build_report":
        from sga_agent.report.build import build_report

        return build_report
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
