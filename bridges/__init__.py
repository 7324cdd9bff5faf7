"""Torch in the loop of :mod:`taichi_mpm`.

:mod:`bridges.step` wraps one MPM step in a ``torch.autograd.Function`` (Taichi forward and
reverse kernels), :mod:`bridges.rollout` strings steps with torch constitutive laws into
trajectories whose loss is back-propagated segment by segment (teacher forcing or
checkpoints), :mod:`bridges.linalg` gives 3x3 SVD/polar decompositions with stable gradients,
and :mod:`bridges.laws` has taichi_mpm's built-in materials written in torch. Imports
``taichi_mpm`` and ``torch``, never ``tasks`` or ``sga_agent``.
"""
