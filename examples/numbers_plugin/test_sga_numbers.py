"""The plugin's own test: it keeps the sga-agent task contract (run it with pytest)."""

from sga_numbers import NumbersTask

from sga_agent.testing import check_task


def test_the_task_keeps_the_contract():
    check_task(NumbersTask())  # its seed is also captured and scored
