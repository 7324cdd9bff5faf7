"""Taichi kernels of the simulator, one per MPM phase."""

from pathlib import Path

from taichi_mpm.front_end import shorten_positions_under

shorten_positions_under(Path(__file__).parents[1])
