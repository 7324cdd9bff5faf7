"""Registering a task the way an installed distribution does, for tests: a dist-info folder
with an ``sga_agent.tasks`` entry point, on the path of this process and of its children."""

from __future__ import annotations

import os
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def register_task(site: Path, name: str, target: str) -> dict[str, str]:
    """Write ``site/<name>_task-1.0.dist-info`` registering task ``name`` as ``target``
    ("module:attribute"); the environment whose ``PYTHONPATH`` starts with ``site`` and the
    repository, for processes (the CLI, capture servers, fit workers) that must find it. Put
    ``site`` on ``sys.path`` too where this process looks the task up."""
    distribution = f"{name.replace('-', '_')}_task"
    info = site / f"{distribution}-1.0.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(
        f"Metadata-Version: 2.1\nName: {distribution.replace('_', '-')}\nVersion: 1.0\n"
    )
    (info / "entry_points.txt").write_text(f"[sga_agent.tasks]\n{name} = {target}\n")
    path = os.pathsep.join(filter(None, [str(site), str(REPO), os.environ.get("PYTHONPATH")]))
    return {**os.environ, "PYTHONPATH": path}
