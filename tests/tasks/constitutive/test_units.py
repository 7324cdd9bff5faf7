"""The units of what a law's parameters stand for: Pa for moduli and stresses (the scenes are
SI), an angle in degrees only when the law's code turns degrees into radians."""

from __future__ import annotations

from pathlib import Path

from tasks.constitutive.task import GranularTask
from tasks.constitutive.units import converts_degrees, parameter_units

ROOT = Path(__file__).resolve().parents[3]
SAND = (ROOT / "examples" / "laws" / "drucker_prager.py").read_text(encoding="utf-8")
IN_RADIANS = SAND.replace(" * math.pi / 180", "")


def test_the_ground_truth_s_friction_angle_is_in_degrees():
    assert "torch.exp(self.log_friction_angle) * math.pi / 180" in SAND
    assert converts_degrees(SAND)
    assert GranularTask().parameter_units(SAND, ["friction_angle"]) == {"friction_angle": "deg"}


def test_an_angle_the_law_uses_as_it_is_is_in_radians():
    assert not converts_degrees(IN_RADIANS)
    assert parameter_units(IN_RADIANS, ["friction_angle"]) == {"friction_angle": "rad"}
    for conversion in ("torch.deg2rad(phi)", "math.radians(phi)", "phi * 0.0174533"):
        assert converts_degrees(f"phi = 1.0\nangle = {conversion}\n"), conversion
    assert not converts_degrees("this is not python (")


def test_moduli_and_stresses_are_in_pascal_and_uncertain_names_get_no_unit():
    names = ["youngs_modulus", "E", "modulus0", "bulk_modulus[1]", "yield_stress",
             "viscosity", "mu", "weight_sand", "fluidity"]  # fmt: skip
    assert parameter_units("", names) == {
        "youngs_modulus": "Pa", "E": "Pa", "modulus0": "Pa", "bulk_modulus[1]": "Pa",
        "yield_stress": "Pa", "viscosity": "Pa s",
    }  # fmt: skip


def test_an_observation_file_s_units_are_its_own_so_only_an_angle_gets_one():
    from tasks.observed.task import ObservedTask

    units = ObservedTask().parameter_units(SAND, ["youngs_modulus", "friction_angle"])
    assert units == {"friction_angle": "deg"}
