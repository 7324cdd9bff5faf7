"""``sga-agent report``: a static report (Markdown and HTML with PNG figures) of one run folder.

:mod:`.data` reads the run folder into plain records, :mod:`.findings` states what the run
found (with the task's own assessment), :mod:`.plots` draws the search figures,
:mod:`.pictures` the optional task-specific pictures (importing task packages lazily),
:mod:`.render` writes ``report.md`` and ``report.html``; :func:`build_report` ties them together.
"""

from __future__ import annotations

from sga_agent.report.build import build_report

__all__ = ["build_report"]
