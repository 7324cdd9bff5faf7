"""Torch autograd bridge to :mod:`taichi_mpm`.

This package wraps the differentiable Taichi MPM simulator in ``torch.autograd.Function``
objects so that simulation rollouts can sit inside a PyTorch computation graph: forward passes
run the Taichi kernels, backward passes run Taichi's reverse-mode kernels and hand the gradients
back to torch. It imports both ``taichi_mpm`` and ``torch``. It is being built; nothing is
exported yet.
"""
