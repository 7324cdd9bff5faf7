"""A constitutive law written in PyTorch inside taichi_mpm, with gradients to its parameters.

The observation comes from taichi_mpm's built-in von Mises plasticine; the torch twin of that
law starts with its yield stress off, and one teacher-forced rollout gives the loss and
dloss/dyield_stress.

    python examples/bridges_rollout.py              # 300 steps, a reset every 100
    python examples/bridges_rollout.py --steps 100  # one segment
"""

import argparse

import taichi_mpm as tm
from bridges.laws import StVKHencky, VonMises
from bridges.rollout import Rollout, trajectory_loss

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--steps", type=int, default=300, help="time steps (default: 300)")
steps = parser.parse_args().steps

tm.init(precision="float32")
scene = tm.paper_scene(steps=steps)
sim = tm.Simulator(scene, tm.Material(tm.StVKHencky(1e6, 0.2), tm.VonMises(3e4)))
resets = list(range(0, steps, 100))  # teacher forcing: restart from the observation here
observed = sim.forward(state_frames=resets)  # every step's positions, full states at resets

# Any nn.Module works as a law; here the torch twin of von Mises, its yield stress off.
plastic = VonMises(E=1e6, nu=0.2, yield_stress=2e4)
elastic = StVKHencky(E=1e6, nu=0.2).requires_grad_(False)
result = trajectory_loss(Rollout(scene, plastic, elastic), observed, resets=sim.states)
print(f"loss {result.loss:.4e}")
print(f"dloss/dyield_stress {plastic.yield_stress.grad.item():+.4e}")  # < 0: raise it
