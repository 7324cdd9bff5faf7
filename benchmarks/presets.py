"""Table 1 across presets: SGA, its ablations and the baselines, with one proposer.

A grid of tasks x presets x seeds, one search run per cell in ``--out-dir``; then ``table.md`` and
``table.csv`` (mean ± std of the final best loss per task and preset), ``ranks.csv`` and
``ranks.png``. Run from the repository root, with the provider's key in the environment::

    python benchmarks/presets.py --tasks elastic,plasticine,homo --seeds 0,1,2 \\
        --model openai/gpt-4o --presets sga,no-bilevel,no-exploit,cot,funsearch,eureka,opro

Running the command again skips finished cells and resumes unfinished ones.
"""

from __future__ import annotations

import click

from sga_agent.benchmark.cli import grid_options, run_benchmark, split_list
from sga_agent.benchmark.grid import Method
from sga_agent.config import PRESETS

TABLE_1 = ("sga", "no-bilevel", "no-exploit", "cot", "funsearch", "eureka", "opro")


@click.command(context_settings={"help_option_names": ["-h", "--help"]})
@click.option(
    "--model",
    required=True,
    envvar="SGA_MODEL",
    metavar="PROPOSER",
    help="The proposer of every preset: a litellm model string (openai/gpt-4o), "
    "builtin, or replay:RUN_DIR.",
)
@click.option(
    "--presets",
    default=",".join(TABLE_1),
    show_default=True,
    callback=split_list,
    metavar="P1,P2",
    help=f"Presets, comma-separated, of: {', '.join(PRESETS)}.",
)
@grid_options(default_out="bench/presets")
def main(model: str, presets: list[str], **options) -> None:
    """Run every preset in --presets with --model on every task and seed, then write
    table.md, table.csv, ranks.csv and ranks.png into --out-dir."""  # fmt: skip
    if not presets:
        raise click.BadParameter("name at least one preset", param_hint="'--presets'")
    run_benchmark([Method(preset, model, preset) for preset in presets], **options)


if __name__ == "__main__":
    main()
