"""Shared fixtures: one float64 Taichi runtime for the whole session; heavy tests are slow.

In-process tests compare Taichi with torch and with finite differences to 1e-10, so they run
in float64. The precision users run, float32 (the tasks' default), is what every test that
evaluates through the sandbox sees: each fit worker starts Taichi with the task's options.
"""

import pytest


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """A test marked ``heavy`` (minutes) is also ``slow``, so ``-m "not slow"`` skips it."""
    for item in items:
        if item.get_closest_marker("heavy") is not None:
            item.add_marker(pytest.mark.slow)


@pytest.fixture(scope="session", autouse=True)
def taichi_runtime():
    import taichi_mpm

    return taichi_mpm.init(arch="cpu", precision="float64")
