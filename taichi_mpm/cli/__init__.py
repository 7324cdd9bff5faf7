"""Command line interface: ``taichi-mpm`` (or ``python -m taichi_mpm``).

One module per command: :mod:`.demo`, :mod:`.warmup`, :mod:`.sysid`.
"""

from __future__ import annotations

import click
from rich.console import Console

import taichi_mpm as tm

#: The distribution that installs this command (its version is ``--version``'s).
DISTRIBUTION = "sga-agent"
ARCHS = ("cpu", "cuda", "vulkan", "gpu")
PRECISIONS = ("float32", "float64")

arch_option = click.option(
    "--arch", type=click.Choice(ARCHS), default="cpu", show_default=True, help="Taichi backend."
)
precision_option = click.option(
    "--precision",
    type=click.Choice(PRECISIONS),
    default="float32",
    show_default=True,
    help="Floating-point type of the simulation.",
)


def start_taichi(console: Console, arch: str, precision: str) -> str:
    """Initialise Taichi; warn when it falls back to another backend; returns the backend."""
    try:
        info = tm.init(arch=arch, precision=precision)
    except Exception as error:  # Taichi raises several types for an unavailable backend
        raise click.ClickException(f"could not start Taichi on arch={arch}: {error}") from error
    if arch in ("cuda", "vulkan") and info.backend != arch:
        console.print(f"[yellow]warning:[/] no {arch} backend here; Taichi runs on {info.backend}")
    return info.backend


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name=DISTRIBUTION, prog_name="taichi-mpm")
def main() -> None:
    """taichi-mpm: a differentiable 3D MLS-MPM simulator in Taichi.

    `taichi-mpm demo` simulates a spinning cube of one of several materials and saves a
    picture of its motion; `taichi-mpm sysid` fits material parameters to an observed
    motion; `taichi-mpm warmup` compiles every kernel once.
    """


# The commands register themselves on ``main`` when imported.
from taichi_mpm.cli import demo, sysid, warmup  # noqa: E402, F401
