"""The tasks page's QM9 calibration figures are the ones scripts/calibrate_qm9.py wrote into
tasks/molecules/calibration.py (its generated block), rounded as the page rounds them."""

from pathlib import Path

from tasks.molecules.calibration import CALIBRATION, QM9_MOLECULES, QM9_STATISTICS

PAGE = Path(__file__).resolve().parents[2] / "docs" / "tasks.md"
HARTREE_EV = 27.211386


def page() -> str:
    return " ".join(PAGE.read_text(encoding="utf-8").split())


def test_the_page_states_the_calibration_the_code_uses():
    text = page()
    assert f"all {QM9_MOLECULES:,} QM9 molecules" in text
    r = ", ".join(f"{CALIBRATION[p].r_test:.3f} ({name})"
                  for p, name in (("homo", "HOMO"), ("lumo", "LUMO"), ("gap", "gap")))  # fmt: skip
    assert f"held-out r = {r}" in text
    mae = ", ".join(f"{CALIBRATION[p].mae_test * HARTREE_EV:.2f}" for p in ("homo", "lumo", "gap"))
    assert f"MAE {mae} eV" in text


def test_the_page_states_the_qm9_statistics_the_code_normalizes_with():
    text = page()
    for prop, name in (("homo", "HOMO"), ("lumo", "LUMO"), ("gap", "gap")):
        statistics = QM9_STATISTICS[prop]
        assert f"{name} {statistics.mean:.4f} ± {statistics.std:.4f}" in text
