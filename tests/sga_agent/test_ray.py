"""The Ray executor (``--executor ray``): a real local Ray instance, cheap test-double tasks.

A search replayed through Ray gives exactly the local pool's results; a Ray worker killed
mid-evaluation is retried once, and recorded as crashed when its retry is killed too; without
Ray the option is a clear usage error. The double task is :class:`LiteralTask` below, which
the sandbox workers import from this module (the repository is put on ``PYTHONPATH``).
"""

from __future__ import annotations

import importlib.util
import json
import os
import signal
import subprocess
import sys
import time
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import pytest
from click.testing import CliRunner

from sga_agent import registry, runner
from sga_agent.cli import main
from sga_agent.config import ConfigError, SearchConfig
from sga_agent.proposers.base import Proposal
from sga_agent.run_store import RunStore
from sga_agent.task import Evaluation, EvaluationSettings, NoOptions, PromptParts

REPO_ROOT = Path(__file__).resolve().parents[2]
TASK = f"{__name__}:LiteralTask"
needs_ray = pytest.mark.skipif(
    importlib.util.find_spec("ray") is None,
    reason='Ray is not installed; pip install -e ".[test]" installs it',
)


def code(action: str, loss: float) -> str:
    """A candidate of :class:`LiteralTask`: what the evaluation does, and its loss."""
    return f"SMILES = {action!r}\ncoordinates = [[{loss}, 0.0, 0.0]]\n"


def answer(candidate: str) -> str:
    return f"### Code\n```python\n{candidate}```\n"


class LiteralTask:
    """Test double: ``SMILES`` says what the evaluation does, ``coordinates[0][0]`` is the loss.

    Actions: "ok"; "raise" (an error); "invalid" (the task rejects it); "wait:PATH" (wait for
    PATH to exist, at most a minute); "hang:..." (sleep until killed).
    """

    name = "literal-double"
    description = "Reads the literals of the candidate (a test double)."
    kind = "entity"

    def seed_solution(self) -> str:
        return code("ok", 3.0)

    def prompt_parts(self) -> PromptParts:
        return PromptParts(role="tester", context="", template="", requirements="")

    def capture(self, solution: str) -> dict:
        namespace: dict = {}
        exec(solution, namespace)  # literal assignments only: the static check ran
        return {"action": namespace["SMILES"], "loss": float(namespace["coordinates"][0][0])}

    def evaluate(self, data: dict, settings: EvaluationSettings) -> Evaluation:
        action, loss = data["action"], data["loss"]
        if action == "raise":
            raise ValueError("the double was asked to raise")
        if action == "invalid":
            return Evaluation.invalid("the double rejects this candidate")
        if action.startswith(("wait:", "hang:")):  # tell the test which process fits it
            folder = Path(action[5:]).parent if action.startswith("wait:") else Path(action[5:])
            (folder / f"evaluating-{os.getpid()}").write_text(action)
        if action.startswith("wait:"):
            deadline = time.monotonic() + 60
            while not os.path.exists(action[5:]) and time.monotonic() < deadline:
                time.sleep(0.05)
        if action.startswith("hang:"):
            time.sleep(3600)
        return Evaluation(
            True, loss, f"loss {loss}", parameters={"x": loss}, curves={"loss": [2 * loss, loss]},
            extras={"nice": os.nice(0)},  # a Ray worker's fit runs at the local pool's priority
        )


class Scripted:
    """Proposer double: the answers, in order."""

    name = "scripted"

    def __init__(self, answers: list[str]) -> None:
        self.answers = list(answers)

    def propose(self, request):
        taken, self.answers = self.answers[: request.n], self.answers[request.n :]
        return [Proposal(text, "scripted", request.temperature, 10, 5, 0.001) for text in taken]


def config(**overrides) -> SearchConfig:
    values = {"task": TASK, "proposer": "scripted", "iterations": 2, "top_k": 2,
              "exploit": 1, "explore": 2, "workers": 2, "timeout_s": 120.0}  # fmt: skip
    return SearchConfig.from_settings(**{**values, **overrides})


