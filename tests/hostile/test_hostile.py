"""The hostile corpus through the real sandbox: no forged score, no damage, no leak, no leftover.

Every candidate of ``candidates/`` is evaluated as a search evaluates it (a warm
:class:`~sga_agent.sandbox.SandboxPool`: confined capture, trusted fit), with the static checks
bypassed so that the sandbox alone is tested; a few go through ``sga-agent evaluate`` too. Then:

- a candidate expected to be refused is not ``ok``;
- an ``ok`` one reports the loss a fresh trusted fit worker gives for the graph it was fitted
  on (``artifacts["captured"]``), to 1e-6 relative;
- the task caches (ground truth, Taichi's kernels) are byte-identical before and after;
- no output holds the secret marker (as text, as hex, or as byte values);
- no process of the capture user is left.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import sys
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from sga_agent.cli import main
from sga_agent.helper_protocol import FitSettings
from sga_agent.sandbox import SandboxLimits, SandboxPool, _LineProcess, worker_environment
from sga_agent.task import EvaluationSettings
from tasks.constitutive.options import ConstitutiveOptions
from tests.hostile.catalog import load_catalog
from tests.sga_agent.test_sandbox import ISOLATED, nobody_processes

pytestmark = [
    pytest.mark.skipif(not ISOLATED, reason="the capture cannot be isolated here"),
    pytest.mark.slow,  # one pool of sandboxed workers serves every candidate: minutes to start
]

CATALOG = load_catalog()
SETTINGS = EvaluationSettings(epochs=1, options=ConstitutiveOptions(steps=20))
SENT = FitSettings.of(SETTINGS)  # as a slot sends them to its fit worker
LIMITS = SandboxLimits(timeout_s=300, capture_timeout_s=10, memory_mb=2048)
MARKER = "SGA-HOSTILE-MARKER-7f3a"
SECRET = Path("/root/.sga-hostile-secret")


def cache_digests() -> dict[str, str]:
    """Content hash of every file in the task caches; of Taichi's index of its kernel cache,
    only that it is there.

    Taichi rewrites that index (``ticache.tcb``) when a process compiles a kernel, even one it
    does not cache: the trusted fit compiles a law it runs as Taichi kernels
    (:mod:`tasks.constitutive.law_kernel`) and writes none of them to the cache. Every kernel
    file, and the set of files, must stay as they were."""
    home = Path.home() / ".cache"
    roots = [Path(os.environ.get("SGA_CACHE_DIR") or home / "sga"), home / "taichi"]
    digests = {}
    for root in roots:
        for path in sorted(root.rglob("*")) if root.exists() else []:
            if path.is_file():
                digests[str(path)] = ("present" if path.name == "ticache.tcb" else
                                      hashlib.sha256(path.read_bytes()).hexdigest())  # fmt: skip
    return digests


@pytest.fixture(scope="module")
def evaluated():
    """Every candidate's evaluation, the caches before and after, processes left."""
    if os.getuid() == 0:
        SECRET.write_text(f"{MARKER}\n")
        SECRET.chmod(0o600)
    saved = {name: os.environ.get(name) for name in ("OPENAI_API_KEY", "SGA_HOSTILE_PLAIN")}
    os.environ.update(dict.fromkeys(saved, MARKER))  # never passed on to a helper
    laws = Path(__file__).parents[2] / "examples" / "laws"
    with SandboxPool(1, LIMITS) as pool:  # ground truth and kernels built before any candidate
        for task, law in (("granular", "fluid.py"), ("elastic", "neo_hookean.py")):
            [warm] = pool.map(task, [(laws / law).read_text()], SETTINGS)
            assert warm.valid, warm.reason
    before, processes = cache_digests(), nobody_processes()
    results = {}
    with SandboxPool(2, LIMITS) as pool:
        futures = {c.name: pool.submit(c.task, c.code, SETTINGS) for c in CATALOG}
        results = {name: future.result() for name, future in futures.items()}
    deadline = time.monotonic() + 10
    while nobody_processes() - processes and time.monotonic() < deadline:
        time.sleep(0.1)
    left = nobody_processes() - processes
    yield results, before, cache_digests(), left
    SECRET.unlink(missing_ok=True)
    for name, value in saved.items():
        if value is None:
            os.environ.pop(name, None)
        else:
            os.environ[name] = value


class Refitter:
    """Fresh trusted fit workers, one per task, kept warm for the whole module."""

    def __init__(self, folder: Path) -> None:
        self.folder, self.workers = folder, {}

    def __call__(self, task: str, data: dict) -> float:
        """The loss a trusted fit worker (not the one that scored it) gives for ``data``."""
        if task not in self.workers:
            command = [sys.executable, "-m", "sga_agent.fit_worker", task, "4096", SENT.options]
            worker = _LineProcess(command, worker_environment(LIMITS), self.folder, task)
            worker.ask(None, 600)
            self.workers[task] = worker
        request = {"data": data, "settings": SENT.request()}
        return float(self.workers[task].ask(request, 600)["loss"])

    def close(self) -> None:
        for worker in self.workers.values():
            worker.close()


