"""Constitutive-law tasks: the true law scores ~0, the seed scores clearly worse, the inner
optimization fits parameters started 2x off, and bad laws are refused with a reason (by the
capture, or by the fit). The laws are captured here, in the test process: they are known code,
and the sandbox has its own tests."""

import math
import re
from pathlib import Path

import pytest
import torch

from sga_agent.registry import load_task
from sga_agent.task import EvaluationSettings, InvalidSolution, Task
from tasks.constitutive.law_code import LawCodeError
from tasks.constitutive.options import ConstitutiveOptions

LAWS = Path(__file__).resolve().parents[3] / "examples" / "laws"
TRUTH = {
    "elastic": "neo_hookean.py",
    "plasticine": "von_mises.py",
    "granular": "drucker_prager.py",
    "fluid": "fluid.py",
    "imaginary": "mixture.py",
}
QUICK = ConstitutiveOptions(steps=200)  # two teacher-forced segments: tells the laws apart


def score(name: str, code: str, epochs: int = 0, **settings) -> object:
    """Capture ``code`` (here: a trusted context), then fit the captured law."""
    settings.setdefault("options", QUICK)
    task = load_task(name)
    return task.evaluate(task.capture(code), EvaluationSettings(epochs=epochs, **settings))


@pytest.mark.slow
@pytest.mark.parametrize("name", list(TRUTH))
def test_truth_scores_noise_and_seed_scores_worse(name):
    task = load_task(name)
    assert isinstance(task, Task) and task.kind == "equation"
    truth = score(name, (LAWS / TRUTH[name]).read_text())
    seed = score(name, task.seed_solution())
    assert truth.valid and seed.valid, (truth.reason, seed.reason)
    assert truth.loss < 1e-8
    assert seed.loss > 1e3 * max(truth.loss, 1e-12)
    assert "Trajectories of corner particles" in truth.feedback
    assert truth.artifacts == {}  # reports draw the free run from the task's assessment


def _shifted(code: str, replacements: dict[str, float]) -> str:
    for argument, value in replacements.items():
        code, count = re.subn(rf"({argument}: float = )[^,)]+", rf"\g<1>{value!r}", code)
        assert count == 1, argument
    return code


#: The mixture with every parameter 2x off (yield stress halved: doubled, it never yields).
IMAGINARY_START = {
    "log_weight_von_mises": math.log(0.25),
    "log_weight_sand": math.log(0.6),
    "log_weight_fluid": math.log(0.15),
    "log_yield_stress": math.log(1.5e4),
    "log_friction_angle": math.log(50.0),
}


@pytest.mark.parametrize(
    ("name", "start", "epochs", "learning_rate"),
    [
        ("elastic", {"log_youngs_modulus": 13.0 + math.log(2.0), "poissons_ratio": 0.1225}, 16,
         0.08),
        pytest.param("plasticine", {"log_yield_stress": math.log(6e4)}, 7, 0.15,
                     marks=pytest.mark.heavy),
        pytest.param("imaginary", IMAGINARY_START, 15, None,  # the task's L-BFGS: no rate
                     marks=pytest.mark.heavy),
    ],
)  # fmt: skip
@pytest.mark.slow
def test_inner_optimization_recovers_parameters_started_2x_off(name, start, epochs, learning_rate):
    """Fewer epochs (at a larger step, for Adam) than the task's 30, to fit the test budget;
    scripts/make_ground_truth.py --fit checks the task's settings on the full scene."""
    code = _shifted((LAWS / TRUTH[name]).read_text(), start)
    result = score(name, code, epochs=epochs, learning_rate=learning_rate)
    assert result.valid, result.reason
    first = result.curves["loss"][0]
    assert result.loss < first / 100
    assert result.loss == min(result.curves["loss"])  # the best epoch is kept
    assert set(start) <= set(result.parameters)


