"""The ``sga-agent`` command line: task listing, evaluation output and exit codes."""

import json
import os
import re
import subprocess
import sys
import time
from importlib import metadata
from importlib.metadata import EntryPoint
from pathlib import Path

import pytest
from click.testing import CliRunner

from sga_agent import registry
from sga_agent.cli import main
from sga_agent.cli.evaluate import solution_in
from sga_agent.cli.options import Duration
from sga_agent.config import SearchConfig
from sga_agent.run_store import RunStore
from sga_agent.task import Evaluation
from tests.sga_agent.doubles import law_solution
from tests.sga_agent.test_proposers import closed_port_url

REPO_ROOT = Path(__file__).resolve().parents[2]
DOUBLE = "tests.sga_agent.doubles:ExecTask"
LAW_DOUBLE = "tests.sga_agent.doubles:ExecLawTask"


@pytest.fixture
def fake_registry(monkeypatch):
    """A registry holding the test double and a broken plugin instead of the real tasks."""
    points = {
        name: EntryPoint(name, value, registry.GROUP)
        for name, value in [
            ("double", DOUBLE),
            ("broken", "tests.sga_agent.doubles:broken_task"),
        ]
    }
    monkeypatch.setattr(registry, "task_entry_points", lambda: points)


@pytest.fixture
def in_repo(monkeypatch):
    """`evaluate` imports a module:callable task from the current directory."""
    monkeypatch.chdir(REPO_ROOT)


def write(tmp_path: Path, text: str) -> str:
    path = tmp_path / "solution.py"
    path.write_text(text)
    return str(path)


def test_tasks_lists_every_task_even_a_broken_one(fake_registry):
    result = CliRunner().invoke(main, ["tasks"])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert lines[0].split()[:2] == ["broken", "?"]
    assert lines[0].endswith("(failed to load: RuntimeError: this plugin is broken)")
    assert lines[1].startswith("double")
    assert "equation" in lines[1] and "Executes the candidate" in lines[1]


def test_tasks_with_an_empty_registry(monkeypatch):
    monkeypatch.setattr(registry, "task_entry_points", dict)
    result = CliRunner().invoke(main, ["tasks"])
    assert result.exit_code == 0
    assert "no tasks are registered" in result.output


@pytest.mark.slow
def test_evaluate_prints_parameters_loss_and_feedback(tmp_path, in_repo):
    better = law_solution(
        "loss = 0.25\nparameters = {'youngs_modulus': 2e5}\nfeedback = 'fits well'"
    )
    answer = f"First try:\n```python\nloss = 9.0\n```\nBetter:\n```python\n{better}```\n"
    result = CliRunner().invoke(main, ["evaluate", "--task", LAW_DOUBLE, write(tmp_path, answer)])
    assert result.exit_code == 0, result.output
    assert "fitted parameters" in result.output
    assert "youngs_modulus" in result.output and "200000" in result.output
    assert "loss: 0.25" in result.output
    assert "fits well" in result.output


@pytest.mark.slow
def test_evaluate_json_passes_settings(tmp_path, in_repo):
    args = ["evaluate", "--task", LAW_DOUBLE, "--epochs", "5", "--lr", "0.01", "--json"]
    result = CliRunner().invoke(main, [*args, write(tmp_path, law_solution("loss = 1.5"))])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["valid"] and data["loss"] == 1.5
    assert data["extras"]["settings"]["epochs"] == 5
    assert data["extras"]["settings"]["learning_rate"] == 0.01


def test_evaluate_applies_the_searchs_static_checks(tmp_path, in_repo):
    file = write(tmp_path, "import os\nloss = 0.0\n")
    result = CliRunner().invoke(main, ["evaluate", "--task", LAW_DOUBLE, file])
    assert result.exit_code == 1
    assert result.stderr.startswith("invalid: the code breaks the rules:")
    assert "os" in result.stderr


@pytest.mark.slow
def test_evaluate_invalid_solution_exits_1_with_reason(tmp_path, in_repo):
    file = write(tmp_path, law_solution("raise ValueError('bad law')"))
    result = CliRunner().invoke(main, ["evaluate", "--task", LAW_DOUBLE, file])
    assert result.exit_code == 1
    assert result.stdout == ""
    reason = "invalid: capturing the solution raised ValueError: bad law"
    assert result.stderr.splitlines()[-1] == reason  # last, after any progress lines
    result = CliRunner().invoke(main, ["evaluate", "--task", LAW_DOUBLE, "--json", file])
    assert result.exit_code == 1
    data = json.loads(result.stdout)
    assert not data["valid"] and data["loss"] == "inf"
    assert "ValueError: bad law" in data["extras"]["traceback"]


@pytest.mark.slow
def test_evaluate_timeout_option(tmp_path, in_repo):
    file = write(tmp_path, law_solution("while True:\n    pass"))
    result = CliRunner().invoke(main, ["evaluate", "--task", LAW_DOUBLE, "--timeout", "1", file])
    assert result.exit_code == 1
    assert result.stderr.splitlines()[-1] == "invalid: exceeded the time limit of 1 s"


