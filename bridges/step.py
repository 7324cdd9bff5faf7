"""One MPM step as a ``torch.autograd.Function``.

:func:`mpm_step` takes the particle state and the Kirchhoff stress as torch tensors,

    (x, v, C, F_corrected, stress) -> (x', v', C', F_trial'),

runs P2G, the grid update and G2P in Taichi, and in backward runs the Taichi gradient kernels
of those phases. The constitutive laws stay outside, in torch, so a law written as an
``nn.Module`` is differentiated by torch and the simulator by Taichi::

    transfer = Transfer(scene)
    F = plastic(F_trial)             # torch
    stress = elastic(F)              # torch
    x, v, C, F_trial = mpm_step(x, v, C, F, stress, transfer)

Only one step's grid lives in Taichi: backward recomputes the step's grid from the saved
inputs before running the reverse kernels, so the memory of a rollout is that of the
particle tensors torch saves (33 numbers per particle and step) plus the laws' own.
"""

from __future__ import annotations

import taichi as ti
import torch

from bridges import kernels
from taichi_mpm import runtime
from taichi_mpm.kernels import transfer as tk
from taichi_mpm.scene import Scene
from taichi_mpm.simulator import PARALLEL_THRESHOLD

_WALL_CODES = {"slip": tk.SLIP, "sticky": tk.STICKY, "separate": tk.SEPARATE}


def torch_dtype() -> torch.dtype:
    """The torch dtype matching the running Taichi precision (taichi_mpm.init)."""
    return torch.float64 if runtime.current().dtype == ti.f64 else torch.float32


class Transfer:
    """Taichi arrays and settings for stepping one scene's particles from torch.

    Parameters
    ----------
    scene : taichi_mpm.Scene
        Grid, time step, walls, particle mass and volume (its initial state is not used).
    parallel : bool, optional
        Parallel loops; default as in :class:`taichi_mpm.Simulator`.
    """

    def __init__(self, scene: Scene, parallel: bool | None = None) -> None:
        info = runtime.current()
        self.scene = scene
        self.dtype = torch_dtype()
        if parallel is None:
            parallel = info.arch != "cpu" or scene.num_particles >= PARALLEL_THRESHOLD
        self._serial = not parallel
        n, N = scene.grid_resolution, scene.num_particles
        vec, mat = ti.types.vector(3, info.dtype), ti.types.matrix(3, 3, info.dtype)
        scalar = info.dtype

        def array(element, shape):
            return ti.ndarray(element, shape=shape, needs_grad=True)

        self.x, self.v = array(vec, (2, N)), array(vec, (2, N))
        self.C, self.F = array(mat, (2, N)), array(mat, (2, N))
        self.F_corrected, self.stress = array(mat, (1, N)), array(mat, (1, N))
        self.grid_mass = array(scalar, (1, n, n, n))
        self.grid_momentum = array(vec, (1, n, n, n))
        self.grid_velocity = array(vec, (1, n, n, n))
        walls = scene.walls
        friction = walls.friction if walls.kind == "separate" else 0.0
        self._transfer_settings = (
            scene.dx, scene.dt, scene.particle_volume, scene.particle_mass, *scene.gravity,
            _WALL_CODES[walls.kind], walls.thickness, friction,
        )  # fmt: skip
        self._grid_settings = (scene.dt, *scene.gravity, _WALL_CODES[walls.kind],
                               walls.thickness, friction)  # fmt: skip

    @property
    def num_particles(self) -> int:
        return self.scene.num_particles

    def _arrays(self):
        return (self.x, self.v, self.C, self.F, self.F_corrected, self.stress, self.grid_mass,
                self.grid_momentum, self.grid_velocity)  # fmt: skip

    def _run_forward(self, x, v, C, F, stress) -> None:
        kernels.load_and_transfer(x, v, C, F, stress, *self._arrays(), *self._transfer_settings,
                                  self._serial)  # fmt: skip

    def forward(self, x, v, C, F, stress):
        """Next (x, v, C, F_trial) from detached contiguous tensors of this Transfer's dtype."""
        self._run_forward(x, v, C, F, stress)
        out = (torch.empty_like(x), torch.empty_like(v), torch.empty_like(C), torch.empty_like(C))
        kernels.store_state(self.x, self.v, self.C, self.F, *out, self._serial)
        return out

    def backward(self, inputs, output_grads):
        """dL/d(x, v, C, F_corrected, stress) of one step from dL/d(x', v', C', F_trial')."""
        self._run_forward(*inputs)
        kernels.seed_output_gradients(
            *output_grads, self.x.grad, self.v.grad, self.C.grad, self.F.grad,
            self.F_corrected.grad, self.stress.grad, self.grid_mass.grad,
            self.grid_momentum.grad, self.grid_velocity.grad, self._serial,
        )  # fmt: skip
        sc = self.scene
        tk.g2p.grad(self.x, self.v, self.C, self.F, self.F_corrected, self.grid_velocity, 0,
                    sc.dx, sc.dt, self._serial)  # fmt: skip
        tk.grid_update.grad(self.grid_mass, self.grid_momentum, 0, self.grid_velocity,
                            *self._grid_settings, self._serial)  # fmt: skip
        tk.p2g.grad(self.x, self.v, self.C, self.stress, 0, self.grid_mass, self.grid_momentum,
                    sc.dx, sc.dt, sc.particle_volume, sc.particle_mass, self._serial)  # fmt: skip
        grads = tuple(torch.empty_like(t) for t in inputs)
        kernels.store_input_gradients(
            self.x.grad, self.v.grad, self.C.grad, self.F_corrected.grad, self.stress.grad,
            *grads, self._serial,
        )  # fmt: skip
        return grads

    def prepare(self, tensor: torch.Tensor, name: str, shape: tuple[int, ...]) -> torch.Tensor:
        """``tensor`` detached, contiguous and of this Transfer's dtype; checks its shape."""
        if tuple(tensor.shape) != shape:
            raise ValueError(f"{name} must have shape {shape}, got {tuple(tensor.shape)}")
        return tensor.detach().to(self.dtype).contiguous()


