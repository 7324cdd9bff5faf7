"""A law written as a scalar program runs as Taichi kernels with torch's values and gradients.

Each law is written twice: in torch (batched tensors, autograd) and as a program (arithmetic on
one particle's :class:`bridges.scalar_law.Scalar` values, element by element of NumPy object
arrays). In float64 the compiled kernels must reproduce torch's stresses, dL/dF and parameter
gradients to round-off, including torch's conventions at the edges (a clamp at its bound, abs
at zero), and pass finite differences.
"""

import gc
import itertools
import math

import numpy as np
import pytest
import torch

from bridges import scalar_law as sl
from taichi_mpm import _compat

EYE = torch.eye(3, dtype=torch.float64)


def _deformations(count: int = 300, seed: int = 0) -> torch.Tensor:
    generator = torch.Generator().manual_seed(seed)
    F = EYE + 0.3 * torch.randn(count, 3, 3, dtype=torch.float64, generator=generator)
    F[0] = EYE  # abs(0) and a clamp exactly at its bound below
    F[1] = -F[1]  # inverted
    return F


def _torch_law(F: torch.Tensor, mu: torch.Tensor, lam: torch.Tensor) -> torch.Tensor:
    J = torch.linalg.det(F)
    logJ = torch.log(J.abs().clamp(min=1e-3))
    B = F @ F.mT
    shear = torch.tanh(B - EYE) * torch.sin(mu) + torch.cos(lam) * (B - EYE).abs()
    bulk = lam * logJ / (1.0 + J * J) + torch.sqrt(J * J + 1.0) - (J - 1.0).clamp(min=0.0) ** 3
    trace = torch.diagonal(B, dim1=-2, dim2=-1).sum(-1)
    gate = torch.where(trace > 3.0, trace - 3.0, torch.zeros_like(trace))
    return mu * shear + (bulk + gate)[:, None, None] * EYE


def _program_law() -> tuple[sl.Program, list]:
    program = sl.Program(9, 2)
    F = np.array(program.inputs, dtype=object).reshape(3, 3)
    mu, lam = program.parameters

    def f(name, *args):
        return sl.apply(name, *args)

    a, b, c, d, e, g, h, i, k = F.reshape(-1)
    J = a * (e * k - g * i) + b * (g * h - d * k) + c * (d * i - e * h)
    magnitude = f("abs", J)
    logJ = f("log", sl.select(f("lt", magnitude, 1e-3), 1e-3, magnitude))
    B = F @ F.T
    strain = B - np.eye(3)
    shear = np.empty((3, 3), dtype=object)
    for r in range(3):
        for s in range(3):
            shear[r, s] = (f("tanh", strain[r, s]) * f("sin", mu)
                           + f("cos", lam) * f("abs", strain[r, s]))  # fmt: skip
    excess = J - 1.0
    clamped = sl.select(f("lt", excess, 0.0), 0.0, excess)
    bulk = lam * logJ / (1.0 + J * J) + f("sqrt", J * J + 1.0) - clamped**3
    trace = B[0, 0] + B[1, 1] + B[2, 2]
    gate = sl.select(f("gt", trace, 3.0), trace - 3.0, 0.0)
    out = mu * shear + (bulk + gate) * np.eye(3)
    return program, list(out.reshape(-1))


@pytest.fixture(scope="module")
def compiled() -> sl.CompiledLaw:
    program, outputs = _program_law()
    return sl.CompiledLaw(program, outputs)


def test_the_kernels_give_torch_s_stresses_and_gradients(compiled):
    F = _deformations()
    mu = torch.tensor(0.7, dtype=torch.float64, requires_grad=True)
    lam = torch.tensor(1.3, dtype=torch.float64, requires_grad=True)
    weights = torch.randn(F.shape, dtype=torch.float64, generator=torch.Generator().manual_seed(1))
    expected = _torch_law(F.requires_grad_(True), mu, lam)
    expected_grads = torch.autograd.grad((expected * weights).sum(), [F, mu, lam])
    F_mine = F.detach().clone().requires_grad_(True)
    actual = sl.apply_law(F_mine, compiled, [mu, lam])
    actual_grads = torch.autograd.grad((actual * weights).sum(), [F_mine, mu, lam])
    torch.testing.assert_close(actual, expected, rtol=1e-10, atol=1e-12)
    for mine, theirs in zip(actual_grads, expected_grads, strict=True):
        torch.testing.assert_close(mine, theirs, rtol=1e-10, atol=1e-10)


