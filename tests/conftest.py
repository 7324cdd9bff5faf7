"""Shared fixtures: one float64 Taichi runtime for the whole session."""

import pytest


@pytest.fixture(scope="session", autouse=True)
def taichi_runtime():
    import taichi_mpm

    return taichi_mpm.init(arch="cpu", precision="float64")
