"""bridges.laws: the torch laws equal taichi_mpm's built-in ones, and their gradients are exact."""

import numpy as np
import pytest
import taichi as ti
import torch

import taichi_mpm as tm
from bridges import laws
from taichi_mpm.kernels import arguments
from taichi_mpm.kernels.arguments import Records, model_types
from taichi_mpm.kernels.constitutive import constitutive_update

E, NU = 1000.0, 0.3  # mu = 385: von Mises yields beyond a deviatoric Hencky strain of 0.065
YIELD_STRESS, FRICTION_ANGLE, COHESION = 50.0, 30.0, 0.02


def deformations(seed: int = 0) -> np.ndarray:
    """Trial deformation gradients in every regime of the plastic laws, some inverted."""
    rng = np.random.default_rng(seed)

    def around(scale: float, noise: float, n: int) -> np.ndarray:
        return scale * np.eye(3) + noise * rng.standard_normal((n, 3, 3))

    inverted = around(1.0, 0.3, 6) @ np.diag([1.0, 1.0, -1.0])
    return np.concatenate(
        [
            around(1.0, 0.02, 12),  # elastic for von Mises
            around(0.9, 0.03, 12),  # compressed inside the Drucker-Prager cone
            around(1.0, 0.3, 16),  # yielding
            around(1.15, 0.05, 8),  # expanded: Drucker-Prager apex
            inverted,
        ]
    )


MIXTURE = tm.PlasticMixture(
    [
        (0.5, tm.VonMises(YIELD_STRESS)),
        (0.3, tm.DruckerPrager(FRICTION_ANGLE, COHESION)),
        (0.2, tm.WeaklyCompressibleFluid()),
    ]
)
MATERIALS = {
    "linear": tm.Material(tm.LinearElastic(E, NU)),
    "neo-Hookean": tm.Material(tm.NeoHookean(E, NU), tm.WeaklyCompressibleFluid()),
    "corotated + von Mises": tm.Material(tm.FixedCorotated(E, NU), tm.VonMises(YIELD_STRESS)),
    "Hencky + sand": tm.Material(tm.StVKHencky(E, NU), tm.DruckerPrager(FRICTION_ANGLE, COHESION)),
    "corotated + mixture": tm.Material(tm.FixedCorotated(E, NU), MIXTURE),
    "Hencky + mixture": tm.Material(
        tm.StVKHencky(E, NU),
        tm.PlasticMixture([(0.6, tm.NoPlasticity()), (0.4, tm.VonMises(YIELD_STRESS))]),
    ),
}


@ti.kernel
def _constitutive(F: ti.types.ndarray(), F_corrected: ti.types.ndarray(),
                  stress: ti.types.ndarray(), records: Records,
                  material: model_types(ti.f64).material):  # fmt: skip
    for p in range(F.shape[1]):
        constitutive_update(F, F_corrected, stress, records, material, 0, p)


