"""Symbolic regression against the search on task (a), ``elastic``: the paper's Table 2.

The paper turns task (a) into a regression problem: deformation gradients F (9 inputs) and the
ground-truth law's stress (9 outputs), each output fitted on its own. Here the samples are the
per-particle F of the ground-truth trajectory at its teacher-forcing reset steps (step 0, where
every F is the identity, left out), and the target is the Kirchhoff stress tau = P F^T that the
task's law returns, from the project's neo-Hookean law (:class:`bridges.laws.NeoHookean` with
the task's E and nu) in float64. Fitted on a random train split, scored on the rest:

* Operon (``pyoperon``) and FFX (``ffx``): one expression per stress component;
* an MLP (scikit-learn ``MLPRegressor``): one network with 9 outputs, inputs and targets
  standardized;
* the laws found by ``sga-agent search --task elastic`` (``--run``; without one a search with
  the built-in genetic programming is run first), rebuilt from their captured graphs
  (:func:`tasks.constitutive.law_graph.build_law`, no candidate code runs) with their fitted
  parameters;
* the true law itself, as a reference (its R2 is 1 by construction).

Each fit is then put back into the simulator as the elastic law and scored like a candidate
with zero epochs (no fitting): the teacher-forced trajectory loss against the ground truth. A
law whose simulation leaves the finite numbers is reported as unstable. Needs the ``sr`` extra
(``pip install -e ".[sr]"``). Run from the repository root::

    python benchmarks/symbolic_regression.py --out-dir sr_out          # a GP search first
    python benchmarks/symbolic_regression.py --run runs/elastic-...    # a recorded search
    python benchmarks/symbolic_regression.py --quick --out-dir /tmp/sr  # CI size, 200 steps

Writes ``table.md`` and ``results.json`` to ``--out-dir`` and prints the table.
"""

from __future__ import annotations

import argparse
import ast
import json
import math
import os
import re
import subprocess
import sys
import time
import warnings
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

REPOSITORY = Path(__file__).resolve().parents[1]
if str(REPOSITORY) not in sys.path:  # run as a script: the checkout's packages first
    sys.path.insert(0, str(REPOSITORY))

import taichi_mpm as tm  # noqa: E402
from bridges import laws as torch_laws  # noqa: E402
from bridges.rollout import LawError, Rollout  # noqa: E402
from bridges.step import torch_dtype  # noqa: E402
from tasks.constitutive.evaluation import ensure_runtime, ground_truth  # noqa: E402
from tasks.constitutive.ground_truth import Trajectory  # noqa: E402
from tasks.constitutive.inner import InnerSettings, NoFiniteEpoch, optimize  # noqa: E402
from tasks.constitutive.law_graph import build_law  # noqa: E402
from tasks.constitutive.specs import ELASTIC_TRUTH, SPECS, ConstitutiveSpec  # noqa: E402

METHODS = ("operon", "ffx", "mlp")
#: Operon's function set: the arithmetic of its default plus what the true law needs (log).
OPERON_SYMBOLS = "add,sub,mul,div,square,sqrt,exp,log,constant,variable"


@dataclass(frozen=True)
class Budget:
    """Sizes of one comparison: samples, scene length, the SR budgets, the search's."""

    samples: int
    steps: int
    operon_generations: int
    operon_population: int
    operon_max_length: int
    mlp_hidden: tuple[int, ...]
    mlp_iterations: int
    search: tuple[str, ...]  # settings of the search run when no --run is given


FULL = Budget(
    samples=3000,
    steps=1000,
    operon_generations=200,
    operon_population=1000,
    operon_max_length=50,
    mlp_hidden=(64, 64),
    mlp_iterations=2000,
    search=(),  # the built-in proposer's quick preset: 4 iterations of 6, 5 epochs each
)
QUICK = Budget(
    samples=240,
    steps=200,
    operon_generations=10,
    operon_population=100,
    operon_max_length=30,
    mlp_hidden=(16,),
    mlp_iterations=300,
    search=(
        "--iterations",
        "1",
        "--exploit",
        "0",
        "--explore",
        "1",
        "--epochs",
        "1",
        "--workers",
        "1",
        "--option",
        "steps=200",
    ),
)


