"""``taichi-mpm warmup``: compile every kernel once."""

from __future__ import annotations

import click
from rich.console import Console

import taichi_mpm as tm
from taichi_mpm.cli import PRECISIONS, arch_option, main, start_taichi


@main.command()
@arch_option
@click.option(
    "--precision",
    type=click.Choice((*PRECISIONS, "both")),
    default="both",
    show_default=True,
    help="Precision(s) to compile for.",
)
def warmup(arch: str, precision: str) -> None:
    """Compile every kernel once, filling Taichi's offline cache.

    Later processes then start in seconds instead of minutes.
    """
    console = Console(highlight=False)
    for chosen in PRECISIONS if precision == "both" else (precision,):
        backend = start_taichi(console, arch, chosen)
        with console.status(f"Compiling kernels ({backend}, {chosen})...", spinner="dots"):
            seconds = tm.warm_up()
        console.print(f"[green]compiled[/] {backend} {chosen} kernels in {seconds:.1f} s")
