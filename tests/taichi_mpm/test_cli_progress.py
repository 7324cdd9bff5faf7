"""What ``taichi-mpm sysid`` tells of a fit in a pipe, without running one: the words of an
iteration, and the phases read from the fit's logger."""

from __future__ import annotations

import logging

from taichi_mpm.cli.sysid import FIT_LOGGER, FitPhases, iteration_text
from taichi_mpm.sysid.fit import Progress


def test_an_iteration_in_words():
    text = iteration_text(0, 1, 7, 200, 1.2273e-4, {"yield_stress": 1977.2, "E": 5e4})
    assert text == "fitting: iteration 7/200, loss 0.0001227, yield_stress=1977, E=5e+04"
    assert iteration_text(1, 3, 5, 50, 2.0, {}).startswith("fitting: run 2/3, iteration 5/50,")


def test_the_phases_of_the_fit_logger_are_shown_not_its_iterations():
    logger = logging.getLogger(FIT_LOGGER)
    before = logger.level
    shown: list[str] = []
    with FitPhases(shown.append):
        assert logger.isEnabledFor(logging.INFO)
        Progress(prefix="run 1/2: ")("fitting E with lbfgs, at most 200 iterations")
        Progress(prefix="run 1/2: ").iteration(3, 1e-4, {"E": 5e4})
        Progress().iteration(4, 1e-4, {"E": 5e4})
        Progress()("uncertainties: 2 simulations around the best fit")
    Progress()("after the fit: not shown")
    assert shown == [
        "run 1/2: fitting E with lbfgs, at most 200 iterations",
        "uncertainties: 2 simulations around the best fit",
    ]
    assert logger.level == before and FitPhases not in map(type, logger.handlers)