@dataclass
class Samples:
    """Flattened deformation gradients (n, 9) and Kirchhoff stresses (n, 9), split."""

    F_train: np.ndarray
    tau_train: np.ndarray
    F_test: np.ndarray
    tau_test: np.ndarray
    pool: int  # deformation gradients the samples were drawn from


@dataclass
class Row:
    """One method's line of the table (and of the JSON)."""

    method: str
    symbolic: bool
    r2: float = math.nan
    mse: float = math.nan
    mae: float = math.nan
    non_finite: int = 0  # test predictions that are NaN or infinite
    trajectory_loss: float = math.nan
    trajectory: str = ""  # "ok", "unstable (step N): why" or why the law failed
    fit_seconds: float = math.nan
    torch_error: float = 0.0  # max |torch law - library prediction| / std(target), test split
    expressions: list[str] = field(default_factory=list)
    notes: dict[str, Any] = field(default_factory=dict)


# ------------------------------------------------------------------------------- samples


def sample(observed: Trajectory, count: int, test_fraction: float, seed: int) -> Samples:
    """``count`` F of the reset states after step 0 with their true stress, split at random."""
    F = observed.states["F"][1:].reshape(-1, 3, 3).astype(np.float64)
    pool = len(F)
    if pool == 0:
        raise SystemExit("the scene has no reset state after step 0: give more --steps")
    rng = np.random.default_rng(seed)
    chosen = rng.choice(pool, size=min(count, pool), replace=False)
    F = F[chosen]
    tau = true_law(torch.float64)(torch.from_numpy(F)).detach().numpy()
    X, Y = F.reshape(-1, 9), tau.reshape(-1, 9)
    split = len(X) - max(1, round(test_fraction * len(X)))
    return Samples(X[:split], Y[:split], X[split:], Y[split:], pool)


def true_law(dtype: torch.dtype) -> nn.Module:
    """The ground truth of ``elastic``: the project's neo-Hookean law, frozen."""
    return torch_laws.NeoHookean(**ELASTIC_TRUTH, dtype=dtype).requires_grad_(False)


def scores(predicted: np.ndarray, target: np.ndarray) -> dict[str, float]:
    """R2, MSE and MAE over all 9 components pooled (NaN when a prediction is not finite)."""
    error = predicted - target
    residual = float((error**2).sum())
    total = float(((target - target.mean()) ** 2).sum())
    return {
        "r2": 1.0 - residual / total,
        "mse": float((error**2).mean()),
        "mae": float(np.abs(error).mean()),
    }


# ------------------------------------------------------------------ laws from the fits


class ComponentLaw(nn.Module):
    """Kirchhoff stress from 9 scalar functions of the 9 entries of F (row-major)."""

    def __init__(self, components: list[Callable[[list[torch.Tensor]], torch.Tensor]]) -> None:
        super().__init__()
        self.components = components

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        x = list(F.reshape(-1, 9).unbind(-1))
        columns = [torch.broadcast_to(c(x), x[0].shape).to(F.dtype) for c in self.components]
        return torch.stack(columns, -1).reshape(F.shape)


_BINARY = {
    ast.Add: torch.add,
    ast.Sub: torch.sub,
    ast.Mult: torch.mul,
    ast.Div: torch.div,
    ast.Pow: torch.pow,
    ast.BitXor: torch.pow,  # Operon writes powers as a ^ b
}
_FUNCTIONS = {
    "log": torch.log,
    "exp": torch.exp,
    "sqrt": torch.sqrt,
    "abs": torch.abs,
    "square": torch.square,
    "sin": torch.sin,
    "cos": torch.cos,
    "tanh": torch.tanh,
}


def expression_function(text: str, variables: dict[str, int]) -> Callable:
    """A torch function of the columns of F for an infix expression; only numbers, the named
    variables, + - * / ^ and the functions above are accepted (the text is never executed)."""

    def build(node: ast.AST) -> Callable[[list[torch.Tensor]], torch.Tensor]:
        if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
            op, left, right = _BINARY[type(node.op)], build(node.left), build(node.right)
            return lambda x: op(left(x), right(x))
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub | ast.UAdd):
            operand, sign = build(node.operand), -1.0 if isinstance(node.op, ast.USub) else 1.0
            return lambda x: sign * operand(x)
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and len(node.args) == 1:
            function, argument = _FUNCTIONS.get(node.func.id), build(node.args[0])
            if function is not None and not node.keywords:
                return lambda x: function(argument(x))
        if isinstance(node, ast.Name) and node.id in variables:
            index = variables[node.id]
            return lambda x: x[index]
        if isinstance(node, ast.Constant) and type(node.value) in (int, float):
            value = float(node.value)
            return lambda x: torch.full_like(x[0], value)
        raise ValueError(f"unsupported part of the expression: {ast.dump(node)[:80]}")

    return build(ast.parse(text, mode="eval").body)