@pytest.mark.slow
def test_lbfgs_steps_back_from_a_trial_point_that_blows_up():
    """A unit step in log_scale (the first L-BFGS trial) makes the scene explode: the line
    search must shrink the step rather than stop, and the feedback says so."""
    code = (
        "import torch, torch.nn as nn\nclass Physics(nn.Module):\n"
        "    def __init__(self, log_scale: float = 0.0):\n        super().__init__()\n"
        "        self.log_scale = nn.Parameter(torch.tensor(log_scale))\n"
        "    def forward(self, F):\n        return F * torch.exp(self.log_scale)\n"
    )
    result = score("plasticine", code, epochs=3, options=ConstitutiveOptions(200, "lbfgs"))
    assert result.valid and result.extras["stopped"] == ""
    assert len(result.curves["loss"]) >= 2 and result.loss == min(result.curves["loss"])
    assert re.search(r"trial points? of the line search (were|was) rejected", result.feedback)
    assert "L-BFGS" in result.feedback


@pytest.mark.slow
def test_parameter_free_law_is_scored_once():
    result = score("fluid", (LAWS / "fluid.py").read_text().replace("nn.Parameter(", "("), 30)
    assert result.valid and result.curves["loss"] == [result.loss]
    assert "no trainable parameters" in result.feedback


#: Code the capture refuses (it never reaches the fit): the reason is the InvalidSolution's.
REFUSED = {
    "syntax": ("class Physics(nn.Module:\n    pass\n", "does not compile: SyntaxError"),
    "no class": ("import torch\nx = 1\n", "defines no top-level class 'Physics'"),
    "not a module": ("class Physics:\n    pass\n", "must derive from nn.Module"),
    "rebound": (
        "import torch.nn as nn\nclass Physics(nn.Module):\n"
        "    def forward(self, F):\n        return F\nPhysics = 1\n",
        "Physics must be a class deriving from torch.nn.Module",
    ),
    "init needs arguments": (
        "import torch.nn as nn\nclass Physics(nn.Module):\n"
        "    def __init__(self, E):\n        super().__init__()\n"
        "    def forward(self, F):\n        return F\n",
        "needs a default value (the starting value of the fit); missing for: E",
    ),
    "wrong signature": (
        "import torch.nn as nn\nclass Physics(nn.Module):\n"
        "    def forward(self, F, J):\n        return F\n",
        "forward must take exactly one required argument besides self, the input F",
    ),
    "shape mismatch": (
        "import torch.nn as nn\nclass Physics(nn.Module):\n"
        "    def forward(self, F):\n        return F @ F[:, :2]\n",
        "the law could not be captured: the shapes of two tensors do not fit together. "
        "At line 4 (`return F @ F[:, :2]`). Fix: F is (B, 3, 3)",
    ),
}


@pytest.mark.parametrize("case", list(REFUSED))
def test_unusable_code_is_refused_by_the_capture_with_a_reason(case):
    code, reason = REFUSED[case]
    with pytest.raises(LawCodeError) as refused:
        load_task("plasticine").capture(code)
    assert isinstance(refused.value, InvalidSolution)
    assert reason in str(refused.value)
    assert "\n" not in str(refused.value)


#: Laws that capture but fail in the fit: (code, reason, status).
BROKEN = {
    "wrong shape": (
        "import torch.nn as nn\nclass Physics(nn.Module):\n"
        "    def forward(self, F):\n        return F[:, 0]\n",
        "must return F_corrected of shape",
        "invalid",
    ),
    "nan": (
        "import torch, torch.nn as nn\nclass Physics(nn.Module):\n"
        "    def forward(self, F):\n        return F * float('nan')\n",
        "returns non-finite F_corrected",
        "unstable",
    ),
    "nan later": (
        "import torch, torch.nn as nn\nclass Physics(nn.Module):\n"
        "    def forward(self, F):\n        return F * 10.0\n",
        "the simulation is unstable with this law (epoch 0: the simulation became non-finite",
        "unstable",
    ),
    "mixes particles": (  # batched segments would couple: refused before any epoch
        "import torch, torch.nn as nn\nclass Physics(nn.Module):\n"
        "    def forward(self, F):\n"
        "        return F - F.mean(dim=0, keepdim=True) + torch.eye(3)\n",
        "the plastic law mixes particles",
        "invalid",
    ),
    "raises": (  # singular matrices: only the values tell, so only the fit finds out
        "import torch, torch.nn as nn\nclass Physics(nn.Module):\n"
        "    def forward(self, F):\n        return torch.linalg.inv(F - F)\n",
        "the law raised ",
        "error",
    ),
}


