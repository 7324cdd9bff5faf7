"""Taichi kernels of the simulator, one per MPM phase."""