def taichi_laws(material: tm.Material, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(F_corrected, Kirchhoff stress) of taichi_mpm's forward constitutive update."""
    mat, coeff = ti.types.matrix(3, 3, ti.f64), ti.types.matrix(3, 2, ti.f64)
    shape = (1, len(F))
    F_trial, F_corrected, stress = (ti.ndarray(mat, shape) for _ in range(3))
    F_trial.from_numpy(F[None])
    params = ti.ndarray(ti.f64, (len(tm.PARAMETER_NAMES),))
    params.from_numpy(material.parameter_array())
    records = Records(**{name: ti.ndarray(coeff if name.startswith("coeff") else mat, shape)
                         for name in Records.members})  # fmt: skip
    plastic = material.plastic
    components = plastic.components if isinstance(plastic, tm.PlasticMixture) else [(1, plastic)]
    single = len(components) == 1 and not isinstance(plastic, tm.WeaklyCompressibleFluid)
    share_basis = material.elastic.needs_svd and single
    _constitutive(F_trial, F_corrected, stress, records,
                  arguments.material(params, material.elastic_kind, share_basis))  # fmt: skip
    return F_corrected.to_numpy()[0], stress.to_numpy()[0]


@pytest.mark.slow
@pytest.mark.parametrize("material", MATERIALS.values(), ids=MATERIALS.keys())
def test_torch_laws_equal_taichi_laws(material):
    F = deformations()
    expected_F, expected_tau = taichi_laws(material, F)
    plastic, elastic = laws.from_material(material, dtype=torch.float64)
    with torch.no_grad():
        F_corrected = plastic(torch.from_numpy(F))
        tau = elastic(F_corrected)
    for ours, theirs in ((F_corrected, expected_F), (tau, expected_tau)):
        np.testing.assert_allclose(ours.numpy(), theirs, rtol=0, atol=1e-10 * np.abs(theirs).max())


def test_deformations_cover_every_regime():
    F = torch.from_numpy(deformations())
    with torch.no_grad():
        von_mises = laws.VonMises(E, NU, YIELD_STRESS)(F)
        sand = laws.DruckerPrager(E, NU, FRICTION_ANGLE, COHESION)(F)
    yielded = (von_mises - F).abs().amax((1, 2)) > 1e-9
    assert yielded.any() and not yielded.all()
    unchanged = (sand - F).abs().amax((1, 2)) < 1e-9
    apex = torch.isclose(torch.linalg.det(sand), torch.tensor(np.exp(COHESION), dtype=F.dtype))
    assert unchanged.any() and apex.any() and not (unchanged | apex).all()
    assert (torch.linalg.det(F) < 0).any()


# ----------------------------------------------------------------------------- gradients


F64 = {"dtype": torch.float64}
TORCH_LAWS = {
    "linear": laws.LinearElastic(E, NU, **F64),
    "corotated": laws.FixedCorotated(E, NU, **F64),
    "neo-Hookean": laws.NeoHookean(E, NU, **F64),
    "Hencky": laws.StVKHencky(E, NU, **F64),
    "identity": laws.NoPlasticity(**F64),
    "von Mises": laws.VonMises(E, NU, YIELD_STRESS, **F64),
    "sand": laws.DruckerPrager(E, NU, FRICTION_ANGLE, COHESION, **F64),
    "fluid": laws.WeaklyCompressibleFluid(**F64),
    "mixture": laws.from_material(tm.Material(tm.LinearElastic(E, NU), MIXTURE), **F64)[0],
}


@pytest.mark.slow
@pytest.mark.parametrize("law", TORCH_LAWS.values(), ids=TORCH_LAWS.keys())
def test_gradients_match_central_differences(law):
    parameters = dict(law.named_parameters())
    # one matrix per regime: elastic, compressed, yielding, expanded, inverted
    F = torch.from_numpy(deformations(seed=1)[[0, 12, 30, 44, 50]]).requires_grad_(True)

    def evaluate(F, *values):
        return torch.func.functional_call(law, dict(zip(parameters, values, strict=True)), (F,))

    inputs = (F, *(value.detach().clone().requires_grad_(True) for value in parameters.values()))
    assert torch.autograd.gradcheck(evaluate, inputs)


def test_parameters_and_their_gradients():
    material = tm.Material(tm.StVKHencky(E, NU), MIXTURE)
    plastic, elastic = laws.from_material(material, dtype=torch.float32)
    assert {p.dtype for p in plastic.parameters()} == {torch.float32}
    names = {name.rsplit(".", 1)[-1] for name, _ in plastic.named_parameters()}
    assert names | {"E", "nu"} == set(material.parameters())
    plastic.double()
    elastic.double()
    F = torch.from_numpy(deformations()[:8])
    elastic(plastic(F)).sum().backward()
    gradients = laws.parameter_gradients(plastic, elastic, elastic)  # a repeat counts once
    assert set(gradients) == set(material.parameters())
    E_grads = [p.grad for name, p in plastic.named_parameters() if name.endswith(".E")]
    assert len(E_grads) == 2
    assert gradients["E"] == pytest.approx(float(sum(E_grads) + elastic.E.grad), rel=1e-12)
