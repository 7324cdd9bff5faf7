"""A run's config: one config per component, the settings' flat names, the checks that name
the problem and the fix, and the config.json of this version and of the runs before it."""

from __future__ import annotations

import json
import shutil
from dataclasses import dataclass
from pathlib import Path

import pytest

from sga_agent.config import (
    FORMAT,
    SETTINGS,
    UNTIL_BUDGET,
    Budgets,
    ConfigError,
    ExecutorConfig,
    FitConfig,
    LoopConfig,
    SandboxConfig,
    SearchConfig,
    current_format,
    default,
    flat_settings,
    quick_screening,
)
from sga_agent.run_store import RunStore
from sga_agent.search import Totals
from sga_agent.task import NoOptions
from tasks.constitutive.options import ConstitutiveOptions

DATA = Path(__file__).resolve().parent / "data"
#: The config.json that commit e69b748 (before the components) wrote for
#: ``sga-agent search --task granular --model builtin --option steps=20 --epochs 1
#: --workers 1 --max-evaluations 9 --seed 3`` (run with that checkout; recorded as written).
FLAT_CONFIG = DATA / "e69b748-granular-config.json"


@dataclass(frozen=True)
class Steps:
    steps: int = 1


def test_each_setting_goes_to_its_component_and_back_by_its_flat_name():
    config = SearchConfig.from_settings(
        task="t", proposer="builtin", task_options=Steps(4), iterations=2, explore=3,
        epochs=7, timeout_s=60.0, executor="ray", ray_address="auto", workers=3,
        max_tokens=100, seed=9,
    )  # fmt: skip
    assert config.loop == LoopConfig(iterations=2, explore=3)
    assert config.fit == FitConfig(epochs=7)
    assert config.sandbox == SandboxConfig(timeout_s=60.0)
    assert config.executor == ExecutorConfig(kind="ray", workers=3, ray_address="auto")
    assert config.budgets == Budgets(max_tokens=100)
    assert (config.seed, config.task_options) == (9, Steps(4))
    flat = config.settings()
    assert flat["executor"] == "ray" and flat["iterations"] == 2 and flat["max_tokens"] == 100
    assert flat["task_options"] == {"steps": 4}
    assert set(flat) == {"task", "proposer", "task_options", "api_base", "preset", "seed",
                         *SETTINGS}  # fmt: skip
    changed = config.replace(ray_address="10.0.0.5:6379", top_k=1)
    assert changed.executor.ray_address == "10.0.0.5:6379" and changed.loop.top_k == 1
    assert changed.loop.iterations == 2  # the rest stays


def test_presets_give_their_values_and_settings_that_are_not_none_win():
    config = SearchConfig.from_preset("quick", task="t", proposer="builtin", iterations=None,
                                      explore=9)  # fmt: skip
    assert (config.loop.iterations, config.loop.explore, config.fit.epochs) == (4, 9, 5)
    assert config.preset == "quick" and config.loop.fidelity == "full"
    assert SearchConfig.from_preset("no-bilevel", task="t", proposer="x").fit.bilevel is False


def test_a_time_budget_without_an_iteration_count_iterates_until_the_budget():
    timed = SearchConfig.from_preset("quick", task="t", proposer="builtin", max_seconds=900.0)
    assert (timed.loop.iterations, timed.budgets.max_seconds) == (UNTIL_BUDGET, 900.0)
    counted = SearchConfig.from_preset("quick", task="t", proposer="builtin", max_seconds=900.0,
                                       iterations=3)  # fmt: skip
    assert counted.loop.iterations == 3