def test_the_kernels_pass_finite_differences(compiled):
    F = _deformations(count=6, seed=3).requires_grad_(True)
    mu = torch.tensor(0.7, dtype=torch.float64, requires_grad=True)
    lam = torch.tensor(1.3, dtype=torch.float64, requires_grad=True)
    F.data[0] += 0.01  # away from the clamp's kink, where finite differences straddle it
    assert torch.autograd.gradcheck(lambda F, mu, lam: sl.apply_law(F, compiled, [mu, lam]),
                                    (F, mu, lam), eps=1e-6, atol=1e-6)  # fmt: skip


def test_a_parameter_only_compared_gets_no_gradient_as_in_torch():
    program = sl.Program(9, 2)
    scale, threshold = program.parameters
    F = program.inputs
    outputs = [sl.select(sl.apply("gt", x, threshold), scale * x, x) for x in F]
    law = sl.CompiledLaw(program, outputs)
    assert law.constant_zero == [False, True]
    parameters = [torch.tensor(2.0, dtype=torch.float64, requires_grad=True),
                  torch.tensor(1.0, dtype=torch.float64, requires_grad=True)]  # fmt: skip
    stress = sl.apply_law(_deformations(count=4), law, parameters)
    grads = torch.autograd.grad(stress.sum(), parameters, allow_unused=True)
    assert grads[0] is not None and grads[1] is None


def test_a_law_without_parameters_and_constant_outputs():
    program = sl.Program(9, 0)
    outputs = [x * 2.0 for x in program.inputs[:8]] + [1.5]
    law = sl.CompiledLaw(program, outputs)
    F = _deformations(count=5).requires_grad_(True)
    stress = sl.apply_law(F, law, [])
    expected = torch.cat([2.0 * F.detach().reshape(5, 9)[:, :8],
                          torch.full((5, 1), 1.5, dtype=torch.float64)], 1)  # fmt: skip
    torch.testing.assert_close(stress.reshape(5, 9), expected)
    (grad,) = torch.autograd.grad(stress.sum(), [F])
    assert torch.equal(grad.reshape(5, 9)[:, :8], torch.full((5, 8), 2.0, dtype=torch.float64))
    assert torch.equal(grad.reshape(5, 9)[:, 8], torch.zeros(5, dtype=torch.float64))


def test_a_collected_law_leaves_its_kernels_out_of_taichi_s_runtime():
    kernels = _compat.runtime_kernels()
    before = len(kernels)
    program = sl.Program(9, 1)
    law = sl.CompiledLaw(program, [x * program.parameters[0] for x in program.inputs])
    assert len(kernels) == before + 4  # forward and reverse, each with Taichi's adjoint
    listed = [id(k) for k in kernels[before:]]
    del law
    gc.collect()
    assert len(kernels) == before and not set(listed) & {id(k) for k in kernels}


def test_constants_fold_and_equal_operations_are_made_once():
    program = sl.Program(9, 0)
    x = program.inputs[0]
    assert sl.apply("add", 2.0, 3.0) == 5.0
    assert (x + 1.0) is (x + 1.0)
    assert x * 1.0 is x and x + 0.0 is x
    with pytest.raises(TypeError, match="no truth value"):
        bool(x > 0.0)


# ------------------------------------------------------------------ the table of operations

#: Every operation of one value that folds on constants: what the element-wise ones are.
ELEMENTWISE = {name: op for name, op in sl.OPERATIONS.items() if op.outputs == 1 and op.fold}