class _MPMStep(torch.autograd.Function):
    @staticmethod
    def forward(ctx, x, v, C, F, stress, transfer: Transfer):
        N = transfer.num_particles
        inputs = tuple(
            transfer.prepare(t, name, shape)
            for t, name, shape in zip(
                (x, v, C, F, stress),
                ("x", "v", "C", "F", "stress"),
                ((N, 3), (N, 3), (N, 3, 3), (N, 3, 3), (N, 3, 3)),
                strict=True,
            )
        )
        ctx.transfer = transfer
        ctx.save_for_backward(*inputs)
        return transfer.forward(*inputs)

    @staticmethod
    def backward(ctx, *output_grads):
        inputs = ctx.saved_tensors
        grads = tuple(
            torch.zeros_like(like) if g is None else g.detach().to(like.dtype).contiguous()
            for g, like in zip(output_grads, (inputs[0], inputs[1], inputs[2], inputs[2]),
                               strict=True)  # fmt: skip
        )
        return (*ctx.transfer.backward(inputs, grads), None)


def mpm_step(x, v, C, F, stress, transfer: Transfer):
    """One differentiable MPM step; see the module docstring.

    Parameters
    ----------
    x, v : (N, 3) tensors
        Positions and velocities.
    C : (N, 3, 3) tensor
        APIC affine velocity.
    F : (N, 3, 3) tensor
        Deformation gradient after the plastic law (F_corrected).
    stress : (N, 3, 3) tensor
        Kirchhoff stress from the elastic law.
    transfer : Transfer
        The scene's Taichi arrays.

    Returns
    -------
    x, v, C, F_trial of the next step.
    """
    return _MPMStep.apply(x, v, C, F, stress, transfer)