@pytest.fixture
def double_task(monkeypatch):
    """The search loads ``module:callable`` tasks; the workers (and Ray's) import this file."""
    monkeypatch.setattr(registry, "load_task", registry.resolve_task)
    path = [str(REPO_ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(path))


def outcomes(store: RunStore) -> dict[str, dict]:
    """Every candidate's recorded evaluation, without its wall times and Ray node."""
    recorded = {}
    for folder in sorted((store.path / "candidates").iterdir()):
        evaluation = json.loads((folder / "evaluation.json").read_text())
        del evaluation["seconds"]
        evaluation["extras"].pop("capture_seconds", None)
        evaluation["extras"].pop("node", None)
        recorded[folder.name] = evaluation
    return recorded


def nodes(store: RunStore) -> dict[str, str]:
    """The Ray node each evaluated candidate's record names (duplicates name none)."""
    found = {}
    for folder in sorted((store.path / "candidates").iterdir()):
        extras = json.loads((folder / "evaluation.json").read_text())["extras"]
        if "node" in extras:
            found[folder.name] = extras["node"]
    return found


def sandbox_event(store: RunStore) -> dict:
    return next(event for event in store.events() if event["type"] == "sandbox")


@pytest.mark.slow
@needs_ray
def test_a_search_through_ray_matches_the_local_pool(tmp_path, double_task):
    """Record a search on the local pool, replay its answers through a local Ray instance."""
    import ray

    answers = [
        answer(code("ok", 2.0)), answer(code("raise", 0.0)), "no code in this answer",
        answer(code("ok", 1.0)), answer(code("invalid", 0.5)), answer(code("ok", 2.0)),
    ]  # fmt: skip
    local_config = config()
    local = RunStore.create(tmp_path / "local", local_config, {})
    local_result = runner.run(local_config, local, proposer=Scripted(answers))

    ray_config = config(executor="ray", proposer=f"{runner.REPLAY_PREFIX}{local.path}")
    remote = RunStore.create(tmp_path / "ray", ray_config, {})
    ray_result = runner.run(ray_config, remote)

    assert not ray.is_initialized()  # the pool stopped the instance it started
    assert outcomes(remote) == outcomes(local)
    statuses = {name: e["status"] for name, e in outcomes(remote).items()}
    assert statuses == {
        "00-seed": "ok", "01-exploit-00": "ok", "01-explore-00": "error",
        "01-explore-01": "invalid", "02-exploit-00": "ok", "02-explore-00": "invalid",
        "02-explore-01": "ok",
    }  # fmt: skip
    assert outcomes(remote)["02-explore-01"]["extras"]["duplicate_of"] == "01-exploit-00"
    assert set(nodes(remote).values()) == {ray_node_address()} and not nodes(local)
    evaluated = {"00-seed", "01-exploit-00", "01-explore-00", "02-exploit-00", "02-explore-00"}
    assert evaluated <= set(nodes(remote)) and "01-explore-01" not in nodes(remote)  # no code
    assert [e.summary() for e in ray_result.top] == [e.summary() for e in local_result.top]
    for name in ("heap/iteration-01.json", "heap/iteration-02.json"):
        assert (remote.path / name).read_text() == (local.path / name).read_text()
    summaries = [json.loads((run.path / "summary.json").read_text()) for run in (remote, local)]
    for summary in summaries:  # the one thing allowed to differ: how long each run took
        assert summary["findings"].pop("duration_s") > 0
    assert summaries[0] == summaries[1]
    local_event, ray_event = sandbox_event(local), sandbox_event(remote)
    assert local_event["executor"] == "local" and ray_event["executor"] == "ray"
    assert ray_event["isolation"] == local_event["isolation"]  # probed on the (local) node
    assert ray_event["cpus"] == 2 and ray_event["nodes"] == 1  # sized by --workers 2
    assert ray_event["slots"] == 2


def ray_node_address() -> str:
    """The address a Ray node on this machine reports (Ray's own choice of interface)."""
    import ray

    return ray.util.get_node_ip_address()


def sandbox_workers(folder: Path) -> list[tuple[int, int, str]]:
    """(pid, parent pid, action) of every running fit worker whose parent is a Ray worker and
    which told ``folder`` that it is fitting a waiting or hanging candidate."""
    found = []
    for marker in folder.glob("evaluating-*"):
        proc = Path("/proc") / marker.name.removeprefix("evaluating-")
        try:
            solution = marker.read_text()
            parent = int((proc / "stat").read_text().rpartition(")")[2].split()[1])
            parent_title = Path(f"/proc/{parent}/cmdline").read_bytes().decode()
        except (OSError, ValueError, IndexError):
            continue  # it finished meanwhile
        if parent_title.startswith("ray::"):
            found.append((int(proc.name), parent, solution))
    return found


def kill_ray_workers(search: Future, waiting: str, hanging: str, release: Path) -> dict:
    """SIGKILL the Ray worker of ``waiting`` once, then ``release`` its retry; SIGKILL the Ray
    worker of ``hanging`` every time (the first try and its retry). Returns the killed pids."""
    killed: dict[str, list[int]] = {"waiting": [], "hanging": []}
    seen: set[int] = set()
    deadline = time.monotonic() + 240  # replacement slots start a Ray worker and helpers each
    while not search.done() and time.monotonic() < deadline:
        for pid, ray_worker, solution in sandbox_workers(release.parent):
            if pid in seen:
                continue
            seen.add(pid)
            if hanging in solution:
                os.kill(ray_worker, signal.SIGKILL)
                killed["hanging"].append(ray_worker)
            elif waiting in solution and not killed["waiting"]:
                os.kill(ray_worker, signal.SIGKILL)
                killed["waiting"].append(ray_worker)
            elif waiting in solution:  # its retry, in a new Ray worker: let it finish
                release.touch()
        time.sleep(0.05)
    return killed


@pytest.mark.slow
@needs_ray
def test_a_candidate_whose_ray_slot_dies_is_retried_once_then_recorded_as_crashed(
    tmp_path, double_task
):
    import ray

    from sga_agent.ray_executor import RayPool, RayUnavailableError

    release = tmp_path / "release"
    waiting, hanging = f"wait:{release}", f"hang:{tmp_path}"
    cfg = config(executor="ray", iterations=1, exploit=1, explore=1, top_k=2)
    store = RunStore.create(tmp_path / "runs", cfg, {})
    proposer = Scripted([answer(code(waiting, 0.5)), answer(code(hanging, 0.25))])
    ray.init(num_cpus=2, include_dashboard=False, object_store_memory=100 * 2**20)
    try:
        with pytest.raises(RayUnavailableError, match="no node of the Ray cluster can run"):
            RayPool(cpus_per_task=3)  # more than any node has: an error, not a silent wait
        with ThreadPoolExecutor(1) as background:
            search = background.submit(runner.run, cfg, store, None, proposer)
            killed = kill_ray_workers(search, waiting, hanging, release)
            result = search.result(timeout=60)
        assert ray.is_initialized()  # a connection made before the pool stays open
    finally:
        ray.shutdown()
    assert len(killed["waiting"]) == 1 and len(killed["hanging"]) == 2, killed
    evaluations = outcomes(store)
    retried, lost = evaluations["01-exploit-00"], evaluations["01-explore-00"]
    assert retried["status"] == "ok" and retried["loss"] == 0.5
    assert "its Ray slot died (ActorDiedError" in retried["extras"]["retried"]
    assert lost["status"] == "crashed" and lost["valid"] is False
    assert "lost on Ray" in lost["reason"] and "ActorDiedError" in lost["reason"]
    assert result.best.candidate == "01-exploit-00" and result.totals.evaluations == 3


def ray_children(binary: str) -> list[int]:
    """Pids of this process's children running Ray's ``binary`` (its local instance's)."""
    found = []
    for proc in Path("/proc").glob("[0-9]*"):
        try:
            parent = int((proc / "stat").read_text().rpartition(")")[2].split()[1])
            program = (proc / "cmdline").read_bytes().split(b"\0")[0].decode()
        except (OSError, ValueError, IndexError):
            continue
        if parent == os.getpid() and Path(program).name == binary:
            found.append(int(proc.name))
    return found


@needs_ray
@pytest.mark.heavy
def test_losing_this_machines_ray_node_records_nothing_twice(tmp_path):
    """The raylet of the search's own node dies mid-iteration.

    Run in a child process: when its raylet dies, Ray may end the driver process outright
    (seen under load), which must not take the test session with it. The slots' actors may
    outlive their raylet and finish the search (their answers reach the driver directly); or
    the search stops (RayClusterLostError) or its process ends. Either way nothing is recorded
    twice: a finished search holds every candidate once with its outcome, a stopped one nothing
    of iteration 2 and no summary (``sga-agent resume`` goes on from there).
    """
    program = (
        f"from tests.sga_agent.test_ray import lose_the_node; lose_the_node({str(tmp_path)!r})"
    )
    environment = {**os.environ, "PYTHONPATH": str(REPO_ROOT)}
    run = subprocess.run(
        [sys.executable, "-c", program], cwd=REPO_ROOT, env=environment,
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert "raylet killed mid-iteration" in run.stdout, run.stderr[-2000:]
    (folder,) = (tmp_path / "runs").iterdir()
    store = RunStore.open(folder)
    evaluated = [e["candidate"] for e in store.events() if e["type"] == "evaluation"]
    assert len(evaluated) == len(set(evaluated))
    recorded = store.recorded().evaluations
    if "search finished" in run.stdout:
        assert {name: e.loss for name, e in recorded.items()} == {
            "00-seed": 3.0, "01-exploit-00": 0.5, "01-explore-00": 0.25,
            "02-exploit-00": 0.1, "02-explore-00": 0.2,
        }  # fmt: skip
        assert (folder / "summary.json").exists()
    else:
        assert run.returncode != 0 or "search stopped: cluster lost" in run.stdout, (
            run.stderr[-2000:]
        )
        assert "00-seed" in recorded and not any(name.startswith("02-") for name in recorded)
        assert not (folder / "summary.json").exists()


def lose_the_node(tmp: str) -> None:
    """The child process of the test above: a search whose raylet is killed mid-iteration."""
    import ray

    from sga_agent.ray_executor import RayClusterLostError

    registry.load_task = registry.resolve_task
    tmp_path = Path(tmp)
    release = tmp_path / "release"
    waiting = f"wait:{release}"
    cfg = config(executor="ray", iterations=2, exploit=1, explore=1)
    store = RunStore.create(tmp_path / "runs", cfg, {})
    proposer = Scripted([answer(code(waiting, 0.5)), answer(code(waiting, 0.25)),
                         answer(code("ok", 0.1)), answer(code("ok", 0.2))])  # fmt: skip
    ray.init(num_cpus=2, include_dashboard=False, object_store_memory=100 * 2**20)
    try:
        (raylet,) = ray_children("raylet")
        with ThreadPoolExecutor(1) as background:
            search = background.submit(runner.run, cfg, store, None, proposer)
            deadline = time.monotonic() + 60
            both_running = False  # the two candidates of iteration 1 are being evaluated
            while time.monotonic() < deadline and not search.done() and not both_running:
                both_running = sum(waiting in s for *_, s in sandbox_workers(tmp_path)) == 2
                time.sleep(0.05)
            os.kill(raylet, signal.SIGKILL)
            if both_running:
                print("raylet killed mid-iteration", flush=True)
            release.touch()
            try:
                search.result(timeout=120)
                print("search finished", flush=True)
            except RayClusterLostError as error:
                if "Ray node of this machine stopped" in str(error):
                    print("search stopped: cluster lost", flush=True)
    finally:
        ray.shutdown()


def test_the_ray_executor_without_ray_is_a_usage_error_naming_the_install(tmp_path):
    program = "import sys; sys.modules['ray'] = None; from sga_agent.cli import main; main()"
    run = subprocess.run(
        [sys.executable, "-c", program, "search", "--task", "elastic", "--executor", "ray",
         "--out-dir", str(tmp_path)],
        capture_output=True, text=True, timeout=120,
        env={**os.environ, "LITELLM_LOCAL_MODEL_COST_MAP": "True"},
    )  # fmt: skip
    assert run.returncode == 2, run.stderr
    assert 'pip install "sga-agent[ray]"' in run.stderr and "--executor local" in run.stderr
    assert not any(tmp_path.iterdir())  # nothing started, no run folder


@needs_ray
def test_an_unreachable_cluster_fails_at_once():
    from sga_agent.ray_executor import RayPool, RayUnavailableError

    with pytest.raises(RayUnavailableError, match=r"no Ray head node answers at 127.0.0.1:1"):
        RayPool("127.0.0.1:1")


@pytest.mark.parametrize(
    ("settings", "fragment"),
    [
        ({"executor": "dask"}, "executor must be one of local, ray"),
        ({"ray_address": "10.0.0.5:6379"}, "only apply to executor 'ray'"),
        ({"executor": "ray", "ray_address": "10.0.0.5"}, "HOST:PORT"),
        ({"executor": "ray", "ray_cpus_per_task": 0}, "ray_cpus_per_task must be positive"),
        ({"executor": "ray", "ray_memory_mb": 0.5}, "ray_memory_mb must be a positive integer"),
    ],
)
def test_executor_settings_are_checked(settings, fragment):
    with pytest.raises(ConfigError, match=fragment):
        SearchConfig.from_settings(task="elastic", proposer="builtin", **settings)


def test_configs_written_before_the_executor_existed_still_load():
    old = SearchConfig(task="elastic", proposer="builtin").settings()  # flat, as they were
    for key in ("executor", "ray_address", "ray_cpus_per_task", "ray_memory_mb"):
        del old[key]
    loaded = SearchConfig.from_dict(old, NoOptions)
    assert loaded.executor.kind == "local" and loaded.executor.ray_address is None


def test_resume_takes_a_ray_address_only_for_a_ray_run(tmp_path):
    store = RunStore.create(tmp_path, SearchConfig(task="elastic", proposer="builtin"), {})
    result = CliRunner().invoke(main, ["resume", str(store.path), "--ray-address", "h:6379"])
    assert result.exit_code == 2 and "only apply to executor 'ray'" in result.output


@needs_ray
def test_a_search_whose_cluster_cannot_be_reached_leaves_no_run_folder(tmp_path):
    result = CliRunner().invoke(main, [
        "search", "--task", "elastic", "--executor", "ray", "--ray-address", "127.0.0.1:1",
        "--out-dir", str(tmp_path),
    ])  # fmt: skip
    assert result.exit_code == 1
    assert "no Ray head node answers at 127.0.0.1:1" in result.output
    assert "no run was started" in result.output and "sga-agent resume" not in result.output
    assert not any(tmp_path.iterdir())
