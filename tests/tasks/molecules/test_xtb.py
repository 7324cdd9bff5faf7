"""GFN1-xTB through dxtb: smooth frontier orbitals and their gradients."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from tasks.molecules.xtb import (
    BOHR_PER_ANGSTROM,
    DTYPE,
    ORBITAL_TEMPERATURE,
    GFN1Model,
    XtbError,
    frontier_orbitals,
)
from tests.tasks.molecules.helpers import conformer


def _frontier(model: GFN1Model, positions: torch.Tensor) -> torch.Tensor:
    point = model(positions)
    return torch.stack([point.homo, point.lumo, point.gap])


@pytest.mark.parametrize("smiles", ["c1ccccc1", "O=C1C=CC(=O)C=C1", "OCc1ccncc1F"])
def test_gradients_match_central_differences(smiles: str) -> None:
    numbers, positions, _ = conformer(smiles)
    model = GFN1Model(numbers.tolist())
    x0 = torch.tensor(positions * BOHR_PER_ANGSTROM, dtype=DTYPE)
    x = x0.clone().requires_grad_(True)
    values = _frontier(model, x)
    grads = [torch.autograd.grad(v, x, retain_graph=True)[0] for v in values]
    rng = np.random.default_rng(0)
    h = 1e-4
    for flat in rng.choice(x0.numel(), size=5, replace=False):
        i, k = divmod(int(flat), 3)
        plus, minus = x0.clone(), x0.clone()
        plus[i, k] += h
        minus[i, k] -= h
        with torch.no_grad():
            numeric = (_frontier(model, plus) - _frontier(model, minus)) / (2 * h)
        analytic = torch.stack([g[i, k] for g in grads])
        assert torch.allclose(analytic, numeric, rtol=1e-3, atol=2e-6), (smiles, i, k)


def test_benzene_degenerate_homo_is_smooth() -> None:
    """Benzene's HOMO pair is degenerate: the smooth HOMO sits T ln 2 above it, and its gradient
    is symmetric under the molecule's six-fold symmetry (equal force magnitude on every C)."""
    numbers, positions, _ = conformer("c1ccccc1")
    model = GFN1Model(numbers.tolist())
    x = torch.tensor(positions * BOHR_PER_ANGSTROM, dtype=DTYPE, requires_grad=True)
    point = model(x)
    (grad,) = torch.autograd.grad(point.homo, x)
    carbon = grad[:6].norm(dim=1)
    assert torch.allclose(carbon, carbon.mean().expand(6), rtol=1e-3)
    # Plain eigenvalues: two equal highest occupied orbitals.
    emo = model._calc.singlepoint(x.detach()).emo.detach()
    top = torch.sort(emo[:15]).values[-2:]
    assert abs(float(top[1] - top[0])) < 1e-6
    expected = float(top.max()) + ORBITAL_TEMPERATURE * np.log(2)
    assert float(point.homo.detach()) == pytest.approx(expected, abs=1e-6)


def test_batched_frontier_orbitals_match_single_molecules() -> None:
    import dxtb
    from tad_mctc.batch import pack

    from tasks.molecules.xtb import calculator_options, gfn1_parameters

    molecules = [conformer(s)[:2] for s in ("CCO", "c1ccccc1O", "CC(=O)N")]
    numbers = pack([torch.tensor(z) for z, _ in molecules])
    positions = pack([torch.tensor(x * BOHR_PER_ANGSTROM, dtype=DTYPE) for _, x in molecules])
    calc = dxtb.Calculator(
        numbers, gfn1_parameters(), opts=calculator_options(batch_mode=1), dtype=DTYPE
    )
    with torch.no_grad():
        result = calc.singlepoint(positions, chrg=torch.zeros(3, dtype=DTYPE))
    n_occ = torch.round(result.occupation.sum(dim=(-2, -1)) / 2).long()
    homo, lumo = frontier_orbitals(result.emo, n_occ, calc.ihelp.orbitals_per_shell.sum(-1))
    for b, (z, x) in enumerate(molecules):
        with torch.no_grad():
            single = GFN1Model(z.tolist())(torch.tensor(x * BOHR_PER_ANGSTROM, dtype=DTYPE))
        assert float(homo[b]) == pytest.approx(float(single.homo), abs=1e-8)
        assert float(lumo[b]) == pytest.approx(float(single.lumo), abs=1e-8)


def test_unsupported_element_is_refused() -> None:
    with pytest.raises(XtbError):
        GFN1Model([6, 118])