def test_evaluate_unknown_task_suggests_the_closest(tmp_path, fake_registry):
    result = CliRunner().invoke(main, ["evaluate", "--task", "doubel", write(tmp_path, "")])
    assert result.exit_code == 2
    assert "no task named 'doubel'" in result.output
    assert "Did you mean 'double'?" in result.output


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["--task", DOUBLE, "missing.py"], "does not exist"),
        (["x.py"], "Missing option '--task'"),
        (["--task", DOUBLE, "--epochs", "-1", "x.py"], "--epochs"),
        (["--task", DOUBLE, "--lr", "0", "x.py"], "--lr"),
        (["--task", DOUBLE, "--memory-mb", "10", "x.py"], "--memory-mb"),
    ],
)
def test_evaluate_usage_errors_exit_2(tmp_path, monkeypatch, args, fragment):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "x.py").write_text("")
    result = CliRunner().invoke(main, ["evaluate", *args])
    assert result.exit_code == 2, result.output
    assert fragment in result.output


def test_a_task_named_by_its_description_is_suggested(tmp_path):
    result = CliRunner().invoke(main, ["search", "--task", "sand", "--out-dir", str(tmp_path)])
    assert result.exit_code == 2, result.output
    assert "no task named 'sand'" in result.output and "Did you mean 'granular'?" in result.output
    assert not any(tmp_path.iterdir())


def test_version():
    result = CliRunner().invoke(main, ["--version"])
    assert result.exit_code == 0
    assert result.output == f"sga-agent, version {metadata.version('sga-agent')}\n"


@pytest.mark.slow
def test_a_search_without_the_models_key_stops_before_it_starts(tmp_path, monkeypatch):
    monkeypatch.delenv("OPENAI_API_KEY", raising=False)
    args = ["search", "--task", "granular", "--model", "openai/gpt-4o", "--out-dir", str(tmp_path)]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 1, result.output
    assert result.output == "Error: no API key for openai/gpt-4o: set OPENAI_API_KEY\n"
    assert not any(tmp_path.iterdir())  # no run folder


def test_the_command_line_starts_without_the_report_s_plotting():
    """Every command imports the report's heartbeat; matplotlib (0.4 s of a command's start)
    comes only with a report's figures."""
    program = (
        "import sys; import sga_agent.cli; from sga_agent.report import heartbeat; "
        "print('matplotlib' in sys.modules)"
    )
    done = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "False"


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="no /proc: the call's clock")
def test_the_program_s_clock_starts_with_its_process():
    """A time budget covers the start-up: the clock a program reads started with its process,
    here a second of waiting before anything of the project was imported."""
    program = (
        "import time; time.sleep(1.0); from sga_agent.cli.clock import process_started; "
        "print(time.monotonic() - process_started())"
    )
    done = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert 0.98 <= float(done.stdout) < 10.0


def test_a_missing_key_is_reported_before_litellm_is_imported(tmp_path):
    """A fresh process, as a user runs it: the missing key is named in under 2 s (litellm
    alone takes seconds to import)."""
    env = {k: v for k, v in os.environ.items() if k != "OPENAI_API_KEY"}
    args = ["search", "--task", "elastic", "--model", "openai/gpt-4o", "--out-dir", str(tmp_path)]
    start = time.perf_counter()
    run = subprocess.run(
        [sys.executable, "-m", "sga_agent", *args], capture_output=True, text=True, env=env
    )
    seconds = time.perf_counter() - start
    assert run.returncode == 1, run.stderr
    assert run.stderr == "Error: no API key for openai/gpt-4o: set OPENAI_API_KEY\n"
    assert seconds < 2.0, f"{seconds:.1f} s"
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize(
    ("args", "suggested"),
    [
        (["--resume", "runs/elastic-1"], "runs/elastic-1"),
        (["--task", "elastic", "--resume=runs/elastic-2"], "runs/elastic-2"),
        (["--resume"], "RUN_DIR"),
    ],
)
def test_search_resume_names_the_resume_command(args, suggested):
    result = CliRunner().invoke(main, ["search", *args])
    assert result.exit_code == 2, result.output
    assert f"`sga-agent resume {suggested}` continues a stopped run" in result.output
    assert "--preset" not in result.output


@pytest.mark.parametrize(
    "args",
    [["--option", "no_such_option=1"], ["--option", "steps=many"], ["--model", "builtin:ga"]],
)
def test_usage_errors_come_before_the_no_model_banner(tmp_path, args):
    result = CliRunner().invoke(
        main, ["search", "--task", "elastic", *args, "--out-dir", str(tmp_path)]
    )
    assert result.exit_code == 2, result.output
    assert "no --model" not in result.output
    assert result.output.startswith("Usage:")
    assert not any(tmp_path.iterdir())