def test_the_quick_preset_screens_only_where_a_screen_is_cheap_and_no_budget_is_given():
    screening = {"fidelity": "multi", "screen_fidelity": 0.2, "promote_rank": 5}
    assert quick_screening("quick", {}, screens_cheaply=True) == screening
    assert quick_screening("quick", {"top_k": 3}, screens_cheaply=True)["promote_rank"] == 3
    # what the user set stays: an explicit multi keeps the quick screening's other settings
    assert quick_screening("quick", {"fidelity": "multi", "screen_fidelity": 0.5},
                           screens_cheaply=False) == {"promote_rank": 5}  # fmt: skip
    assert quick_screening("quick", {"max_seconds": 900.0}, screens_cheaply=True) == {}
    assert quick_screening("quick", {}, screens_cheaply=False) == {}
    assert quick_screening("sga", {}, screens_cheaply=True) == {}
    assert quick_screening("quick", {"fidelity": "full"}, screens_cheaply=True) == {}
    assert quick_screening("sga", {"fidelity": "multi"}, screens_cheaply=False) == {}
    from tasks.constitutive.task import ElasticTask, GranularTask
    from tasks.observed.task import ObservedTask

    assert GranularTask.screens_cheaply and not ObservedTask.screens_cheaply
    # with the task's built-in proposer: the opening, at the task's screen fidelity
    opening = {"fidelity": "multi", "screen_fidelity": 0.2, "promote_rank": 5, "opening": 20,
               "promote": 0.1}  # fmt: skip
    elastic = ElasticTask.opening_answers, ElasticTask.opening_screen
    granular = GranularTask.opening_answers, GranularTask.opening_screen
    assert quick_screening("quick", {}, True, elastic) == opening
    assert quick_screening("quick", {}, True, granular)["opening"] == 40
    assert quick_screening("quick", {}, True, granular)["screen_fidelity"] == 0.1
    assert "opening" not in quick_screening("quick", {"opening": 0}, True, granular)  # the user's
    assert quick_screening("quick", {"max_seconds": 60.0}, True, granular) == {}
    assert quick_screening("quick", {}, False, granular) == {}
    # a search whose shape the command sets has no opening
    assert "opening" not in quick_screening("quick", {"explore": 1}, True, granular)


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"iterations": 0}, "iterations must be at least 1, got 0"),
        ({"top_k": 0}, "top_k must be at least 1, got 0"),
        ({"explore": -1}, "explore must be >= 0, got -1"),
        ({"exploit": 0, "explore": 0}, "exploit + explore must be at least 1"),
        ({"explore_temperature": 2.5}, "explore_temperature must lie in [0, 2], got 2.5"),
        ({"epochs": -1}, "epochs must be >= 0, got -1"),
        ({"learning_rate": 0.0}, "learning_rate must be positive, got 0.0"),
        ({"timeout_s": 0}, "timeout_s must be a positive, finite number, got 0"),
        ({"memory_mb": 10}, "memory_mb must be at least 64, got 10"),
        ({"workers": 0}, "workers must be at least 1, got 0"),
        ({"ray_cpus_per_task": 2.0}, "ray_cpus_per_task only apply to executor 'ray'"),
        ({"max_usd": 0}, "max_usd must be positive, got 0"),
        ({"max_evaluations": -3}, "max_evaluations must be positive, got -3"),
        ({"iteration": 3}, "no search setting 'iteration' (known: task, proposer"),
        ({"iteration": 3}, "Did you mean 'iterations'?"),
        ({"task_options": {"steps": 3}}, "task options must be the task's options dataclass"),
    ],
)
def test_a_bad_setting_is_named_with_what_it_takes(settings, message):
    with pytest.raises(ConfigError) as raised:
        SearchConfig.from_settings(task="t", proposer="builtin", **settings)
    assert message in str(raised.value)


def test_the_command_line_s_defaults_are_the_config_s():
    assert default("timeout_s") == SandboxConfig().timeout_s == 900.0
    assert default("executor") == "local" and default("seed") == 0
    assert default("workers") == ExecutorConfig().workers >= 1
    assert default("explore_temperature") == LoopConfig().explore_temperature == 1.0


def test_budgets_stop_at_the_first_limit_reached():
    budgets = Budgets(max_usd=1.0, max_evaluations=10)
    assert budgets.exceeded(Totals(cost_usd=0.5, evaluations=9)) == ""
    assert budgets.exceeded(Totals(cost_usd=1.0, evaluations=10)) == "max_usd=1.0 reached"
    assert budgets.exceeded(Totals(tokens=10**9, evaluations=10)) == "max_evaluations=10 reached"
    assert Budgets().exceeded(Totals(tokens=10**9, cost_usd=1e9, evaluations=10**9)) == ""


