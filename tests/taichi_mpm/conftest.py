"""Fixtures of the taichi_mpm tests."""

import pytest


@pytest.fixture
def prompt_lines(monkeypatch):
    """Plain lines of progress (taichi_mpm/cli/heartbeat.py) at once and for each change: no
    5 s of grace, no 5 s between two lines."""
    from taichi_mpm.cli import heartbeat

    for name in ("GRACE_S", "EVERY_S"):
        monkeypatch.setattr(heartbeat, name, 0.0)