def test_a_resume_whose_server_is_down_stops_before_it_touches_the_run(tmp_path):
    """Resumed after its seed was evaluated, the run asks the model for one word first:
    nothing listens, so the command stops and the run is as it was."""
    config = SearchConfig.from_settings(
        task="granular", proposer="hosted_vllm/some-model", api_base=closed_port_url(),
        iterations=3, exploit=1, explore=1, workers=1,
    )  # fmt: skip
    store = RunStore.create(tmp_path, config, {})
    seed = Evaluation(True, 1.0, "the seed's feedback")
    store.append({"type": "evaluation", "candidate": "00-seed", "evaluation": seed.to_dict()})
    before = store.events()
    result = CliRunner().invoke(main, ["resume", str(store.path)])
    assert result.exit_code == 1, result.output
    error = next(line for line in result.output.splitlines() if line.startswith("Error:"))
    assert "connection refused" in error and "start the server or correct --api-base" in error
    assert f"sga-agent resume {store.path}` again once the model answers" in result.output
    assert store.events() == before
    assert not (store.path / "summary.json").exists()


def test_a_search_whose_server_is_down_leaves_no_run_folder(tmp_path):
    started = time.monotonic()
    result = CliRunner().invoke(
        main,
        ["search", "--task", "elastic", "--model", "hosted_vllm/some-model",
         "--api-base", closed_port_url(), "--out-dir", str(tmp_path)],
    )  # fmt: skip
    assert result.exit_code == 1, result.output
    assert time.monotonic() - started < 15
    assert "connection refused" in result.output and "no run was started" in result.output
    assert not any(tmp_path.iterdir())


def test_a_money_budget_for_an_unpriced_model_needs_a_price(tmp_path):
    args = ["search", "--task", "elastic", "--model", "openai/my-local-model", "--api-base",
            closed_port_url(), "--max-usd", "0.0001", "--out-dir", str(tmp_path)]  # fmt: skip
    result = CliRunner().invoke(main, args, env={"OPENAI_API_KEY": "sk-test"})
    assert result.exit_code == 2, result.output
    assert "--price" in result.output and "openai/my-local-model" in result.output
    priced = CliRunner().invoke(main, [*args, "--price", "2.5,10"], env={"OPENAI_API_KEY": "x"})
    assert priced.exit_code == 1 and "connection refused" in priced.output  # past the check
    wrong = CliRunner().invoke(main, [*args, "--price", "2.5"], env={"OPENAI_API_KEY": "x"})
    assert wrong.exit_code == 2 and "IN,OUT" in wrong.output


def test_a_file_s_solution_is_read_as_the_search_reads_an_answer():
    task = registry.load_task("elastic")
    last = solution_in("a\n```python\nx = 1\n```\n```python\nx = 2\n```\n", task)
    assert last == ("x = 2\n", "", [])  # neither defines the template's names: the last
    assert solution_in("x = 3\n", task) == ("x = 3\n", "", [])  # a bare solution as it is
    law = law_solution("SCALE = 2.0")
    code, problem, fixes = solution_in(f"```python\n{law}```\n```python\nPhysics()\n```", task)
    assert code == law and not problem and "block 1" in fixes[0]


def test_search_help_writes_every_default_one_way():
    """Defaults read "[default: ...]", from the config and the presets, never "[0.5]"."""
    from sga_agent.config import PRESETS, SandboxConfig

    help_text = CliRunner().invoke(main, ["search", "--help"], terminal_width=400).output
    assert "Default:" not in help_text and not re.search(r"\[\d", help_text)
    assert f"[default: {SandboxConfig.timeout_s}; x>=1]" in help_text
    iterations = f"{PRESETS['sga']['iterations']} (sga), {PRESETS['quick']['iterations']} (quick)"
    until = "with --time-budget, until the budget"
    assert f"Outer iterations.  [default: ({iterations}; {until}); x>=1]" in help_text
    assert "--out-dir DIRECTORY" in help_text and "--out " not in help_text


@pytest.mark.parametrize(
    ("text", "seconds"), [("15m", 900.0), ("1h30m", 5400.0), ("90s", 90.0), ("2.5", 2.5)]
)
def test_a_time_budget_is_read_as_seconds(text, seconds):
    assert Duration().convert(text, None, None) == seconds


@pytest.mark.parametrize("text", ["soon", "15 minutes", "0", "m"])
def test_a_bad_time_budget_is_a_usage_error_naming_the_form(tmp_path, text):
    args = ["search", "--task", "elastic", "--time-budget", text, "--out-dir", str(tmp_path)]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 2, result.output
    assert "--time-budget" in result.output
    assert "duration" in result.output
    assert not any(tmp_path.iterdir())


def test_a_resume_asks_the_model_first_only_when_it_will_ask_it_again(tmp_path):
    from sga_agent.cli.resume import answers_wanted

    config = SearchConfig.from_settings(
        task="granular", proposer="openai/gpt-4o", iterations=1, exploit=1, explore=1
    )
    store = RunStore.create(tmp_path, config, {})
    assert answers_wanted(config, store)
    for candidate in ("01-exploit-00", "01-explore-00"):
        store.append({"type": "proposal", "candidate": candidate, "proposal": {"text": "x"}})
    assert not answers_wanted(config, store)  # every answer is recorded: no request is sent
    assert answers_wanted(config.replace(iterations=2), store)
    assert answers_wanted(config.replace(max_seconds=60.0, iterations=1_000_000), store)
