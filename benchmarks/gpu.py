"""The GPU check, for a machine with CUDA: every number into one JSON file, in at most 8 minutes.

On ``--device cuda``, each part in its own process with its own time limit, what finished is
kept when a later part fails or runs out of time:

1. ``scale``: ``benchmarks/scale.py --device cuda`` (10^3 to 6.4·10^4 particles, 400 steps):
   the simulator alone and one evaluation of ``observed`` per size;
2. ``evaluations``: ``sga-agent evaluate --device cuda --json`` of each constitutive
   benchmark task's true law (``examples/laws``), its default fit;
3. ``search``: ``sga-agent search --task granular --device cuda --time-budget 3m --json``.

Besides the parts, the file records the machine (GPU, torch, Taichi, CPU cores) and the
command. No GPU has run this script yet: no session has been lent one since it was written.

On the device machine of this workplace (CUDA torch, Python 3.12, no Taichi), Taichi and its
one missing dependency travel as wheels (54 MiB; see the device tool's notes)::

    echo /.whl/ >> .git/info/exclude
    python3 -m pip download --no-deps --only-binary=:all: --python-version 3.12 \\
        --implementation cp --platform manylinux_2_27_x86_64 -d .whl taichi==1.7.4 dill
    # there, with .whl carried:
    python3 -m pip install -q --no-index --no-deps --target /tmp/site .whl/*.whl
    export PYTHONPATH=/tmp/site:$PWD
    python3 -m pip install -q --no-index --no-deps --no-build-isolation -e .  # task entry points
    python3 benchmarks/gpu.py --out $OUT/gpu.json
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPOSITORY = Path(__file__).resolve().parents[1]
#: Each constitutive benchmark task and the example file of its true law.
TRUE_LAWS = {"elastic": "neo_hookean.py", "plasticine": "von_mises.py",
             "granular": "drucker_prager.py", "fluid": "fluid.py"}  # fmt: skip
#: Seconds each part may take: 8 minutes together, with room for starting the processes.
LIMITS = {"scale": 170, "evaluations": 110, "search": 200}


def machine() -> dict:
    """The GPU, the libraries and the CPU cores of this machine."""
    import taichi
    import torch

    facts = {"torch": torch.__version__, "torch_cuda": torch.version.cuda,
             "taichi": ".".join(map(str, taichi.__version__)), "cpu_cores": os.cpu_count(),
             "python": sys.version.split()[0]}  # fmt: skip
    if torch.cuda.is_available():
        facts["gpu"] = torch.cuda.get_device_name(0)
    return facts


def part(command: list[str], limit: float) -> dict:
    """Run ``command`` in the repository with a limit: its seconds, exit status and the last
    line of its output read as JSON where it is (else the output's tail)."""
    started = time.perf_counter()
    try:
        done = subprocess.run(command, cwd=REPOSITORY, capture_output=True, text=True,
                              timeout=limit)  # fmt: skip
    except subprocess.TimeoutExpired:
        return {"command": command, "seconds": limit, "timed_out": True}
    record = {"command": command, "seconds": round(time.perf_counter() - started, 1),
              "returncode": done.returncode}  # fmt: skip
    try:
        record["result"] = json.loads(done.stdout)
    except json.JSONDecodeError:
        record["output"] = (done.stdout + done.stderr)[-3000:]
    return record


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="the JSON file to write")
    parser.add_argument("--device", choices=("cuda", "cpu"), default="cuda",
                        help="cpu runs the same parts on the CPU, to try the script anywhere")
    args = parser.parse_args()
    from sga_agent.cuda import DeviceUnavailable, check_device

    try:
        check_device(args.device)
    except DeviceUnavailable as error:
        sys.exit(f"benchmarks/gpu.py needs a GPU: {error}")
    device = args.device
    found: dict = {"machine": machine(), "command": sys.argv}
    python, cli = sys.executable, [sys.executable, "-m", "sga_agent"]

    def save() -> None:
        args.out.write_text(json.dumps(found, indent=1) + "\n")

    with tempfile.TemporaryDirectory() as folder:
        scale = Path(folder) / "scale"
        found["scale"] = part([python, "benchmarks/scale.py", "--device", device, "--steps",
                               "400", "--out", str(scale)], LIMITS["scale"])  # fmt: skip
        if (scale / "scale.json").exists():
            found["scale"]["rows"] = json.loads((scale / "scale.json").read_text())
        save()
        each = LIMITS["evaluations"] / len(TRUE_LAWS)
        found["evaluations"] = {
            task: part([*cli, "evaluate", "--task", task, "--device", device, "--json",
                        f"examples/laws/{law}"], each)  # fmt: skip
            for task, law in TRUE_LAWS.items()
        }
        save()
        found["search"] = part([*cli, "search", "--task", "granular", "--device", device,
                                "--time-budget", "3m", "--json", "--out-dir",
                                str(Path(folder) / "runs")], LIMITS["search"])  # fmt: skip
        save()
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
