"""Small pieces of wording the command line shares: counts with their noun in the right number,
and how many times a loss lies below or above another.

Standard library only, so that any part of the agent (the report too) may import it.
"""

from __future__ import annotations

import math


def counted(count: int, noun: str, plural: str = "") -> str:
    """``count`` with ``noun`` in the right number: "1 evaluation", "3 evaluations", "0
    evaluations"; ``plural`` where adding an "s" is wrong ("1 candidate answer", "2 analyses").

    >>> counted(1, "screen"), counted(2, "screen"), counted(2, "analysis", "analyses")
    ('1 screen', '2 screens', '2 analyses')
    """
    return f"{count} {noun if count == 1 else plural or noun + 's'}"


def times_below(ratio: float, reference: str = "") -> str:
    """How a loss compares with a ``reference`` ("the seed's"; "" for a table's cell), ``ratio``
    being the reference's loss over this one (more than 1: this one is lower, better).

    >>> times_below(38.9, "the seed's"), times_below(0.5, "the seed's")
    ("38.9x below the seed's", "2.00x above the seed's")
    >>> times_below(1.0, "the seed's"), times_below(1.0), times_below(0.25)
    ("equal to the seed's", 'equal', '4.00x above')
    """
    if not math.isfinite(ratio) or ratio <= 0:
        return f"not comparable with {reference}" if reference else "-"
    if ratio == 1:
        return f"equal to {reference}" if reference else "equal"
    factor = ratio if ratio > 1 else 1 / ratio
    words = f"{_factor(factor)}x {'below' if ratio > 1 else 'above'}"
    return f"{words} {reference}" if reference else words


def _factor(value: float) -> str:
    return f"{value:.2f}" if value < 10 else f"{value:.3g}"
