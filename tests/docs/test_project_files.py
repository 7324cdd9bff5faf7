"""The distribution's name, and what the README's examples leave behind in a checkout."""

import re
import subprocess
from pathlib import Path

from sga_agent.ray_executor import RAY_INSTALL

ROOT = Path(__file__).resolve().parents[2]
#: Free on the Python package index when chosen; ``sga`` there is an unrelated project.
DISTRIBUTION = "sga-agent"


def test_the_distribution_has_a_name_of_its_own_everywhere():
    pyproject = (ROOT / "pyproject.toml").read_text(encoding="utf-8")
    assert re.search(r'^name = "(.*)"$', pyproject, re.MULTILINE).group(1) == DISTRIBUTION
    assert f"{DISTRIBUTION}[ray]" in RAY_INSTALL
    for path in [ROOT / "README.md", *ROOT.glob("sga_agent/**/*.py"), *ROOT.glob("docs/**/*")]:
        if path.is_file() and path.suffix in (".md", ".py"):
            text = path.read_text(encoding="utf-8")
            assert not re.search(r"install[^\n]*\bsga\[", text), path


def test_the_readme_examples_outputs_are_ignored_by_git():
    outputs = ["observed.npz", "sysid_out/fit.json", "runs/granular-20261122-101500/config.json"]
    ignored = subprocess.run(
        ["git", "check-ignore", *outputs], cwd=ROOT, capture_output=True, text=True, check=False
    )
    assert ignored.stdout.split() == outputs