def ffx_function(model: Any) -> Callable[[list[torch.Tensor]], torch.Tensor]:
    """FFX's model (offset + sum of coefficient * basis, over 1 + the same for a denominator),
    computed from its bases in torch, operator for operator as FFX's ``simulate``."""
    from ffx.core import (
        OP_ABS,
        OP_GTH,
        OP_LOG10,
        OP_LTH,
        OP_MAX0,
        OP_MIN0,
        ConstantModel,
        OperatorBase,
        ProductBase,
        SimpleBase,
    )

    def basis(base: Any, x: list[torch.Tensor]) -> torch.Tensor:
        if isinstance(base, SimpleBase):
            return x[base.var] ** float(base.exponent)
        if isinstance(base, ProductBase):
            return basis(base.base1, x) * basis(base.base2, x)
        if isinstance(base, OperatorBase):
            inner = basis(base.simple_base, x)
            operators = {
                OP_ABS: torch.abs,
                OP_LOG10: torch.log10,
                OP_MAX0: lambda v: v.clamp(min=0.0),
                OP_MIN0: lambda v: v.clamp(max=0.0),
                OP_GTH: lambda v: (float(base.thr) - v).clamp(min=0.0),
                OP_LTH: lambda v: (v - float(base.thr)).clamp(min=0.0),
            }
            return operators[base.nonlin_op](inner)
        raise ValueError(f"unknown FFX basis {type(base).__name__}")

    def function(x: list[torch.Tensor]) -> torch.Tensor:
        if isinstance(model, ConstantModel):
            return torch.full_like(x[0], float(model.constant))
        value = float(model.coefs_n[0]) + sum(
            float(c) * basis(b, x) for c, b in zip(model.coefs_n[1:], model.bases_n, strict=True)
        )
        if model.bases_d:
            value = value / (
                1.0
                + sum(
                    float(c) * basis(b, x)
                    for c, b in zip(model.coefs_d, model.bases_d, strict=True)
                )
            )
        return value

    return function


class MLPLaw(nn.Module):
    """A fitted scikit-learn MLP (standardized inputs and targets) as torch operations, in the
    dtype of the F it is given."""

    def __init__(self, x_mean, x_scale, weights, biases, y_mean, y_scale, activation: str):
        super().__init__()
        self.layers = len(weights)
        named = {
            "x_mean": x_mean,
            "x_scale": x_scale,
            "y_mean": y_mean,
            "y_scale": y_scale,
            **{f"weight{i}": w for i, w in enumerate(weights)},
            **{f"bias{i}": b for i, b in enumerate(biases)},
        }
        for name, value in named.items():
            self.register_buffer(name, torch.as_tensor(value, dtype=torch.float64))
        self.activation = {
            "tanh": torch.tanh,
            "relu": torch.relu,
            "logistic": torch.sigmoid,
            "identity": lambda v: v,
        }[activation]

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        buffer = {name: value.to(F.dtype) for name, value in self.named_buffers()}
        h = (F.reshape(-1, 9) - buffer["x_mean"]) / buffer["x_scale"]
        for index in range(self.layers):
            h = h @ buffer[f"weight{index}"] + buffer[f"bias{index}"]
            if index < self.layers - 1:
                h = self.activation(h)
        return (h * buffer["y_scale"] + buffer["y_mean"]).reshape(F.shape)


# ---------------------------------------------------------------------------- the fits


@dataclass
class Fit:
    """A fitted method: its torch law, the library's own test predictions, its expressions."""

    law: nn.Module
    predicted: np.ndarray  # the library's own predictions on the test split
    expressions: list[str]
    seconds: float
    notes: dict[str, Any] = field(default_factory=dict)