def _cases() -> list[tuple[str, tuple]]:
    """Each element-wise operation on every choice of its arguments among three inputs (x0,
    x1 in [0.5, 2], x2 = 0: both branches of a select, a zero for and/or), a constant 2.5
    where it takes a constant; each case as (name, the inputs' indices or the constant)."""
    return [(name, args) for name, op in ELEMENTWISE.items()
            for args in itertools.product(*[[2.5] if k in op.constants else [0, 1, 2]
                                            for k in range(op.arity)])]  # fmt: skip


def _value(name: str, args: tuple, x: list[float]) -> float:
    """The operation's fold on the row ``x``: Python's IEEE double."""
    return sl.apply(name, *[a if isinstance(a, float) else x[a] for a in args])


def _central_differences(name: str, args: tuple, x: list[float], h: float = 1e-6) -> list:
    """d/dx0 and d/dx1 of the operation's fold at the row ``x``."""
    grads = []
    for k in range(2):
        plus, minus = list(x), list(x)
        plus[k] += h
        minus[k] -= h
        grads.append((_value(name, args, plus) - _value(name, args, minus)) / (2 * h))
    return grads


def _compiled(cases: list[tuple[str, tuple]]) -> sl.CompiledLaw:
    program = sl.Program(9, 0)
    return sl.CompiledLaw(program, [
        sl.apply(name, *[a if isinstance(a, float) else program.inputs[a] for a in args])
        for name, args in cases
    ])  # fmt: skip


@pytest.fixture(scope="module")
def rows() -> torch.Tensor:
    """x0, x1 in [0.5, 2], x2 = 0 (and the rest)."""
    rows = torch.zeros(5, 9, dtype=torch.float64)
    generator = torch.Generator().manual_seed(4)
    rows[:, :2] = 0.5 + 1.5 * torch.rand(5, 2, generator=generator, dtype=torch.float64)
    return rows


def test_every_operation_s_kernel_computes_its_fold(rows):
    """One entry of the table is one operation: its Taichi code computes its fold."""
    cases = _cases()
    out = _compiled(cases).forward(rows, sl.flat_parameters([], rows))
    expected = torch.tensor([[_value(name, args, row.tolist()) for name, args in cases]
                             for row in rows], dtype=torch.float64)  # fmt: skip
    # where x2 = 0 makes a fold infinite or NaN, Taichi's fast math may differ (x2 / x2 is 1)
    finite = expected.isfinite()
    assert finite.float().mean() > 0.9
    torch.testing.assert_close(out[:, : len(cases)][finite], expected[finite], rtol=1e-12,
                               atol=1e-12)  # fmt: skip


def test_every_operation_s_derivative_is_its_fold_s_central_differences(rows):
    """The reverse kernel's dL/dx0 and dL/dx1 of each case on its own (one row per row and
    case, its seed one-hot), where the fold is smooth in x0 and x1 on every row (a division
    by x2 = 0 is left out: its infinite local derivative, times a zero seed, would make every
    other case's gradient NaN in the same reverse)."""
    numeric = {case: [_central_differences(*case, row.tolist()) for row in rows]
               for case in _cases()}  # fmt: skip
    cases = [case for case, grads in numeric.items() if math.isfinite(sum(sum(grads, [])))]
    assert len(cases) > 0.9 * len(numeric)
    law = _compiled(cases)
    flat = sl.flat_parameters([], rows)
    saved = law.forward(rows, flat)[:, len(cases) :].repeat_interleave(len(cases), 0)
    seeds = torch.eye(len(cases), dtype=torch.float64).repeat(len(rows), 1)
    dx, _ = law.backward(rows.repeat_interleave(len(cases), 0), flat, saved, seeds)
    expected = torch.tensor([numeric[case] for case in cases], dtype=torch.float64).transpose(0, 1)
    torch.testing.assert_close(dx[:, :2].reshape(len(rows), len(cases), 2), expected, rtol=0,
                               atol=1e-6)  # fmt: skip


def test_every_aten_overload_of_the_table_is_one_of_aten():
    for name, op in sl.OPERATIONS.items():
        for overload in op.aten:
            namespace, packet, kind = overload.split(".")
            assert namespace == "aten" and hasattr(getattr(torch.ops.aten, packet), kind), name
