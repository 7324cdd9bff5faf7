"""Differentiable GFN1-xTB frontier-orbital energies and total energy through dxtb.

Everything is float64 on the CPU. The SCF runs in dxtb's "full" mode (autograd through the
unrolled SCF iterations): its orbital-energy gradients match finite differences, which the
implicit mode's did not. HOMO and LUMO are smooth extrema of the occupied and virtual orbital
energies (a log-sum-exp at a small temperature) so that their derivatives stay correct when the
frontier orbitals are degenerate (benzene's e1g pair, for instance), where the derivative of
"the orbital at index nocc - 1" is not defined.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import torch

BOHR_PER_ANGSTROM = 1.0 / 0.529177210903
HARTREE_IN_EV = 27.211386245988
HARTREE_IN_KCAL_MOL = 627.5094740631

ORBITAL_TEMPERATURE = 5e-4
"""Temperature (Hartree) of the smooth max/min over orbital energies. A two-fold degenerate HOMO
comes out ``T ln 2`` = 0.35 mHa (0.01 QM9 standard deviations) above the orbital energy; the
QM9 calibration is fitted on the same smooth values."""

MAX_ELEMENT = 86
"""GFN1-xTB is parametrized for H to Rn."""

DTYPE = torch.float64


class XtbError(RuntimeError):
    """The xTB calculation failed (no SCF convergence, non-finite result)."""


@dataclass
class XtbPoint:
    """One single point: total energy and smooth frontier-orbital energies (Hartree, tensors)."""

    energy: torch.Tensor
    homo: torch.Tensor
    lumo: torch.Tensor
    scf_iterations: int

    @property
    def gap(self) -> torch.Tensor:
        """Smooth HOMO-LUMO gap (Hartree)."""
        return self.lumo - self.homo


def smooth_max(values: torch.Tensor, temperature: float = ORBITAL_TEMPERATURE) -> torch.Tensor:
    """``T * logsumexp(values / T)`` over the last axis: a differentiable maximum."""
    return temperature * torch.logsumexp(values / temperature, dim=-1)


def smooth_min(values: torch.Tensor, temperature: float = ORBITAL_TEMPERATURE) -> torch.Tensor:
    """``-T * logsumexp(-values / T)`` over the last axis: a differentiable minimum."""
    return -smooth_max(-values, temperature)


def frontier_orbitals(
    emo: torch.Tensor,
    n_occupied: torch.Tensor | int,
    n_orbitals: torch.Tensor | int,
    temperature: float = ORBITAL_TEMPERATURE,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Smooth HOMO and LUMO from ascending orbital energies.

    Parameters
    ----------
    emo : Tensor
        Orbital energies, ``(norb,)`` or batched ``(B, norb)`` with padding orbitals last.
    n_occupied : Tensor or int
        Doubly occupied orbitals per molecule (closed shell: electrons / 2).
    n_orbitals : Tensor or int
        Real (non-padding) orbitals per molecule.
    temperature : float
        Smoothing temperature in Hartree.

    Returns
    -------
    (homo, lumo) : tuple of Tensor
        Shape ``()`` or ``(B,)``.
    """
    index = torch.arange(emo.shape[-1], device=emo.device)
    n_occ = torch.as_tensor(n_occupied, device=emo.device).unsqueeze(-1)
    n_orb = torch.as_tensor(n_orbitals, device=emo.device).unsqueeze(-1)
    occupied = index < n_occ
    virtual = (index >= n_occ) & (index < n_orb)
    homo = smooth_max(torch.where(occupied, emo, -torch.inf), temperature)
    lumo = smooth_min(torch.where(virtual, emo, torch.inf), temperature)
    return homo, lumo


@functools.cache
def gfn1_parameters() -> object:
    """The GFN1-xTB parametrization as a dxtb ``ParamModule`` (built once per process)."""
    import dxtb

    return dxtb.ParamModule(dxtb.GFN1_XTB, dtype=DTYPE, device=torch.device("cpu"))


def calculator_options(**overrides: object) -> dict[str, object]:
    """dxtb options used for every calculation here (full-mode SCF, silent, must converge)."""
    options: dict[str, object] = {
        "scf_mode": "full",
        "verbosity": 0,
        "force_convergence": True,
        "maxiter": 200,
    }
    options.update(overrides)
    return options


class GFN1Model:
    """GFN1-xTB single points for one molecule (fixed atoms, varying positions).

    Parameters
    ----------
    numbers : sequence of int
        Atomic numbers of all atoms, hydrogens included.
    charge : int
        Total charge.
    """

    def __init__(self, numbers: Sequence[int], charge: int = 0) -> None:
        import dxtb

        self.numbers = torch.as_tensor(list(numbers), dtype=torch.long)
        if self.numbers.numel() == 0 or int(self.numbers.max()) > MAX_ELEMENT:
            raise XtbError(f"GFN1-xTB covers elements 1-{MAX_ELEMENT} only")
        self.charge = int(charge)
        self._calc = dxtb.Calculator(
            self.numbers,
            gfn1_parameters(),
            opts=calculator_options(),
            dtype=DTYPE,
            device=torch.device("cpu"),
        )
        self._n_orbitals = int(self._calc.ihelp.nao)

    def __call__(self, positions_bohr: torch.Tensor) -> XtbPoint:
        """Energy and frontier orbitals at ``positions_bohr`` (``(n, 3)``, Bohr).

        Raises
        ------
        XtbError
            The SCF did not converge or produced non-finite values.
        """
        self._calc.reset()
        try:
            result = self._calc.singlepoint(positions_bohr, chrg=self.charge)
        except (RuntimeError, ValueError, torch.linalg.LinAlgError) as error:
            raise XtbError(f"xTB failed: {str(error).splitlines()[0][:200]}") from error
        electrons = float(result.occupation.detach().sum())
        n_occupied = int(round(electrons / 2))
        if abs(electrons - 2 * n_occupied) > 1e-6:
            raise XtbError(f"{electrons:g} valence electrons: not a closed-shell molecule")
        homo, lumo = frontier_orbitals(result.emo, n_occupied, self._n_orbitals)
        energy = result.total.sum()
        if not (torch.isfinite(energy) and torch.isfinite(homo) and torch.isfinite(lumo)):
            raise XtbError("xTB returned non-finite energies")
        return XtbPoint(energy=energy, homo=homo, lumo=lumo, scf_iterations=int(result.iter))
