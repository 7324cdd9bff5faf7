"""The differentiable simulator: forward stepping, checkpoints and reverse-mode gradients.

Usage (a tape in three verbs)::

    sim = Simulator(scene, material)
    positions = sim.forward(frames)          # record: (len(frames), N, 3)
    grads = sim.backward(dloss_dpositions)   # same shape as positions
    grads.material["E"], grads.positions, grads.velocities

Memory does not grow with steps x particles: the forward pass keeps only the state at
the start of every segment of ``checkpoint_every`` steps; the backward pass re-runs one
segment at a time, storing its steps, and walks it backwards with Taichi's autodiff.

The kernels read a model and advance a state (:mod:`taichi_mpm.kernels.arguments`): the
model is the scene's step constants and the material's pack, made when the simulator or its
material is set; the state is the recorded segment's particle arrays, its grids and the SVD
records of its constitutive updates.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np
import taichi as ti

from taichi_mpm import runtime
from taichi_mpm.kernels import arguments, constitutive, slots
from taichi_mpm.kernels.arguments import CARRIED, Grid, Records, State
from taichi_mpm.kernels.step import step_kernels
from taichi_mpm.kernels.transfer import phase_kernels
from taichi_mpm.materials import (
    PARAMETER_INDEX,
    DruckerPrager,
    FixedCorotated,
    LinearElastic,
    Material,
    PlasticMixture,
    StVKHencky,
    VonMises,
    WeaklyCompressibleFluid,
)
from taichi_mpm.scene import Scene

#: Default memory for one recorded segment; sets ``checkpoint_every`` when not given.
SEGMENT_BUDGET_BYTES = 32 * 2**20
#: Scenes with at least this many particles use parallel loops (launch overhead dominates below).
PARALLEL_THRESHOLD = 20_000


@dataclass
class Gradients:
    """Gradient of the loss seeded in :meth:`Simulator.backward`."""

    material: dict[str, float]
    positions: np.ndarray  # dL/dx at step 0, (N, 3)
    velocities: np.ndarray  # dL/dv at step 0, (N, 3)


class Simulator:
    """Differentiable 3D MLS-MPM simulation of one scene and one material.

    Parameters
    ----------
    scene : Scene
        Particles, grid, time step, walls.
    material : Material
        Constitutive law; change it between runs with :attr:`material`.
    checkpoint_every : int, optional
        Steps per recorded segment. Default: as many as fit in 32 MiB, or more where
        that lowers the total memory (checkpoints plus one segment).
        ``checkpoint_every=scene.steps`` records the whole trajectory in the forward pass,
        so the backward pass re-runs nothing.
    parallel : bool, optional
        Parallel loops. Default: on GPUs always, on the CPU from 20k particles (below
        that a parallel launch costs more than the work).
    """

    def __init__(
        self,
        scene: Scene,
        material: Material,
        checkpoint_every: int | None = None,
        parallel: bool | None = None,
    ) -> None:
        info = runtime.current()
        self.scene = scene
        self._dtype = info.dtype
        if parallel is None:  # GPUs always run parallel loops
            parallel = info.arch != "cpu" or scene.num_particles >= PARALLEL_THRESHOLD
        self._serial = not parallel
        self.segment = self._segment_length(checkpoint_every)
        self.num_segments = -(-scene.steps // self.segment)
        self._allocate()  # the state: particle arrays, grids, SVD records
        # the model: the scene's step constants here, the material's pack with the material
        self._constants = arguments.step_constants(scene)
        self._step_kernels = step_kernels(self._dtype)
        self._phase_kernels = phase_kernels(self._dtype)
        self._frames: np.ndarray | None = None
        #: Full states kept by the last forward(state_frames=...): x, v, C, F (trial).
        self.states: dict[str, np.ndarray] = {}
        self.material = material

    # ------------------------------------------------------------------ set-up

    def _segment_length(self, requested: int | None) -> int:
        steps = self.scene.steps
        if requested is not None:
            if requested < 1:
                raise ValueError(f"checkpoint_every={requested} must be >= 1")
            return min(requested, steps)
        # Memory is steps/k checkpoints plus k recorded steps: k = sqrt(steps * ckpt / step)
        # minimises it; longer segments (fewer launches) are used while they fit the budget.
        per_step, per_checkpoint = self.bytes_per_step(), self.bytes_per_checkpoint()
        balanced = int(np.sqrt(steps * per_checkpoint / per_step))
        return int(np.clip(max(SEGMENT_BUDGET_BYTES // per_step, balanced), 1, steps))

    def bytes_per_checkpoint(self) -> int:
        """Memory of one stored state (x, v, C, F)."""
        values = sum(int(np.prod(shape)) for shape in CARRIED.values())
        return (8 if self._dtype == ti.f64 else 4) * values * self.scene.num_particles

    def bytes_per_step(self) -> int:
        """Memory one recorded step takes (values, gradients and SVD factors)."""
        size = 8 if self._dtype == ti.f64 else 4
        particle = (3 + 3 + 9 + 9 + 9 + 9) * 2 + 9 * 4 + 6 * 3
        grid = (1 + 3 + 3) * 2
        return size * (particle * self.scene.num_particles + grid * self.scene.grid_resolution**3)

    def _allocate(self) -> None:
        n, N, k = self.scene.grid_resolution, self.scene.num_particles, self.segment
        dt = self._dtype
        vec, mat = ti.types.vector(3, dt), ti.types.matrix(3, 3, dt)

        def array(element, shape, grad=True):
            return ti.ndarray(element, shape=shape, needs_grad=grad)

        def carried(shape, grad=True):  # an array of `shape` per field of CARRIED
            return {name: array(vec if len(field) == 1 else mat, shape, grad)
                    for name, field in CARRIED.items()}  # fmt: skip

        #: the recorded segment: slot s holds step start + s
        self.state = State(**carried((k + 1, N)), F_corrected=array(mat, (k, N)),
                           stress=array(mat, (k, N)))  # fmt: skip
        self.grid = Grid(mass=array(dt, (k, n**3)), momentum=array(vec, (k, n**3)),
                         velocity=array(vec, (k, n**3)))  # fmt: skip
        coeff = ti.types.matrix(3, 2, dt)
        self.records = Records(  # constants to the reverse pass: no gradients
            trial_U=array(mat, (k, N), False),
            trial_V=array(mat, (k, N), False),
            elastic_U=array(mat, (k, N), False),
            elastic_V=array(mat, (k, N), False),
            coeff_von_mises=array(coeff, (k, N), False),
            coeff_sand=array(coeff, (k, N), False),
            coeff_elastic=array(coeff, (k, N), False),
        )
        self.params = array(dt, (len(PARAMETER_INDEX),))
        self._carried = {name: self.state[name] for name in CARRIED}
        self._checkpoints = carried((self.num_segments, N), False)
        self._carry = carried((1, N), False)  # across segment boundaries: a state, its grad
        self._seed = array(vec, (N,), False)

    @property
    def material(self) -> Material:
        return self._material

    @material.setter
    def material(self, material: Material) -> None:
        if not isinstance(material, Material):
            raise TypeError(
                f"material must be a taichi_mpm.Material, got {type(material).__name__}"
            )
        self._material = material
        self._frames = None  # a recorded trajectory belongs to the old material
        self._recorded_segment: int | None = None
        self._phases = self._constitutive_phases(material)
        self.params.from_numpy(material.parameter_array().astype(self._numpy_dtype))
        self._material_pack = arguments.material(
            self.params, material.elastic_kind, self._share_basis
        )

    def _constitutive_phases(self, material: Material) -> list[tuple[object, Callable]]:
        """(kernel, args(slot)) of the plastic then the elastic law, differentiated in reverse.

        Also sets ``self._share_basis``: a single SVD-based plastic law (or none) leaves
        F_corrected = U diag(S') V^T, and an SVD-based elastic law then reuses that SVD.
        """
        C = constitutive
        serial = self._serial
        F, Fc, stress = self.state.F, self.state.F_corrected, self.state.stress
        params, records = self.params, self.records
        plastic = material.plastic
        components = (
            plastic.components if isinstance(plastic, PlasticMixture) else ((1.0, plastic),)
        )
        spectral_elastic = isinstance(material.elastic, FixedCorotated | StVKHencky)
        single = len(components) == 1 and not isinstance(components[0][1], WeaklyCompressibleFluid)
        self._share_basis = spectral_elastic and single
        trial_U, trial_V = records.trial_U, records.trial_V
        phases: list[tuple[object, Callable]] = []
        for _, law in components:
            if isinstance(law, VonMises | DruckerPrager):
                von_mises = isinstance(law, VonMises)
                kernel = C.plastic_von_mises if von_mises else C.plastic_sand
                coeff = records.coeff_von_mises if von_mises else records.coeff_sand
                phases.append(
                    (kernel, lambda s, c=coeff: (F, s, trial_U, trial_V, c, params, Fc, serial))
                )
            else:
                kernel = (
                    C.plastic_fluid
                    if isinstance(law, WeaklyCompressibleFluid)
                    else C.plastic_identity
                )
                phases.append((kernel, lambda s: (F, s, params, Fc, serial)))
        if spectral_elastic:
            kernel = (
                C.stress_corotated
                if isinstance(material.elastic, FixedCorotated)
                else C.stress_stvk_hencky
            )
            U, V = (
                (trial_U, trial_V) if self._share_basis else (records.elastic_U, records.elastic_V)
            )
            coeff = records.coeff_elastic
            phases.append((kernel, lambda s: (Fc, s, U, V, coeff, params, stress, serial)))
        else:
            kernel = (
                C.stress_linear
                if isinstance(material.elastic, LinearElastic)
                else C.stress_neo_hookean
            )
            phases.append((kernel, lambda s: (Fc, s, params, stress, serial)))
        return phases

    @property
    def _numpy_dtype(self):
        return np.float64 if self._dtype == ti.f64 else np.float32

    # ------------------------------------------------------------------ one step

    def _advance(self, steps: int) -> None:
        """Run slots 0 .. steps - 1 forward, recording every value the reverse pass reads."""
        groups = (self.state, self.grid, self.records, self._material_pack, self._constants)
        if self._serial:
            self._step_kernels.advance(*groups, 0, steps)
        else:
            for s in range(steps):
                self._step_kernels.step_parallel(*groups, s)

    def _substep_grad(self, s: int) -> None:
        """Reverse of step s: the phases' gradient kernels in reverse order."""
        state, grid, constants, serial = self.state, self.grid, self._constants, self._serial
        phases = self._phase_kernels
        phases.g2p.grad(state.x, state.v, state.C, state.F, state.F_corrected, grid.velocity, s,
                        constants, serial)  # fmt: skip
        phases.grid_update.grad(grid.mass, grid.momentum, grid.velocity, s, constants, serial)
        phases.p2g.grad(state.x, state.v, state.C, state.stress, grid.mass, grid.momentum, s,
                        constants, serial)  # fmt: skip
        for kernel, args in reversed(self._phases):
            kernel.grad(*args(s))

    # ------------------------------------------------------------------ segments

    def _segment_steps(self, segment: int) -> int:
        return min(self.segment, self.scene.steps - segment * self.segment)

    def _load_initial_state(self) -> None:
        sc, N, np_dtype = self.scene, self.scene.num_particles, self._numpy_dtype
        initial = {
            "x": sc.positions,
            "v": sc.velocities,
            "C": np.zeros((N, 3, 3)),
            "F": np.broadcast_to(np.eye(3), (N, 3, 3)),
        }
        for name, carry in self._carry.items():
            carry.from_numpy(np.ascontiguousarray(initial[name], dtype=np_dtype)[None])
            slots.copy_slot(carry, 0, self._carried[name], 0)

    def _store_checkpoint(self, segment: int) -> None:
        for name, array in self._carried.items():
            slots.copy_slot(array, 0, self._checkpoints[name], segment)

    def _restore_checkpoint(self, segment: int) -> None:
        for name, array in self._carried.items():
            slots.copy_slot(self._checkpoints[name], segment, array, 0)

    def _shift_last_to_first(self, steps: int) -> None:
        for array in self._carried.values():
            slots.copy_slot(array, steps, array, 0)

    # ------------------------------------------------------------------ public API

    def forward(
        self, frames: Iterable[int] | None = None, state_frames: Iterable[int] | None = None
    ) -> np.ndarray:
        """Run all steps from the scene's initial state.

        Parameters
        ----------
        frames : iterable of int, optional
            Steps (0..scene.steps) whose particle positions are returned; default every step.
        state_frames : iterable of int, optional
            Steps whose full particle state (x, v, C and the trial F) is kept in
            :attr:`states` (for example to restart or teacher-force another simulation).

        Returns
        -------
        (len(frames), N, 3) float64 array of positions.
        """
        frames = self._check_frames(frames)
        wanted_states = self._check_frames([] if state_frames is None else state_frames, True)
        self._load_initial_state()
        N = self.scene.num_particles
        positions = np.empty((len(frames), N, 3))
        self.states = {
            name: np.empty((len(wanted_states), N, *shape)) for name, shape in CARRIED.items()
        }
        for segment in range(self.num_segments):
            start, steps = segment * self.segment, self._segment_steps(segment)
            if segment > 0:
                self._shift_last_to_first(self.segment)
            self._store_checkpoint(segment)
            self._advance(steps)
            wanted = np.nonzero((frames >= start) & (frames <= start + steps))[0]
            if len(wanted):
                recorded = self.state.x.to_numpy()
                positions[wanted] = recorded[frames[wanted] - start]
            kept = np.nonzero((wanted_states >= start) & (wanted_states <= start + steps))[0]
            if len(kept):
                for name, array in self._carried.items():
                    self.states[name][kept] = array.to_numpy()[wanted_states[kept] - start]
        # The last segment stays recorded: backward starts there without re-running it.
        self._recorded_segment = self.num_segments - 1
        self._frames = frames
        return positions

    def final_state(self) -> dict[str, np.ndarray]:
        """x, v, C, F after the last :meth:`forward` call."""
        if self._frames is None:
            raise RuntimeError("call forward() before final_state()")
        last = self._segment_steps(self.num_segments - 1)
        return {name: array.to_numpy()[last] for name, array in self._carried.items()}

    def backward(self, position_grads: np.ndarray) -> Gradients:
        """Reverse pass for a loss on the positions returned by the last :meth:`forward`.

        Parameters
        ----------
        position_grads : (len(frames), N, 3) array
            dL/dpositions, the gradient of a scalar loss with respect to the recorded frames.
        """
        if self._frames is None:
            raise RuntimeError("call forward(frames) before backward(...)")
        frames = self._frames
        expected = (len(frames), self.scene.num_particles, 3)
        position_grads = np.asarray(position_grads, dtype=np.float64)
        if position_grads.shape != expected:
            raise ValueError(
                f"position_grads must have the shape of the recorded positions {expected}, "
                f"got {position_grads.shape}"
            )
        self.params.grad.fill(0)
        for segment in reversed(range(self.num_segments)):
            start, steps = segment * self.segment, self._segment_steps(segment)
            if self._recorded_segment != segment:
                self._restore_checkpoint(segment)
                self._advance(steps)
                self._recorded_segment = segment
            self._zero_grads()
            if segment < self.num_segments - 1:
                for name, array in self._carried.items():
                    slots.copy_slot(self._carry[name], 0, array.grad, steps)
            low = start if segment == 0 else start + 1
            for index in np.nonzero((frames >= low) & (frames <= start + steps))[0]:
                self._seed.from_numpy(position_grads[index].astype(self._numpy_dtype))
                slots.add_to_slot(self.state.x.grad, int(frames[index] - start), self._seed)
            for s in reversed(range(steps)):
                self._substep_grad(s)
            for name, array in self._carried.items():
                slots.copy_slot(array.grad, 0, self._carry[name], 0)
        return self._collect_gradients()

    def _zero_grads(self) -> None:
        for _, array in (*self.state.items, *self.grid.items):
            slots.clear(array.grad)

    def _collect_gradients(self) -> Gradients:
        param_grad = self.params.grad.to_numpy()
        names = self._material.parameters()
        return Gradients(
            material={name: float(param_grad[PARAMETER_INDEX[name]]) for name in names},
            positions=self._carry["x"].to_numpy()[0].astype(np.float64),
            velocities=self._carry["v"].to_numpy()[0].astype(np.float64),
        )

    def _check_frames(self, frames: Iterable[int] | None, may_be_empty: bool = False) -> np.ndarray:
        steps = self.scene.steps
        if frames is None:
            return np.arange(steps + 1)
        frames = np.asarray(list(frames), dtype=np.int64)
        if may_be_empty and frames.size == 0:
            return frames
        if frames.ndim != 1 or len(frames) == 0:
            raise ValueError("frames must be a non-empty sequence of step indices")
        if frames.min() < 0 or frames.max() > steps:
            raise ValueError(f"frames must lie in [0, {steps}] (scene.steps)")
        return frames