def fit_operon(data: Samples, budget: Budget, seed: int) -> Fit:
    """One Operon expression per component: single-objective GP on R2, 5 Levenberg-Marquardt
    iterations on each tree's constants, the result linearly scaled to the target."""
    from pyoperon.sklearn import SymbolicRegressor

    started = time.perf_counter()
    functions, expressions, predicted = [], [], []
    names = {f"X{i + 1}": i for i in range(9)}  # Operon's variable names
    for component in range(9):
        model = SymbolicRegressor(
            allowed_symbols=OPERON_SYMBOLS,
            generations=budget.operon_generations,
            population_size=budget.operon_population,
            max_length=budget.operon_max_length,
            optimizer_iterations=5,
            random_state=seed + component,
            n_threads=1,
        )
        model.fit(data.F_train, data.tau_train[:, component])
        text = model.get_model_string(model.model_, 17)
        functions.append(expression_function(text, names))
        expressions.append(model.get_model_string(model.model_, 4))
        predicted.append(model.predict(data.F_test))
        progress(f"operon: component {component + 1}/9")
    law = ComponentLaw(functions)
    return Fit(law, np.stack(predicted, -1), expressions, time.perf_counter() - started)


def fit_ffx(data: Samples, seed: int) -> Fit:
    """One FFX model per component: its Pareto front is built on 80% of the train split and
    the front's model with the least error on the other 20% is kept."""
    import ffx

    started = time.perf_counter()
    order = np.random.default_rng(seed).permutation(len(data.F_train))
    cut = int(0.8 * len(order))
    fit_rows, check_rows = order[:cut], order[cut:]
    names = [f"F{i // 3}{i % 3}" for i in range(9)]
    functions, expressions, predicted = [], [], []
    for component in range(9):
        y = data.tau_train[:, component]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # ElasticNet's convergence warnings, by the hundred
            front = ffx.run(
                data.F_train[fit_rows], y[fit_rows], data.F_train[check_rows], y[check_rows], names
            )
        model = min(front, key=lambda m: m.test_nmse)
        functions.append(ffx_function(model))
        expressions.append(str(model))
        predicted.append(model.simulate(data.F_test))
        progress(f"ffx: component {component + 1}/9")
    law = ComponentLaw(functions)
    return Fit(law, np.stack(predicted, -1), expressions, time.perf_counter() - started)


