"""Benchmark grids: tasks x methods x seeds, one search run per cell, and their Table-1 summary.

:mod:`.grid` plans the cells (validating every name first), runs the missing and unfinished
ones in parallel worker processes and skips the finished ones; :mod:`.table` reads the cells'
final losses into ``table.md``/``table.csv`` (mean and spread per task and method) and
``ranks.csv``; :mod:`.chart` draws ``ranks.png``; :mod:`.cli` holds the command-line options
shared by ``benchmarks/backbones.py`` and ``benchmarks/presets.py``.
"""

from __future__ import annotations

from sga_agent.benchmark.grid import Cell, GridError, Method, plan_cells, run_cells

__all__ = ["Cell", "GridError", "Method", "plan_cells", "run_cells"]
