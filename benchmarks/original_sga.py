"""Drive the original SGA implementation (github.com/PingchuanMa/SGA, Warp + torch) on the CPU.

Run with a Python that has the original's requirements (warp-lang 1.1.0, torch, numpy < 2,
pyyaml, tqdm, tensorboard) and ``SGA_ORIGINAL`` set to a checkout of that repository.
``benchmarks/evaluate_speed.py --original`` starts it; by hand::

    SGA_ORIGINAL=~/SGA python original_sga.py dataset elastic DATA
    SGA_ORIGINAL=~/SGA python original_sga.py epoch elastic 3 --data DATA

``dataset`` writes the original's own ground truth (its eval.py with ``is_dataset``, no
rendering). ``epoch`` times the loop body of its train.py: 1000 steps with teacher forcing every
100, the position loss, backward, gradient clipping, one Adam step, and prints one JSON line.
The only departure from the original's code path is the device (``cpu`` for ``cuda:N``); its
renderer and LLM-client modules are replaced by empty ones, which the loop never uses. Nothing
of the original is copied here: it is imported from its checkout.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import sys
import time
import types
from pathlib import Path

#: Which of the original's physics templates each benchmark law uses, the template values that
#: put it 2x off, and its dataset (the ground truth's template).
LAWS = {
    "elastic": ("neohookean", {"youngs_modulus_log": 13.0 + math.log(2.0),
                               "poissons_ratio_sigmoid": math.log(1 / 3)}, "neohookean"),
    "plasticine": ("plasticine", {"yield_stress": 6e4}, "plasticine"),
}  # fmt: skip


def import_original():
    """Import the original's ``sga`` package from ``$SGA_ORIGINAL``, on the CPU."""
    checkout = os.environ.get("SGA_ORIGINAL")
    if not checkout:
        sys.exit("set SGA_ORIGINAL to a checkout of github.com/PingchuanMa/SGA")
    sys.path.insert(0, checkout)
    for unused in ("sga.renderer", "sga.agent"):  # VTK and the LLM clients: not needed here
        sys.modules[unused] = types.ModuleType(unused)
    import sga
    import torch
    import warp as wp

    torch.set_num_threads(1)
    wp.config.quiet = True
    wp.init()
    wp.set_module_options({"fast_math": True})  # as the original's train.py
    for replace in ("svd", "polar", "trace", "cbrt"):
        getattr(sga.warp, f"replace_torch_{replace}")()
    torch.set_default_device("cpu")
    return sga, torch, wp


def physics_module(sga, config, overrides: dict, path: Path):
    """The original's Physics class from its template, with ``overrides`` filled in."""
    values = dict(vars(config)) | overrides
    source = Path(config.path).read_text().format(**values)
    path.write_text(source)
    return sga.utils.get_class_from_path(str(path), "Physics")()


def scene(sga, wp, sim_config, env_config, requires_grad: bool):
    """The original's model, statics and (for datasets) initial state."""
    from sga.sim import MPMInitData, MPMModelBuilder, MPMStateInitializer, MPMStaticsInitializer

    model = MPMModelBuilder().parse_cfg(sim_config).finalize("cpu", requires_grad=requires_grad)
    data = MPMInitData.get(env_config)
    data.set_lin_vel(env_config.vel.lin_vel)
    data.set_ang_vel(env_config.vel.ang_vel)
    statics = MPMStaticsInitializer(model)
    statics.add_group(data)
    states = MPMStateInitializer(model)
    states.add_group(data)
    return model, statics.finalize(), states


