"""A captured law compiled into Taichi kernels computes what its torch graph computes.

The laws are captured here, in the test process (known code). In float64 the kernels must give
the torch graph's stress, dL/dF and parameter gradients to round-off (a law whose SVDs are of
F itself, with the SVD's factors as the kernels' inputs, too); a law whose operations have no
translation (an SVD unless asked for) or whose torch graph mixes particles stays in torch; and
a fit scores a law the same with and without the kernels.
"""

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from bridges import scalar_law
from sga_agent.registry import load_task
from sga_agent.task import EvaluationSettings
from tasks.constitutive import law_kernel, law_ops
from tasks.constitutive.evaluation import law_kernels_for
from tasks.constitutive.gp.codegen import law_code
from tasks.constitutive.gp.genome import Genome, Node, Param, Term
from tasks.constitutive.law_capture import capture_law
from tasks.constitutive.law_graph import build_law
from tasks.constitutive.options import ConstitutiveOptions

EXAMPLES = Path(__file__).resolve().parents[3] / "examples" / "laws"

#: Most of the translated operations in one law.
BROAD = """
import torch
from torch import nn


class Physics(nn.Module):
    def __init__(self):
        super().__init__()
        self.log_mu = nn.Parameter(torch.tensor(0.5))
        self.weights = nn.Parameter(torch.tensor([0.3, -0.2]))
        self.scale = nn.Parameter(torch.ones(3, 3) * 0.1)

    def forward(self, F):
        J = torch.linalg.det(F).view(-1, 1, 1)
        inverse = torch.linalg.inv(F)
        B = F @ F.transpose(1, 2)
        eye = torch.eye(3, dtype=F.dtype).expand_as(F)
        w = torch.softmax(self.weights, dim=0)
        trace = torch.diagonal(B, dim1=-2, dim2=-1).mean(-1).view(-1, 1, 1)
        dev = B - trace * eye
        gate = torch.sigmoid(J - 1) * torch.relu(J - 0.5) + torch.maximum(J, torch.ones_like(J))
        mixed = torch.stack([dev, inverse.permute(0, 2, 1)], dim=1).sum(1)
        rows = torch.cat([mixed[:, :2], self.scale[None, 2:].expand(F.shape[0], 1, 3)], dim=1)
        return (
            torch.exp(self.log_mu) * (w[0] * rows + w[1] * gate * eye)
            + torch.clamp(dev, -0.5, 0.5).pow(2)
            + torch.rsqrt(J.abs() + 1) * eye * self.scale.unsqueeze(0)
            - torch.where(J > 1.05, (J - 1.05) ** 3, torch.zeros_like(J)) * eye
        )
"""

MIXING = """
import torch
from torch import nn


class Physics(nn.Module):
    def __init__(self):
        super().__init__()
        self.mu = nn.Parameter(torch.tensor(1.0))

    def forward(self, F):
        return self.mu * (F - F.mean(0, keepdim=True))
"""


def _gp_law(rotation: bool = True) -> str:
    """A law of the genetic-programming grammar using its SVD's U, sigma and Vh: a von Mises
    return mapping rebuilt from the corrected strain (the yield strain of ``plasticine``'s
    ground truth), and with ``rotation`` a shear towards the rotation of F, scaled by log J
    (the determinant of F), which makes the scene unstable."""
    eps = Node("eps")
    threshold = Node("const", (Param("log", math.log(3e4 / (2 * 1e6 / 2.4))),))
    mapped = Node("add", (Node("vol", (eps,)), Node("shrink", (Node("dev", (eps,)), threshold))))
    terms = (Term(Param("sigmoid", 1.0), Node("from_strain", (mapped,))),)
    if rotation:
        towards = Node("smul", (Node("log_J"), Node("sub", (Node("R"), Node("F")))))
        terms += (Term(Param("sigmoid", -2.0), towards),)
    return law_code(Genome("plastic", terms))


#: Laws whose every SVD is of F itself: compiled with its factors as the kernels' inputs.
SVD_OF_F = {"gp": _gp_law(), "von_mises": (EXAMPLES / "von_mises.py").read_text(),
            "drucker_prager": (EXAMPLES / "drucker_prager.py").read_text()}  # fmt: skip


def _deformations(count: int = 400) -> torch.Tensor:
    generator = torch.Generator().manual_seed(7)
    F = torch.eye(3, dtype=torch.float64) + 0.2 * torch.randn(
        count, 3, 3, dtype=torch.float64, generator=generator
    )
    F[1] = -F[1]
    return F


def _law(code: str):
    return build_law(capture_law(code), torch.float64)


