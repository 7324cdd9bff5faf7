"""Molecule tests run torch on one thread, as the sandbox worker does (2 threads are several
times slower for these small xTB matrices)."""

import pytest
import torch


@pytest.fixture(autouse=True)
def one_torch_thread():
    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(previous)