def make_dataset(law: str, out: Path) -> None:
    """Write the ground truth of ``law``'s dataset as the original's StateRecorder does."""
    sga, torch, wp = import_original()
    from sga.sim import MPMForwardSim, SigmaElasticity

    config = sga.config.EvalConfig(path=str(out))
    config.update([f"--physics.env.physics={LAWS[law][2]}"])
    (out / "state").mkdir(parents=True, exist_ok=True)
    with torch.no_grad():
        physics = physics_module(sga, config.physics.env.physics, {}, out / "physics.py").eval()
        elasticity = SigmaElasticity().eval() if law == "plasticine" else None
        model, statics, states = scene(sga, wp, config.physics.sim, config.physics.env, False)
        state, _ = states.finalize()
        simulate = MPMForwardSim(model, statics)
        x, v, C, F, stress = state.to_torch()
        recorder = sga.utils.StateRecorder()
        recorder.add_hyper(key_indices=config.physics.env.shape.key_indices)
        recorder.add(x=x, v=v, F=F, C=C, stress=stress)
        for _ in range(config.physics.sim.num_steps):
            F = physics(F) if elasticity is not None else F
            stress = elasticity(F) if elasticity is not None else physics(F)
            state.from_torch(F=F, stress=stress)
            x, v, C, F = simulate(state)
            recorder.add(x=x, v=v, F=F, C=C, stress=stress)
    recorder.save(out / "state" / "ckpt.pt")


def time_epochs(law: str, epochs: int, warmup: int, data: Path, work: Path) -> dict:
    """Seconds of each epoch of the original's inner loop (after ``warmup`` untimed ones)."""
    started = time.perf_counter()
    sga, torch, wp = import_original()
    from sga.sim import MPMCacheDiffSim, MPMDataset, SigmaElasticity

    template, overrides, dataset_name = LAWS[law]
    plastic = law == "plasticine"
    config = sga.config.TrainConfig(path=str(work), dataset_path=str(data / dataset_name))
    config.update([f"--physics.env.physics={template}"])
    steps, teacher_every = config.physics.sim.num_steps, config.optim.num_teacher_steps
    alpha = 1e5 if plastic else 1e4  # position-loss weights of the original's invent scripts
    model, statics, _ = scene(sga, wp, config.physics.sim, config.physics.env, True)
    simulate = MPMCacheDiffSim(model, statics, num_steps=steps)
    work.mkdir(parents=True, exist_ok=True)
    physics = physics_module(sga, config.physics.env.physics, overrides, work / f"physics_{law}.py")
    elasticity = SigmaElasticity().eval().requires_grad_(False) if plastic else None
    optimizer = torch.optim.Adam(physics.parameters(), lr=config.optim.lr)
    dataset = MPMDataset(Path(config.dataset_path), "cpu")
    setup_s = time.perf_counter() - started
    seconds, losses = [], []
    for _ in range(warmup + epochs):
        tick = time.perf_counter()
        loss = 0.0
        x_obs, v_obs, C_obs, F_obs, _ = dataset[0]
        physics.train()
        for step in range(steps):
            if step % teacher_every == 0:
                x, v, C, F = x_obs, v_obs, C_obs, F_obs
            if plastic:
                F = physics(F)
                stress = elasticity(F)
            else:
                stress = physics(F)
            x, v, C, F = simulate(step, x, v, C, F, stress)
            x_obs, v_obs, C_obs, F_obs, _ = dataset[step + 1]
            loss += sga.utils.loss_fn(x, x_obs) / steps * alpha
            sga.utils.loss_fn(v, v_obs).item()  # train.py logs the velocity loss every step
        losses.append(loss.item())
        optimizer.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(physics.parameters(), 1.0)
        optimizer.step()
        seconds.append(time.perf_counter() - tick)
        del loss
    return {
        "implementation": "original",
        "law": law,
        "setup_s": setup_s,
        "warmup_s": seconds[:warmup],
        "epoch_s": seconds[warmup:],
        "loss": losses,
        "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True)
    dataset = commands.add_parser("dataset", help="write a law's ground truth")
    dataset.add_argument("law", choices=LAWS)
    dataset.add_argument("out", type=Path, help="data folder (the law's dataset goes below it)")
    epoch = commands.add_parser("epoch", help="time epochs of the inner loop")
    epoch.add_argument("law", choices=LAWS)
    epoch.add_argument("epochs", type=int)
    epoch.add_argument("--warmup", type=int, default=1)
    epoch.add_argument("--data", type=Path, required=True)
    epoch.add_argument("--work", type=Path, default=Path("original-work"))
    args = parser.parse_args()
    if args.command == "dataset":
        make_dataset(args.law, args.out / LAWS[args.law][2])
    else:
        print(json.dumps(time_epochs(args.law, args.epochs, args.warmup, args.data, args.work)))


if __name__ == "__main__":
    main()
