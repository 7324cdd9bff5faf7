"""Table 1 across proposers: the same preset with several LLM backbones (or LLM-free proposers).

A grid of tasks x proposers x seeds, one search run per cell in ``--out-dir``; then ``table.md`` and
``table.csv`` (mean ± std of the final best loss per task and proposer), ``ranks.csv`` and
``ranks.png`` (rank per task and mean rank, as the paper's Figure 4). Run from the repository
root, with the providers' keys in the environment::

    python benchmarks/backbones.py --tasks elastic,homo --seeds 0,1,2 \\
        --models openai/gpt-4o,anthropic/claude-3-5-sonnet-20240620,builtin
    python benchmarks/backbones.py --tasks elastic --models builtin,replay:runs/elastic-... \\
        --preset quick --option steps=100 --epochs 2

A proposer is a litellm model string, ``builtin`` (each task's LLM-free proposer) or
``replay:PATH`` (a recorded run, or a folder of runs of which each cell replays its task's and
seed's); ``LABEL=PROPOSER`` names its column. Running the command again skips finished cells
and resumes unfinished ones.
"""

from __future__ import annotations

from pathlib import Path

import click

from sga_agent.benchmark.cli import grid_options, run_benchmark, split_list
from sga_agent.benchmark.grid import Method
from sga_agent.config import PRESETS
from sga_agent.runner import REPLAY_PREFIX


def method(spec: str, preset: str) -> Method:
    """A column from "PROPOSER" or "LABEL=PROPOSER"; a replay is labelled by its folder."""
    label, sep, proposer = spec.partition("=")
    if not sep:
        proposer = spec
        label = spec
        if spec.startswith(REPLAY_PREFIX):
            label = REPLAY_PREFIX + Path(spec[len(REPLAY_PREFIX) :]).name
    return Method(label.strip(), proposer.strip(), preset)


@click.command(context_settings={"help_option_names": ["-h", "--help"]})
@click.option(
    "--models",
    required=True,
    callback=split_list,
    metavar="M1,M2",
    help="Proposers, comma-separated: litellm model strings (openai/gpt-4o, "
    "anthropic/claude-3-5-sonnet-20240620, hosted_vllm/NAME with --api-base), "
    "builtin, or replay:RUN_DIR; LABEL=PROPOSER names the column.",
)
@click.option(
    "--preset",
    type=click.Choice(list(PRESETS)),
    default="sga",
    show_default=True,
    help="Search settings of every proposer (a column of the paper's Table 1).",
)
@grid_options(default_out="bench/backbones")
def main(models: list[str], preset: str, **options) -> None:
    """Run every proposer in --models on every task and seed with one preset, then write
    table.md, table.csv, ranks.csv and ranks.png into --out-dir."""  # fmt: skip
    if not models:
        raise click.BadParameter("name at least one proposer", param_hint="'--models'")
    run_benchmark([method(spec, preset) for spec in models], **options)


if __name__ == "__main__":
    main()