@pytest.mark.parametrize("case", list(BROKEN))
def test_broken_laws_are_invalid_with_a_reason(case):
    code, reason, status = BROKEN[case]
    result = score("plasticine", code)
    assert not result.valid
    assert result.loss == math.inf
    assert reason in result.reason
    assert "\n" not in result.reason
    assert result.status == status


@pytest.mark.parametrize(
    ("data", "reason"),
    [
        (None, "not a captured law graph"),
        ({"solution": "class Physics: ..."}, "not a captured law graph"),
        ({"law": {"format": 1, "parameters": [], "constants": [], "nodes": "x"}}, "list of nodes"),
        (
            {"law": {"format": 1, "parameters": [], "constants": [], "output": {"node": 0},
                     "nodes": [{"op": "builtins.exec", "args": ["import os"], "kwargs": {}}]}},
            "not an ATen operation",
        ),
    ],
)  # fmt: skip
def test_the_fit_refuses_data_that_is_not_a_checked_graph(data, reason):
    """What reaches the fit is untrusted: it is checked, never run, and never raises."""
    result = load_task("plasticine").evaluate(data, EvaluationSettings(epochs=0, options=QUICK))
    assert not result.valid and result.status == "invalid"
    assert reason in result.reason and "\n" not in result.reason


def test_a_precision_other_than_the_running_one_is_an_error():
    """The test session runs Taichi in float64 (tests/conftest.py)."""
    task = load_task("elastic")
    with pytest.raises(ValueError, match="precision=float32 differs from the float64 Taichi"):
        task.evaluate({}, EvaluationSettings(options=ConstitutiveOptions(precision="float32")))


UNUSED = """import torch
import torch.nn as nn


class Physics(nn.Module):
    def __init__(self, log_youngs_modulus: float = 10.0, poissons_ratio: float = 0.2):
        super().__init__()
        self.log_youngs_modulus = nn.Parameter(torch.tensor(log_youngs_modulus))
        self.poissons_ratio = nn.Parameter(torch.tensor(poissons_ratio))

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        I = torch.eye(3, dtype=F.dtype, device=F.device)
        return {stress}
"""
#: Uses neither parameter / only the Young's modulus (a small linear law).
NEITHER = "1e3 * (F + F.transpose(1, 2) - 2 * I)"
ONE = "torch.exp(self.log_youngs_modulus) * 1e-2 * (F + F.transpose(1, 2) - 2 * I)"


def test_parameters_the_output_ignores_are_found_without_simulating():
    from tasks.constitutive.inner import unused_parameters
    from tasks.constitutive.law_graph import build_law

    task = load_task("elastic")
    for stress, unused in [(NEITHER, ["log_youngs_modulus", "poissons_ratio"]),
                           (ONE, ["poissons_ratio"])]:  # fmt: skip
        law = build_law(task.capture(UNUSED.format(stress=stress))["law"], torch.float64)
        assert unused_parameters(law) == unused


ONE_SENTENCE = (
    "The loss does not depend on the parameter poissons_ratio (no gradient reaches it from the "
    "law's output), so it was not fitted: use it in forward or remove it."
)


@pytest.mark.heavy
@pytest.mark.parametrize(("stress", "unused"), [(NEITHER, 2), (ONE, 1)])
def test_a_parameter_the_loss_ignores_is_named_in_one_sentence(stress, unused):
    """Fitted, not "element 0 of tensors does not require grad"."""
    result = score("elastic", UNUSED.format(stress=stress), epochs=1,
                   options=ConstitutiveOptions(steps=100))  # fmt: skip
    assert result.valid, result.reason
    sentences = [line for line in result.feedback.splitlines() if "does not depend" in line]
    assert len(sentences) == 1 and "poissons_ratio" in sentences[0]
    if unused == 1:
        assert sentences == [ONE_SENTENCE]
        assert list(result.parameters) == ["log_youngs_modulus"]
    else:
        assert "parameters log_youngs_modulus, poissons_ratio" in sentences[0]
        assert result.parameters == {}
