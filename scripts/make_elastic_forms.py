"""Write ``tasks/constitutive/gp/elastic_forms.py``: the one-term elastic forms the law search
pairs, most probable first.

A form is listed when it is admissible (frame indifferent and stress-free at rest, see
``tasks.constitutive.gp.admissible``), stiffens the body at small strain (no negative shear or
bulk response, and some response: a term of second order carries no small-strain stiffness)
and is not another listed form's stress in other words: forms are told apart by their stress
on sample deformations, so ``T(b) - I`` and ``b - I`` are one form. They are ranked by their
probability under random generation (``enumeration``), summed over their writings. A form whose
stress is a pressure (a multiple of the identity everywhere, as lam log(J) I) is marked: the
search pairs it with the others first (``enumeration.elastic_pairs``).

The search process never imports torch, so this runs once, here, and the table is kept in the
repository; ``tests/tasks/constitutive/test_gp.py`` checks that it is up to date. From the
repository root::

    python scripts/make_elastic_forms.py
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from tasks.constitutive.gp.admissible import admissible_term  # noqa: E402
from tasks.constitutive.gp.canonical import form  # noqa: E402
from tasks.constitutive.gp.codegen import law_code  # noqa: E402
from tasks.constitutive.gp.enumeration import expressions, loose  # noqa: E402
from tasks.constitutive.gp.genome import (  # noqa: E402
    Genome,
    Node,
    Param,
    Term,
    from_json,
    to_json,
    trivial,
)
from tasks.constitutive.law_code import load_law  # noqa: E402

TABLE = ROOT / "tasks" / "constitutive" / "gp" / "elastic_forms.py"
MAX_SIZE = 4  # nodes of a listed form
LISTED = 12  # forms kept
STRAIN = 1e-4  # of the small-strain probes
SAMPLES = 32  # deformations that tell forms apart


def stress(expr: Node, F: torch.Tensor) -> torch.Tensor:
    """The (unsymmetrised) value of the one-term law ``expr`` at unit modulus, (B, 3, 3)."""
    code = law_code(Genome("elastic", (Term(Param("log", 0.0), expr),)))
    code = code.replace("return 0.5 * (stress + stress.transpose(-2, -1))", "return stress")
    law = load_law(code, torch.float64)
    with torch.no_grad():
        return law(F)


def small_strain_response(expr: Node) -> tuple[float, float, float]:
    """The term's response at unit modulus to small strains: tau_01 / 2h under the shear
    F = I + h (e_01 + e_10), and tr(tau) / 3h under the stretch (1 + h) I and the compression
    (1 - h) I (signed so that a stiffening term gives positive numbers; a linear law
    2 mu eps + lam tr(eps) I gives mu, 2 mu + 3 lam, 2 mu + 3 lam)."""
    eye = torch.eye(3, dtype=torch.float64)
    shear = eye.clone()
    shear[0, 1] = shear[1, 0] = STRAIN
    tau = stress(expr, torch.stack([shear, eye * (1 + STRAIN), eye * (1 - STRAIN)]))
    stretch, compression = tau[1].trace().item(), -tau[2].trace().item()
    return tau[0, 0, 1].item() / (2 * STRAIN), stretch / (3 * STRAIN), compression / (3 * STRAIN)


def response(expr: Node) -> tuple[float, float]:
    """(shear, volume) response for matching moduli: the volume one the mean of stretching and
    compressing."""
    shear, stretch, compression = small_strain_response(expr)
    return shear, (stretch + compression) / 2


def is_pressure(tau: torch.Tensor) -> bool:
    """Whether every stress of ``tau`` (B, 3, 3) is a multiple of the identity."""
    mean = tau.diagonal(dim1=-2, dim2=-1).mean(-1).view(-1, 1, 1)
    return bool(torch.allclose(tau, mean * torch.eye(3, dtype=tau.dtype), atol=1e-9))


def samples() -> torch.Tensor:
    generator = torch.Generator().manual_seed(0)
    noise = torch.randn(SAMPLES, 3, 3, generator=generator, dtype=torch.float64)
    return torch.eye(3, dtype=torch.float64) + 0.2 * noise


def listed_forms() -> list[tuple[str, float, bool]]:
    """(genome JSON of the one-term form, its probability, whether it is a pressure), most
    probable first."""
    chances: dict[tuple, float] = {}
    first: dict[tuple, Node] = {}
    for nodes in range(1, MAX_SIZE + 1):
        for expr, probability in expressions("elastic", "M", nodes):
            if not isinstance(expr, Node) or trivial(expr, "elastic") or not admissible_term(expr):
                continue
            key = loose(form(Genome("elastic", (Term(Param("log", 0.0), expr),))))
            chances[key] = chances.get(key, 0.0) + probability
            first.setdefault(key, expr)
    F = samples()
    kept: list[tuple[str, float, bool]] = []
    seen: list[tuple[torch.Tensor, int]] = []
    for key in sorted(chances, key=lambda key: (-chances[key], repr(key))):
        expr = first[key]
        value = stress(expr, F).flatten()
        small = small_strain_response(expr)
        if not torch.isfinite(value).all() or min(small) < -1e-6 or sum(small) < 1e-3:
            continue  # no stiffness at small strain, or a negative one
        direction = value / value.norm()
        match = next((i for d, i in seen if torch.allclose(d, direction, atol=1e-8)), None)
        if match is not None:  # another writing of a listed form: its chance counts there
            text, chance, pressure = kept[match]
            kept[match] = (text, chance + chances[key], pressure)
            continue
        seen.append((direction, len(kept)))
        genome = Genome("elastic", (Term(Param("log", 0.0), expr),))
        kept.append((to_json(genome), chances[key], is_pressure(value.view(-1, 3, 3))))
    kept.sort(key=lambda item: -item[1])
    return kept[:LISTED]


def responses(forms: list[tuple[str, float, bool]]) -> dict[str, tuple[float, float]]:
    """The (shear, volume) response of each listed form, by its genome JSON."""
    return {
        text: tuple(round(value, 6) + 0.0 for value in response(from_json(text).terms[0].expr))
        for text, _, _ in forms
    }  # + 0.0: no -0.0


def render(forms: list[tuple[str, float, bool]]) -> str:
    rows = "\n".join(
        f"    (\n        {text!r},\n        {chance:.6g}, {pressure},\n    ),"
        for text, chance, pressure in forms
    )
    known = "\n".join(
        f"    {text!r}:\n        ({shear!r}, {volume!r}),"
        for text, (shear, volume) in responses(forms).items()
    )
    return (
        "# ruff: noqa: E501 (genome JSON on one line)\n"
        '"""One-term elastic forms the law search pairs, most probable first: (genome JSON, '
        "prior\nprobability, whether its stress is a pressure); and the small-strain response "
        "(shear,\nvolume) of each at unit modulus. Generated by\n"
        "``scripts/make_elastic_forms.py``; do not edit.\n"
        '"""\n\n'
        f"FORMS: tuple[tuple[str, float, bool], ...] = (\n{rows}\n)  # fmt: skip\n\n"
        f"RESPONSES: dict[str, tuple[float, float]] = {{\n{known}\n}}  # fmt: skip\n"
    )


def main() -> None:
    forms = listed_forms()
    assert all(math.isfinite(chance) for _, chance, _ in forms)
    TABLE.write_text(render(forms))
    print(f"wrote {len(forms)} forms to {TABLE.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
