"""Torch in the loop of :mod:`taichi_mpm`.

:mod:`bridges.step` wraps one MPM step in a ``torch.autograd.Function`` (Taichi forward and
reverse kernels), :mod:`bridges.rollout` strings steps with torch constitutive laws into
trajectories whose loss is back-propagated segment by segment (teacher forcing or
checkpoints), :mod:`bridges.linalg` gives 3x3 SVD/polar decompositions with stable gradients,
and :mod:`bridges.laws` has taichi_mpm's built-in materials written in torch. Where a Taichi
CPU runtime runs, the laws' costly parts run in Taichi kernels with hand-written reverses:
the 3x3 SVD (:mod:`bridges.fast_svd`), the StVK-Hencky stress (:mod:`bridges.hencky`) and
batched 3x3 products (:mod:`bridges.products`); determinants and inverses run in closed form
(:mod:`bridges.closed_form`). Imports ``taichi_mpm`` and ``torch``, never ``tasks`` or
``sga_agent``.
"""