@pytest.fixture(scope="module")
def refit(tmp_path_factory):
    refitter = Refitter(tmp_path_factory.mktemp("refit"))
    yield refitter
    refitter.close()


def leaks(evaluation_json: str) -> bool:
    hexed = MARKER.encode().hex()
    codes = ", ".join(str(1000 + byte) for byte in MARKER.encode()[:6])
    return MARKER in evaluation_json or hexed in evaluation_json or codes in evaluation_json


@pytest.mark.slow
@pytest.mark.parametrize("candidate", CATALOG, ids=[c.name for c in CATALOG])
def test_candidate_cannot_forge_or_leak(candidate, evaluated, refit):
    results, *_ = evaluated
    evaluation = results[candidate.name]
    if candidate.expected == "refused":
        assert evaluation.status != "ok", (evaluation.loss, evaluation.feedback[:300])
    if evaluation.status == "ok":
        honest = refit(candidate.task, evaluation.artifacts["captured"])
        assert math.isclose(evaluation.loss, honest, rel_tol=1e-6), (evaluation.loss, honest)
    assert not leaks(json.dumps(evaluation.to_dict()))


def test_caches_are_untouched_and_no_process_is_left(evaluated):
    _, before, after, left = evaluated
    assert after == before
    assert not left


@pytest.mark.slow
@pytest.mark.parametrize("name", ["01", "24", "61"])
def test_sga_agent_evaluate_takes_the_same_path(name, tmp_path, refit):
    [candidate] = [c for c in CATALOG if c.name.startswith(f"{name}_")]
    path = tmp_path / "law.py"
    path.write_text(candidate.code)
    result = CliRunner().invoke(
        main, ["evaluate", "--task", candidate.task, str(path), "--epochs", "1",
               "--option", "steps=20", "--json"],
    )  # fmt: skip
    [line] = [line for line in result.output.splitlines() if line.startswith("{")]
    evaluation = json.loads(line)
    if candidate.static == "rejected":
        assert evaluation["reason"].startswith("the code breaks the rules")
    elif evaluation["status"] == "ok":
        honest = refit(candidate.task, evaluation["artifacts"]["captured"])
        assert math.isclose(float(evaluation["loss"]), honest, rel_tol=1e-6)
    assert not leaks(result.output)


@pytest.mark.heavy
def test_a_search_driven_by_hostile_answers_ranks_honest_scores(tmp_path, refit):
    """A third of the granular candidates that pass the static checks, in a real search."""
    from sga_agent import registry
    from sga_agent.config import SearchConfig
    from sga_agent.run_store import RunStore
    from sga_agent.search import Search
    from tasks.constitutive.assessment import truth_loss
    from tasks.constitutive.specs import SPECS
    from tests.sga_agent.test_search import Scripted

    hostile = [c for c in CATALOG if c.task == "granular" and c.static == "passes"][::3]
    truth = (Path(__file__).parents[2] / "examples" / "laws" / "drucker_prager.py").read_text()
    answers = [f"### Code\n```python\n{code}```\n" for code in [truth] + [c.code for c in hostile]]
    explore = 6
    cfg = SearchConfig.from_settings(
        task="granular", proposer="scripted", iterations=-(-len(answers) // (explore + 1)),
        top_k=3, exploit=1, explore=explore, workers=2, epochs=1,
        task_options=SETTINGS.options, timeout_s=300.0, memory_mb=2048,
    )  # fmt: skip
    store = RunStore.create(tmp_path, cfg, {"proposer": "scripted"})
    # the summary's findings score the true law in this process (trusted code) and cache it:
    # cached here first, so that any change below would be the candidates' doing
    truth_loss(SPECS["granular"], cfg.task_options)
    before = cache_digests()
    limits = SandboxLimits(timeout_s=300.0, capture_timeout_s=10, memory_mb=2048)
    with SandboxPool(2, limits) as pool:
        result = Search(cfg, registry.load_task("granular"), Scripted(answers), pool, store).run()
    assert cache_digests() == before
    scored = 0
    for folder in sorted((store.path / "candidates").iterdir()):
        evaluation = json.loads((folder / "evaluation.json").read_text())
        if evaluation["status"] != "ok" or "duplicate_of" in evaluation["extras"]:
            continue
        artifacts = json.loads((folder / "artifacts.json").read_text())
        honest = refit("granular", artifacts["captured"])
        assert math.isclose(float(evaluation["loss"]), honest, rel_tol=1e-6), folder.name
        scored += 1
    assert scored >= 3
    best = result.top[0]
    assert best.loss < 1e-10, (best.candidate, best.loss)  # the true law tops an honest heap
    for name in ("evaluation.json", "feedback.txt", "curves.json", "artifacts.json"):
        for path in (store.path / "candidates").glob(f"*/{name}"):  # what the evaluations wrote
            assert not leaks(path.read_text(errors="replace")), path
    for event in store.events():
        if event["type"] == "evaluation":
            assert not leaks(json.dumps(event)), event["candidate"]
