"""Task options: text read once into the task's options dataclass, its one serialisation and
the reading back, and the CLI's usage errors (exit 2, before anything is evaluated) for
unknown keys and bad values."""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Literal

import pytest
from click.testing import CliRunner

from sga_agent.cli import main
from sga_agent.options import (
    OptionError,
    describe_options,
    options_data,
    options_from_data,
    options_json,
    parse_options,
)
from sga_agent.task import NoOptions


@dataclass(frozen=True)
class Options:
    steps: int | None = None
    weight: float = 0.3
    optimizer: Literal["adam", "lbfgs"] | None = None
    verbose: bool = False
    label: str = ""

    def __post_init__(self) -> None:
        if self.steps is not None and self.steps < 1:
            raise ValueError(f"option 'steps' must be at least 1, got {self.steps}")


def test_values_are_typed_by_their_fields_into_the_options_object():
    raw = {"steps": "200", "weight": "1e-2", "optimizer": "lbfgs", "verbose": "yes", "label": "x"}
    assert parse_options(Options, raw, "t") == Options(200, 0.01, "lbfgs", True, "x")
    assert parse_options(Options, {"weight": "2"}, "t") == Options(weight=2.0)  # the rest default
    assert describe_options(Options) == (
        "steps (integer), weight (number), optimizer (adam|lbfgs), verbose (true|false), "
        "label (text)"
    )


@pytest.mark.parametrize(
    ("raw", "message"),
    [
        ({"stepz": "100"}, "task 't' has no option 'stepz'; did you mean 'steps'?"),
        ({"steps": "abc"}, "option 'steps' takes an integer, got 'abc'"),
        ({"steps": "2.5"}, "option 'steps' takes an integer, got '2.5'"),
        ({"weight": "nan"}, "option 'weight' takes a finite number, got 'nan'"),
        ({"optimizer": "sgd"}, "option 'optimizer' takes one of adam, lbfgs, got 'sgd'"),
        ({"verbose": "maybe"}, "option 'verbose' takes true or false"),
        ({"steps": "0"}, "option 'steps' must be at least 1, got 0"),
    ],
)
def test_unknown_keys_and_bad_values_name_the_option(raw, message):
    with pytest.raises(OptionError) as raised:
        parse_options(Options, raw, "t")
    assert message in str(raised.value)


def test_a_task_without_options_takes_none():
    with pytest.raises(OptionError, match="task 't' has no option 'steps' .its options: none"):
        parse_options(NoOptions, {"steps": "1"}, "t")


@pytest.mark.parametrize(
    ("option", "message"),
    [
        ("stepz=100", "no option 'stepz'; did you mean 'steps'?"),
        ("optimiser=adam", "no option 'optimiser'; did you mean 'optimizer'?"),
        ("steps=abc", "option 'steps' takes an integer, got 'abc'"),
        ("precision=float16", "option 'precision' takes one of float32, float64"),
    ],
)
def test_search_refuses_bad_options_before_anything_runs(tmp_path, option, message):
    args = ["search", "--task", "granular", "--option", option, "--out-dir", str(tmp_path)]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 2, result.output
    assert "Invalid value for '--option'" in result.output and message in result.output
    assert not any(tmp_path.iterdir())  # no run folder: nothing started


def test_evaluate_refuses_bad_options_before_anything_runs(tmp_path):
    law = tmp_path / "law.py"
    law.write_text("raise SystemExit('evaluated')\n")
    result = CliRunner().invoke(
        main, ["evaluate", "--task", "homo", str(law), "--option", "strain_weight=-1"]
    )
    assert result.exit_code == 2, result.output
    assert "option 'strain_weight' must be a finite number >= 0, got -1.0" in result.output


def test_the_options_survive_their_json_and_are_built_back_with_their_checks():
    options = Options(steps=3, weight=0.5, optimizer="adam", verbose=True, label="ünï")
    text = options_json(options)
    raw = {"steps": "3", "weight": "0.5", "optimizer": "adam", "verbose": "on", "label": "ünï"}
    assert text == options_json(parse_options(Options, raw, "t"))
    assert list(json.loads(text)) == sorted(options_data(options))  # equal options, equal text
    assert options_from_data(Options, json.loads(text), "t") == options
    assert options_from_data(Options, {}, "t") == Options()  # a run that set none
    with pytest.raises(OptionError, match="task 't' has no option 'stepz'; did you mean"):
        options_from_data(Options, {"stepz": 3}, "t")
    with pytest.raises(OptionError, match="option 'steps' must be at least 1, got 0"):
        options_from_data(Options, {"steps": 0}, "t")


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"steps": 3}, "must be the task's options dataclass .its options_type., got dict"),
        (Options, "got type"),
        (Options(weight=float("nan")), "must be JSON-serialisable"),
    ],
)
def test_what_is_not_an_options_object_cannot_be_sent(options, message):
    with pytest.raises(TypeError, match=message):
        options_json(options)
