"""Simulate the SGA paper's scene with taichi_mpm and take gradients through it.

python examples/simulate_cube.py              # the paper scene: 1000 steps
python examples/simulate_cube.py --steps 200  # a shorter run
"""

import argparse

import numpy as np

import taichi_mpm as tm

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--steps", type=int, default=1000, help="time steps (default: 1000)")
steps = parser.parse_args().steps

tm.init(arch="cpu", precision="float32")  # "cuda"/"vulkan"; "float64" for gradient checks

scene = tm.paper_scene(steps=steps)  # 1000-particle cube, 20^3 grid, dt = 5e-4 s
material = tm.Material(tm.StVKHencky(E=1e5, nu=0.2), tm.VonMises(yield_stress=3e3))
sim = tm.Simulator(scene, material)

frames = np.linspace(0, steps, 5).astype(int)  # steps at which positions are kept
positions = sim.forward(frames)  # (5, 1000, 3)
print(f"positions {positions.shape}, centre of mass at the end {positions[-1].mean(0).round(3)}")

# A softer material's motion stands in for an observation.
softer = material.replace(yield_stress=2e3)
target = tm.Simulator(scene, softer).forward(frames)

# The gradient of any scalar loss on the kept positions: seed dL/dpositions, go back.
loss = float(((positions - target) ** 2).mean())
grads = sim.backward(2 * (positions - target) / positions.size)
print(f"loss {loss:.3e}")
for name, value in grads.material.items():  # E, nu, yield_stress
    print(f"dloss/d{name} = {value:+.3e}")
print(f"dloss/dx0 {grads.positions.shape}, dloss/dv0 {grads.velocities.shape}")

sim.material = softer  # new parameter values: nothing is recompiled
