"""System identification with taichi_mpm: recover a von Mises yield stress from motion.

A synthetic observation (the paper's cube, yield stress 2e3 Pa, 1% position noise) is fitted
from a guess 2.5x off with L-BFGS; progress prints after every iteration.

    python examples/sysid_cube.py              # 1000 steps
    python examples/sysid_cube.py --steps 300  # a shorter run
"""

import argparse

import numpy as np

import taichi_mpm as tm
from taichi_mpm.sysid import Observation, identify

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--steps", type=int, default=1000, help="time steps (default: 1000)")
steps = parser.parse_args().steps

tm.init(precision="float64")

# The observation: 10 frames of every particle, noise of 1% of the body's size (0.5 m).
scene = tm.paper_scene(steps=steps)
truth = tm.Material(tm.StVKHencky(E=5e4, nu=0.3), tm.VonMises(yield_stress=2e3))
frames = np.linspace(steps / 10, steps, 10).round().astype(int)
positions = tm.Simulator(scene, truth).forward(frames)
positions += np.random.default_rng(0).normal(scale=0.01 * 0.5, size=positions.shape)
observation = Observation(scene, positions, frames, np.arange(scene.num_particles))
# From a file instead: taichi_mpm.sysid.load_observation("observed.npz")


def progress(run, iteration, loss, values):
    print(f"run {run} iteration {iteration:2d}: loss {loss:.4e}, "
          f"yield_stress {values['yield_stress']:.1f} Pa")  # fmt: skip


guess = truth.replace(yield_stress=5e3)
result = identify(
    observation, guess, names=["yield_stress"], optimizer="lbfgs", learning_rate=0.5,
    patience=3, callback=progress,  # stop after 3 iterations without progress
)  # fmt: skip
print(result.summary())  # fitted values, relative standard deviations, warnings