def _assert_kernels_match_torch(law, kernels: scalar_law.CompiledLaw) -> None:
    """The law's stress, dL/dF and parameter gradients with ``kernels`` are its torch graph's."""
    F = _deformations(count=300).requires_grad_(True)
    weights = torch.randn(F.shape, dtype=torch.float64, generator=torch.Generator().manual_seed(3))
    expected = law.torch_forward(F)
    expected_grads = torch.autograd.grad((expected * weights).sum(), [F, *law.graph_parameters])
    law.use_kernels(kernels)
    actual = law(F)
    actual_grads = torch.autograd.grad((actual * weights).sum(), [F, *law.graph_parameters])
    torch.testing.assert_close(actual, expected, rtol=1e-10, atol=1e-10)
    for mine, theirs in zip(actual_grads, expected_grads, strict=True):
        torch.testing.assert_close(mine, theirs, rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize("code", [BROAD, (EXAMPLES / "neo_hookean.py").read_text(),
                                  (EXAMPLES / "fluid.py").read_text()],
                         ids=["broad", "neo_hookean", "fluid"])  # fmt: skip
def test_compiled_laws_equal_their_torch_graphs(code):
    law = _law(code)
    kernels = law_kernel.kernel_law(law, _deformations())
    assert kernels is not None
    _assert_kernels_match_torch(law, kernels)


@pytest.mark.parametrize("name", SVD_OF_F)
def test_laws_with_an_svd_of_F_compile_with_its_factors_as_inputs(name):
    """No Jacobi sweeps in the kernels: U, S, Vh come from ``bridges.linalg.svd`` (the same
    SVD as the torch graph's), so in float64 the stress and every gradient match torch's."""
    law = _law(SVD_OF_F[name])
    program, _ = law_kernel.translate(law.graph, torch.float64, svd=False, factored=True)
    assert len(program.inputs) == 30 and all(op != "svd" for op, _ in program.nodes)
    kernels = law_kernel.kernel_law(law, _deformations(), factored=True)
    assert kernels is not None and kernels.svd_inputs
    _assert_kernels_match_torch(law, kernels)


@pytest.mark.parametrize("name", SVD_OF_F)
def test_a_law_of_F_and_its_svd_passes_finite_differences(name):
    """Through the law's reverse kernel and then the SVD's reverse, to F and the parameters."""
    law = _law(SVD_OF_F[name])
    kernels = law_kernel.kernel_law(law, _deformations(), factored=True)
    assert kernels is not None
    F = _deformations(count=5).requires_grad_(True)
    parameters = [p.detach().clone().requires_grad_(True) for p in law.graph_parameters]
    assert torch.autograd.gradcheck(lambda F, *p: scalar_law.apply_law(F, kernels, p),
                                    (F, *parameters), eps=1e-6, atol=1e-6)  # fmt: skip


def test_a_law_with_another_svd_stays_in_torch_unless_sweeps_are_asked_for():
    code = (EXAMPLES / "von_mises.py").read_text()
    code = code.replace("torch.linalg.svd(F)", "torch.linalg.svd(F.transpose(1, 2))")
    law = _law(code)
    with pytest.raises(law_kernel.Untranslatable, match="other than F"):
        law_kernel.translate(law.graph, torch.float64, svd=False, factored=True)
    assert law_kernel.kernel_law(law, _deformations(), factored=True) is None
    program, _ = law_kernel.translate(law.graph, torch.float64, svd=True, factored=True)
    assert len(program.inputs) == 9 and any(op == "svd" for op, _ in program.nodes)


def test_every_overload_of_the_operations_table_may_appear_in_a_graph():
    """An operation's ATen overloads are translated by its entry; a graph may hold them."""
    overloads = [name for op in scalar_law.OPERATIONS.values() for name in op.aten]
    assert len(overloads) > 30 and all(law_ops.is_allowed(name) for name in overloads)
    assert set(overloads) <= set(law_kernel.RULES)


def test_a_law_with_an_svd_is_compiled_only_when_asked():
    law = _law((EXAMPLES / "von_mises.py").read_text())
    with pytest.raises(law_kernel.Untranslatable, match="svd"):
        law_kernel.translate(law.graph, torch.float64, svd=False)
    assert law_kernel.kernel_law(law, _deformations()) is None


def test_in_float64_a_law_with_an_svd_stays_in_torch():
    """The kernels' SVD (Jacobi sweeps to float32 round-off) is not LAPACK's to 1e-9."""
    law = _law((EXAMPLES / "von_mises.py").read_text())
    law_kernel.translate(law.graph, torch.float64)
    assert law_kernel.kernel_law(law, _deformations(), svd=True) is None


def test_a_law_of_large_tensors_per_particle_is_not_translated():
    code = MIXING.replace("self.mu * (F - F.mean(0, keepdim=True))",
                          "F * torch.ones(100, 100).sum() * self.mu")  # fmt: skip
    with pytest.raises(law_kernel.Untranslatable, match="values per particle"):
        law_kernel.translate(_law(code).graph, torch.float64)


#: In float32, where the torch graph's SVD and the kernels' are the same Jacobi sweeps, every
#: example law compiles both ways (the sweeps in its kernels, or svd3's factors as their
#: inputs), agrees, and a fit's first loss and gradient match with the factors as inputs.
FLOAT32_CHECK = r"""
import json, sys, torch
import taichi_mpm as tm
tm.init(arch="cpu", precision="float32")
from bridges import scalar_law
from sga_agent.registry import load_task
from sga_agent.task import EvaluationSettings
from tasks.constitutive import law_kernel, law_ops
from tasks.constitutive.gp.codegen import law_code
from tasks.constitutive.gp.genome import Genome, Node, Param, Term
from tasks.constitutive.law_graph import build_law
from tasks.constitutive.options import ConstitutiveOptions
report = {}
for name, (task, path) in json.loads(sys.argv[1]).items():
    code = open(path).read()
    evaluator = load_task(task)
    data = evaluator.capture(code)
    F = torch.eye(3) + 0.1 * torch.randn(300, 3, 3, generator=torch.Generator().manual_seed(0))
    law = build_law(data["law"], torch.float32)
    compiled = law_kernel.kernel_law(law, F, svd=True) is not None  # Jacobi sweeps inside
    factored = law_kernel.kernel_law(law, F, factored=True) is not None  # svd3's factors
    losses = [evaluator.evaluate(data, EvaluationSettings(epochs=1, options=ConstitutiveOptions(
        steps=100, law_kernels=kernels))).curves["loss"] for kernels in ("svd-inputs", "none")]
    report[name] = {"compiled": compiled, "factored": factored, "losses": losses}
print(json.dumps(report))
"""


def test_in_float32_laws_with_svds_compile_and_fit_as_in_torch():
    laws = {"von_mises": ("plasticine", str(EXAMPLES / "von_mises.py")),
            "drucker_prager": ("granular", str(EXAMPLES / "drucker_prager.py")),
            "mixture": ("imaginary", str(EXAMPLES / "mixture.py"))}  # fmt: skip
    out = subprocess.run([sys.executable, "-c", FLOAT32_CHECK, json.dumps(laws)],
                         capture_output=True, text=True, timeout=900)  # fmt: skip
    assert out.returncode == 0, out.stderr[-3000:]
    report = json.loads(out.stdout.strip().splitlines()[-1])
    for name, row in report.items():
        assert row["compiled"] and row["factored"], name
        (first, second), (torch_first, torch_second) = row["losses"]
        if torch_first < 1e-9:  # float32 round-off: the example mixture fits its task to 1e-12
            continue
        # the first loss: the same law, parameters and rollout; then one Adam step later
        assert first == pytest.approx(torch_first, rel=1e-4), name
        assert second == pytest.approx(torch_second, rel=1e-3), name


def test_a_law_that_mixes_particles_is_not_compiled_into_one_that_does_not():
    law = _law(MIXING)
    # per particle, the mean over the batch is the particle itself
    law_kernel.translate(law.graph, torch.float64)
    assert law_kernel.kernel_law(law, _deformations()) is None


@pytest.mark.parametrize(("task_name", "code", "kernels"), [
    ("elastic", (EXAMPLES / "neo_hookean.py").read_text(), "no-svd"),
    ("plasticine", _gp_law(rotation=False), "svd-inputs"),  # the SVD's factors as inputs
], ids=["neo_hookean", "gp_von_mises"])  # fmt: skip
def test_a_fit_scores_a_law_the_same_with_and_without_kernels(task_name, code, kernels):
    task = load_task(task_name)
    data = task.capture(code)
    results = [
        task.evaluate(data, EvaluationSettings(
            epochs=2, options=ConstitutiveOptions(steps=100, law_kernels=option)))
        for option in (kernels, "none")
    ]  # fmt: skip
    assert all(result.valid for result in results)
    compiled, in_torch = results
    assert compiled.loss == pytest.approx(in_torch.loss, rel=1e-9)
    for name, values in in_torch.curves.items():
        assert compiled.curves[name] == pytest.approx(values, rel=1e-9), name


@pytest.mark.parametrize(("option", "fidelity", "mode"), [
    ("auto", 1.0, "all"), ("auto", 0.2, "no-svd"), ("all", 0.2, "all"),
    ("svd-inputs", 1.0, "svd-inputs"), ("none", 1.0, "none"),
])  # fmt: skip
def test_the_default_compiles_an_svd_only_for_a_full_fit(option, fidelity, mode):
    """``auto`` writes a law's SVDs into its kernels for a full fit, not for a screen (too short
    to repay the compiling); any other option is taken as it is."""
    assert law_kernels_for(option, fidelity) == mode


def test_a_screen_asks_for_no_svd_kernels(monkeypatch, tmp_path):
    """An evaluation passes its fidelity to the law's compile: the kernels asked for are the
    sweeps for a full fit and none of an SVD for a screen."""
    asked = []
    real = law_kernel.kernel_law

    def recording(law, F, svd=True, factored=False):
        asked.append(svd)
        return real(law, F, svd=svd, factored=factored)

    monkeypatch.setattr(law_kernel, "kernel_law", recording)
    task = load_task("plasticine")
    data = task.capture((EXAMPLES / "von_mises.py").read_text())
    for fidelity in (1.0, 0.2):
        settings = EvaluationSettings(epochs=1, fidelity=fidelity,
                                      options=ConstitutiveOptions(steps=200))  # fmt: skip
        assert task.evaluate(data, settings).valid
    assert asked == [True, False]
