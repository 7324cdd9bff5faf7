"""Counts in the right number, and a ratio to a reference read by its side of 1."""

from __future__ import annotations

import math

from sga_agent.wording import counted, times_below


def test_counted_uses_the_singular_for_one_only():
    assert [counted(n, "screen") for n in (0, 1, 2)] == ["0 screens", "1 screen", "2 screens"]
    assert counted(2, "analysis", "analyses") == "2 analyses"


def test_a_ratio_below_one_reads_above():
    assert times_below(38.9, "the seed's") == "38.9x below the seed's"
    assert times_below(0.5, "the seed's") == "2.00x above the seed's"
    assert times_below(0.01) == "100x above"
    assert times_below(1.0, "the seed's") == "equal to the seed's" and times_below(1.0) == "equal"
    assert times_below(math.inf) == "-" and times_below(0.0, "x") == "not comparable with x"
