"""``taichi-mpm warmup``: compile every kernel once."""

from __future__ import annotations

import time

import click
from rich.console import Console

from taichi_mpm.cli import PRECISIONS, arch_option, main, start_taichi
from taichi_mpm.cli.heartbeat import Heartbeat
from taichi_mpm.warmup import WARM_UP_MATERIALS, warm_up_passes

#: Passes per precision (:func:`~taichi_mpm.warmup.warm_up_passes`): each law of
#: :data:`~taichi_mpm.warmup.WARM_UP_MATERIALS` with serial and with parallel loops, forward and
#: backward.
PASSES = 2 * len(WARM_UP_MATERIALS) * 2


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

    Later processes then start in seconds instead of minutes. While it works it shows which
    kernels it compiles (the law, the loops, the pass; i of N): a live line on a terminal,
    else, from 5 s on, a plain line on stderr every 5 s.
    """
    console = Console(highlight=False)
    chosen = PRECISIONS if precision == "both" else (precision,)
    with Heartbeat(active=not console.is_terminal) as heartbeat:
        for number, one in enumerate(chosen, 1):
            backend = start_taichi(console, arch, one)
            title = f"compiling {backend} {one} kernels"
            if len(chosen) > 1:
                title += f" ({number}/{len(chosen)})"
            with console.status(f"{title}...", spinner="dots") as status:
                start = time.perf_counter()
                for index, what in enumerate(warm_up_passes(), 1):
                    text = f"{title}: {index}/{PASSES} {what}"
                    status.update(f"{text}...")
                    heartbeat.state(text)
                seconds = time.perf_counter() - start
            console.print(f"[green]compiled[/] {backend} {one} kernels in {seconds:.1f} s")
            heartbeat.said()