def test_a_time_budget_keeps_its_last_share_for_the_run_s_end():
    """The evaluations of a 5-minute budget end 9 s before it, for the best's assessment;
    the share is at most 30 s, and nothing is kept without a time budget."""
    five = Budgets(max_seconds=300.0)
    assert five.kept_for_end() == pytest.approx(9.0)
    assert Budgets(max_seconds=7200.0).kept_for_end() == 30.0
    assert Budgets(max_evaluations=3).kept_for_end() == 0.0
    kept = five.kept_for_end()
    assert five.exceeded(Totals(seconds=292.0), kept=kept) == "max_seconds=300.0 reached"
    assert five.exceeded(Totals(seconds=290.0), kept=kept) == ""
    assert five.exceeded(Totals(seconds=299.0)) == ""  # the end itself may use the share


def test_the_config_survives_its_json_with_the_task_options_typed():
    config = SearchConfig.from_preset("cot", task="granular", proposer="builtin", seed=2,
                                      task_options=ConstitutiveOptions(steps=20))  # fmt: skip
    data = json.loads(json.dumps(config.to_dict()))
    assert data["format"] == FORMAT and data["loop"]["iterations"] == 1
    assert data["task_options"]["steps"] == 20
    assert SearchConfig.from_dict(data, ConstitutiveOptions) == config


def test_a_run_config_of_an_older_flat_layout_is_read_into_the_components():
    """The config.json e69b748 wrote: every setting flat, the task options only those given
    (with the built-in proposer's), typed here by the task's options dataclass."""
    data = json.loads(FLAT_CONFIG.read_text())
    assert "format" not in data["config"] and "iterations" in data["config"]  # the old layout
    config = SearchConfig.from_dict(data["config"], ConstitutiveOptions)
    assert config.task == "granular" and config.proposer == "builtin"
    assert config.preset == "quick" and config.seed == 3
    assert config.task_options == ConstitutiveOptions(steps=20, optimizer="lbfgs")
    assert config.loop == LoopConfig(iterations=4, top_k=5, exploit=2, explore=4)
    assert config.fit == FitConfig(bilevel=True, epochs=1)
    assert config.executor == ExecutorConfig(kind="local", workers=1)
    assert config.budgets == Budgets(max_evaluations=9)
    assert config.sandbox == SandboxConfig()
    record = current_format(data["config"])
    assert flat_settings(record) == {**data["config"]}  # nothing lost, nothing added
    again = SearchConfig.from_dict(json.loads(json.dumps(config.to_dict())), ConstitutiveOptions)
    assert again == config


def test_a_run_store_reads_either_layout(tmp_path):
    old = tmp_path / "old"
    old.mkdir()
    shutil.copy(FLAT_CONFIG, old / "config.json")
    (old / "events.jsonl").write_text("")
    store = RunStore.open(old)
    assert store.config_record()["loop"]["explore"] == 4
    assert store.config(ConstitutiveOptions).task_options.steps == 20
    new = RunStore.create(tmp_path / "new", store.config(ConstitutiveOptions), {})
    assert RunStore.open(new.path).config(ConstitutiveOptions) == store.config(ConstitutiveOptions)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda d: d.update(tokens_per_minute=5), "unknown settings in the run config: tokens"),
        (lambda d: d["loop"].update(depth=2), "unknown settings in the run config: loop.depth"),
        (lambda d: d["task_options"].update(stepz=2), "the run's task options: task 'granular' "
                                                       "has no option 'stepz'"),
        (lambda d: d["loop"].update(iterations=0), "iterations must be at least 1, got 0"),
    ],
)  # fmt: skip
def test_a_recorded_config_this_version_cannot_honour_is_refused_by_name(change, message):
    config = SearchConfig.from_settings(task="granular", proposer="builtin",
                                        task_options=ConstitutiveOptions())  # fmt: skip
    data = config.to_dict()
    change(data)
    with pytest.raises(ConfigError) as raised:
        SearchConfig.from_dict(data, ConstitutiveOptions)
    assert message in str(raised.value)


def test_a_config_without_task_options_is_for_a_task_without_options():
    config = SearchConfig(task="t", proposer="builtin")
    assert config.task_options == NoOptions() and config.to_dict()["task_options"] == {}