def fit_mlp(data: Samples, budget: Budget, seed: int) -> Fit:
    """One MLP for the 9 components (tanh, Adam), on standardized inputs and targets."""
    from sklearn.compose import TransformedTargetRegressor
    from sklearn.neural_network import MLPRegressor
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    started = time.perf_counter()
    network = MLPRegressor(
        hidden_layer_sizes=budget.mlp_hidden,
        activation="tanh",
        max_iter=budget.mlp_iterations,
        tol=1e-7,
        random_state=seed,
    )
    model = TransformedTargetRegressor(
        make_pipeline(StandardScaler(), network), transformer=StandardScaler()
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a budget that stops before convergence says so
        model.fit(data.F_train, data.tau_train)
    scaler, fitted = model.regressor_[0], model.regressor_[1]
    law = MLPLaw(
        scaler.mean_,
        scaler.scale_,
        fitted.coefs_,
        fitted.intercepts_,
        model.transformer_.mean_,
        model.transformer_.scale_,
        fitted.activation,
    )
    notes = {"hidden": list(budget.mlp_hidden), "iterations": int(fitted.n_iter_)}
    return Fit(law, model.predict(data.F_test), [], time.perf_counter() - started, notes)


# ---------------------------------------------------------------- laws from search runs


def search(out_dir: Path, budget: Budget, seed: int) -> Path:
    """Run ``sga-agent search --task elastic --model builtin`` into ``out_dir``; its folder."""
    command = [sys.executable, "-m", "sga_agent", "search", "--task", "elastic"]
    command += ["--model", "builtin", "--seed", str(seed), "--json", "--out-dir", str(out_dir)]
    command += ["--option", f"steps={budget.steps}", *budget.search]
    path = os.pathsep.join(filter(None, [str(REPOSITORY), os.environ.get("PYTHONPATH")]))
    env = {**os.environ, "PYTHONPATH": path, "LITELLM_LOCAL_MODEL_COST_MAP": "True"}
    progress("search: " + " ".join(command[1:]))
    done = subprocess.run(command, env=env, capture_output=True, text=True, check=False)
    lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
    if done.returncode != 0 or not lines:
        raise SystemExit(f"the search failed (exit {done.returncode}):\n{done.stderr[-3000:]}")
    return Path(json.loads(lines[-1])["run"])


def run_law(run: Path, dtype: torch.dtype) -> tuple[nn.Module, dict[str, Any]]:
    """The best law of a recorded search, rebuilt from its captured graph (no candidate code
    runs) with its fitted parameters, and what the run says about it."""
    summary = json.loads((run / "summary.json").read_text())
    if not summary.get("best"):
        raise SystemExit(f"{run}: the search found no valid law")
    candidate = summary["best"]["candidate"]
    folder = run / "candidates" / candidate
    evaluation = json.loads((folder / "evaluation.json").read_text())
    artifacts = json.loads((folder / "artifacts.json").read_text())
    law = build_law(artifacts["captured"]["law"], dtype)
    fitted = evaluation["parameters"]
    with torch.no_grad():
        for name, parameter in law.named_parameters():
            if name in fitted:
                parameter.fill_(fitted[name])
            else:  # a tensor parameter: name[i] per element
                flat = [fitted[f"{name}[{i}]"] for i in range(parameter.numel())]
                parameter.copy_(torch.tensor(flat, dtype=dtype).reshape(parameter.shape))
    config = json.loads((run / "config.json").read_text())
    notes = {
        "run": str(run),
        "candidate": candidate,
        "proposer": config.get("proposer"),
        "recorded_loss": evaluation["loss"],
        "parameters": fitted,
        "task_options": config["config"].get("task_options", {}),
    }
    return law.requires_grad_(False), notes


# --------------------------------------------------------------------------- simulation


def trajectory(law: nn.Module, observed: Trajectory, spec: ConstitutiveSpec) -> tuple[float, str]:
    """The task's trajectory loss of ``law`` as the elastic law, fitted for zero epochs."""
    scene = tm.paper_scene(steps=observed.positions.shape[0] - 1)
    rollout = Rollout(scene, torch_laws.NoPlasticity(), law)
    try:
        result = optimize(
            rollout, law, observed, InnerSettings(epochs=0, reset_every=spec.reset_every)
        )
    except NoFiniteEpoch as error:  # "... non-finite at step 57" or "... at the initial state"
        step = re.search(r"at step (\d+)", str(error))
        return math.nan, f"unstable (step {step.group(1) if step else 0}): {error}"
    except LawError as error:
        return math.nan, f"rejected: {str(error).splitlines()[0][:120]}"
    except Exception as error:  # the law failing inside the simulation (e.g. an SVD of NaN)
        return math.nan, f"failed: {type(error).__name__}: {str(error).splitlines()[0][:100]}"
    return result.best_loss, "ok"


def row_for(
    name: str,
    symbolic: bool,
    laws: Callable[[torch.dtype], nn.Module],
    data: Samples,
    observed: Trajectory,
    spec: ConstitutiveSpec,
    fit: Fit | None = None,
) -> Row:
    """Score the law ``laws(dtype)`` on the test split (float64) and in the simulator (the
    running Taichi's dtype)."""
    with torch.no_grad():
        F = torch.from_numpy(data.F_test.reshape(-1, 3, 3))
        predicted = laws(torch.float64)(F).numpy().reshape(-1, 9)
    row = Row(name, symbolic)
    row.non_finite = int((~np.isfinite(predicted)).any(-1).sum())
    if row.non_finite == 0:
        row.r2, row.mse, row.mae = scores(predicted, data.tau_test).values()
    if fit is not None:
        row.fit_seconds, row.expressions, row.notes = fit.seconds, fit.expressions, fit.notes
        gap = np.abs(predicted - fit.predicted)
        row.torch_error = float(np.nanmax(gap) / data.tau_test.std())
    progress(f"{name}: trajectory")
    row.trajectory_loss, row.trajectory = trajectory(laws(torch_dtype()), observed, spec)
    return row


# ------------------------------------------------------------------------------- output


def number(value: float) -> str:
    return (
        "n/a"
        if not math.isfinite(value)
        else f"{value:.4g}"
        if abs(value) < 1e4
        else f"{value:.2e}"
    )


def markdown(rows: list[Row]) -> str:
    """Table 2's columns, plus the trajectory loss and the fitting time."""
    lines = [
        "| method | symbolic | R² ↑ | MSE ↓ | MAE ↓ | trajectory loss ↓ | fit (s) |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        r2 = f"{row.r2:.6f}" if math.isfinite(row.r2) else f"n/a ({row.non_finite} non-finite)"
        loss = number(row.trajectory_loss) if row.trajectory == "ok" else row.trajectory
        loss = loss.split(":")[0]  # the reason is in the JSON
        fit = "" if math.isnan(row.fit_seconds) else f"{row.fit_seconds:.0f}"
        lines.append(
            f"| {row.method} | {'yes' if row.symbolic else 'no'} | {r2} | "
            f"{number(row.mse)} | {number(row.mae)} | {loss} | {fit} |"
        )
    return "\n".join(lines) + "\n"


def progress(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def labelled(text: str) -> tuple[str | None, Path]:
    """``LABEL=DIR`` or ``DIR``."""
    label, separator, folder = text.partition("=")
    return (label, Path(folder)) if separator else (None, Path(text))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="CI size: 200 steps, tiny budgets")
    parser.add_argument(
        "--run",
        action="append",
        default=[],
        metavar="[LABEL=]DIR",
        help="a recorded `sga-agent search --task elastic` folder (repeatable); "
        "without one a built-in GP search is run",
    )
    parser.add_argument("--methods", default=",".join(METHODS), help="of " + ",".join(METHODS))
    parser.add_argument("--samples", type=int, help="F samples, train and test together")
    parser.add_argument("--steps", type=int, help="scene steps (task option steps)")
    parser.add_argument("--test-fraction", type=float, default=0.25)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out-dir", type=Path, default=Path("sr_out"))
    args = parser.parse_args(argv)
    methods = [m for m in args.methods.split(",") if m]
    if unknown := set(methods) - set(METHODS):
        parser.error(f"unknown methods: {', '.join(sorted(unknown))}")
    base = QUICK if args.quick else FULL
    budget = Budget(
        **{
            **asdict(base),
            "samples": args.samples or base.samples,
            "steps": args.steps or base.steps,
        }
    )
    if budget.steps <= SPECS["elastic"].reset_every:
        parser.error(f"--steps must exceed {SPECS['elastic'].reset_every} (a reset state after 0)")
    args.out_dir.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()

    spec = SPECS["elastic"]
    ensure_runtime("float32")
    observed = ground_truth(spec, budget.steps)
    data = sample(observed, budget.samples, args.test_fraction, args.seed)
    progress(f"{len(data.F_train)} train and {len(data.F_test)} test samples of {data.pool} F")

    rows = [row_for("neo-Hookean (ground truth)", True, true_law, data, observed, spec)]
    fitters = {
        "operon": ("Operon", True, lambda: fit_operon(data, budget, args.seed)),
        "ffx": ("FFX", True, lambda: fit_ffx(data, args.seed)),
        "mlp": ("MLP", False, lambda: fit_mlp(data, budget, args.seed)),
    }
    for method in methods:
        name, symbolic, fitter = fitters[method]
        fit = fitter()
        rows.append(row_for(name, symbolic, lambda _, law=fit.law: law, data, observed, spec, fit))
    runs = [labelled(text) for text in args.run] or [
        (None, search(args.out_dir / "runs", budget, args.seed))
    ]
    for label, run in runs:
        notes = run_law(run, torch.float64)[1]
        row = row_for(
            f"sga-agent search ({label or notes['proposer']})",
            True,
            lambda dtype, run=run: run_law(run, dtype)[0],
            data,
            observed,
            spec,
        )
        row.notes = notes
        rows.append(row)

    table = markdown(rows)
    (args.out_dir / "table.md").write_text(table)
    result = {
        "command": " ".join(["benchmarks/symbolic_regression.py", *(argv or sys.argv[1:])]),
        "budget": asdict(budget),
        "target": "Kirchhoff stress tau = P F^T of bridges.laws.NeoHookean(E=e^13, nu=0.245), "
        "float64; inputs: the 9 entries of F (row-major)",
        "samples": {"train": len(data.F_train), "test": len(data.F_test), "pool": data.pool},
        "seconds": time.perf_counter() - started,
        "rows": [asdict(row) for row in rows],
    }
    (args.out_dir / "results.json").write_text(json.dumps(result, indent=2, default=str) + "\n")
    print(table, end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
