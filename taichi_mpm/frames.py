"""Picking frames of a trajectory: evenly spaced integer steps or indices."""

from __future__ import annotations

import numpy as np


def evenly_spaced(first: float, last: float, count: int) -> np.ndarray:
    """Up to ``count`` distinct integers evenly spread from ``first`` to ``last``, both ends
    included (``np.linspace`` rounded half to even; fewer when the range holds fewer).

    >>> evenly_spaced(0, 100, 5).tolist()
    [0, 25, 50, 75, 100]
    >>> evenly_spaced(0, 2, 5).tolist()
    [0, 1, 2]
    """
    return np.unique(np.linspace(first, last, count).round().astype(np.int64))
