"""The inner fit's Adam: the same numbers as torch.optim.Adam, without importing torch's
compiler stack into the fit worker."""

import json
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from sga_agent.registry import load_task
from tasks.constitutive.adam import Adam

LAW = Path(__file__).resolve().parents[3] / "examples" / "laws" / "neo_hookean.py"


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_adam_takes_torch_adams_steps_exactly(dtype):
    generator = torch.Generator().manual_seed(0)
    shapes = [(), (3,), (2, 3)]
    ours = [torch.randn(shape, generator=generator, dtype=dtype).requires_grad_()
            for shape in shapes]  # fmt: skip
    theirs = [parameter.detach().clone().requires_grad_() for parameter in ours]
    mine, reference = Adam(ours, lr=3e-2), torch.optim.Adam(theirs, lr=3e-2)
    for step in range(25):
        grads = [torch.randn(shape, generator=generator, dtype=dtype) * 10**(step % 4 - 2)
                 for shape in shapes]  # fmt: skip
        for index, (a, b) in enumerate(zip(ours, theirs, strict=True)):
            skipped = index == 1 and step % 5 == 3  # a step without this gradient
            a.grad = None if skipped else grads[index].clone()
            b.grad = None if skipped else grads[index].clone()
        mine.step()
        reference.step()
        for a, b in zip(ours, theirs, strict=True):
            assert torch.equal(a, b), step
    mine.zero_grad()
    assert all(parameter.grad is None for parameter in ours)


def test_adam_refuses_settings_that_are_not_adam():
    with pytest.raises(ValueError, match="invalid Adam settings"):
        Adam([torch.zeros(1, requires_grad=True)], lr=-1.0)


FIT = """
import json, sys
import torch
from sga_agent.registry import load_task
from sga_agent.task import EvaluationSettings
from tasks.constitutive.options import ConstitutiveOptions
task = load_task("elastic")
options = ConstitutiveOptions(steps=200)
for _stage in task.warm_up_fit(options):
    pass
data = json.loads(sys.stdin.read())
result = task.evaluate(data, EvaluationSettings(epochs=2, options=options))
print(json.dumps({"valid": result.valid, "losses": len(result.curves["loss"]),
                  "compiler": "torch._dynamo" in sys.modules}))
"""


@pytest.mark.slow
def test_a_fit_worker_never_imports_torchs_compiler_stack():
    data = load_task("elastic").capture(LAW.read_text())  # capturing uses it: done here
    out = subprocess.run([sys.executable, "-c", FIT], input=json.dumps(data),
                         capture_output=True, text=True, check=True)  # fmt: skip
    answer = json.loads(out.stdout.strip().splitlines()[-1])
    assert answer == {"valid": True, "losses": 3, "compiler": False}
