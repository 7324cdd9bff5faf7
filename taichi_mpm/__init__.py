"""taichi_mpm: a standalone differentiable 3D MLS-MPM simulator in Taichi.

Imports taichi and numpy only. Call :func:`init` once, build a :class:`Scene` and a
:class:`Material`, then run a :class:`Simulator` forward and, for gradients, backward.
"""

from taichi_mpm import _banner  # noqa: F401 (before Taichi is imported)
from taichi_mpm.materials import (
    PARAMETER_NAMES,
    DruckerPrager,
    FixedCorotated,
    LinearElastic,
    Material,
    MaterialError,
    NeoHookean,
    NoPlasticity,
    PlasticMixture,
    StVKHencky,
    VonMises,
    WeaklyCompressibleFluid,
)
from taichi_mpm.runtime import init
from taichi_mpm.scene import (
    Scene,
    SceneError,
    Walls,
    cube,
    paper_scene,
    rigid_velocity,
    rigid_velocity_fit,
    rigid_velocity_gradient,
    sphere,
)
from taichi_mpm.scene_file import load_scene, save_scene
from taichi_mpm.simulator import Gradients, Simulator
from taichi_mpm.warmup import warm_up

__all__ = [
    "PARAMETER_NAMES",
    "DruckerPrager",
    "FixedCorotated",
    "Gradients",
    "LinearElastic",
    "Material",
    "MaterialError",
    "NeoHookean",
    "NoPlasticity",
    "PlasticMixture",
    "Scene",
    "SceneError",
    "Simulator",
    "StVKHencky",
    "VonMises",
    "Walls",
    "WeaklyCompressibleFluid",
    "cube",
    "init",
    "paper_scene",
    "load_scene",
    "save_scene",
    "rigid_velocity",
    "rigid_velocity_fit",
    "rigid_velocity_gradient",
    "sphere",
    "warm_up",
]
