"""A real two-node Ray cluster on this machine (two raylets on loopback addresses), and the loss
of its second node in the middle of a search: nothing is lost, nothing is recorded twice, the
candidate the lost node was evaluating is evaluated again on the head, and Ray's messages about
the dead node stay off the search's screen.

The nodes are started with ``ray start`` on 127.0.0.2 (head) and 127.0.0.3; only loopback
addresses are used. The search runs in a child process (its stdout and stderr are its screen),
with the test-double task of :mod:`tests.sga_agent.test_ray`.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from sga_agent.run_store import RunStore

from .test_ray import REPO_ROOT, needs_ray, sandbox_workers

HEAD, SECOND = "127.0.0.2", "127.0.0.3"


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind((HEAD, 0))
        return probe.getsockname()[1]


def ray_command() -> str:
    return str(Path(sys.executable).with_name("ray"))


class Cluster:
    """Two Ray nodes started for one test, in a temporary folder of their own, and stopped by
    killing their processes only (``ray stop`` would stop every Ray process of the machine)."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.port = free_port()
        # the nodes' workers import the test-double task from this repository
        path = [str(REPO_ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]
        self.env = {**os.environ, "RAY_AUTH_MODE": "disabled",
                    "PYTHONPATH": os.pathsep.join(path)}  # fmt: skip
        common = ["--num-cpus=1", "--disable-usage-stats"]
        self._start(["--head", f"--node-ip-address={HEAD}", f"--port={self.port}",
                     "--include-dashboard=false", f"--temp-dir={folder}", *common])  # fmt: skip
        self._start([f"--address={self.address}", f"--node-ip-address={SECOND}", *common])

    @property
    def address(self) -> str:
        return f"{HEAD}:{self.port}"

    def _start(self, arguments: list[str]) -> None:
        subprocess.run([ray_command(), "start", *arguments], env=self.env, check=True,
                       capture_output=True, timeout=120)  # fmt: skip

    def processes(self, marker: str = "") -> list[tuple[int, str]]:
        """(pid, command line) of this cluster's processes (those naming its folder or port)."""
        found = []
        for proc in Path("/proc").glob("[0-9]*"):
            try:
                command = (proc / "cmdline").read_bytes().replace(b"\0", b" ").decode()
            except OSError:
                continue
            ours = str(self.folder) in command or f"{HEAD}:{self.port}" in command
            if ours and marker in command and int(proc.name) != os.getpid():
                found.append((int(proc.name), command))
        return found

    def second_raylet(self) -> int:
        (pid,) = [pid for pid, command in self.processes("raylet")
                  if f"--node_ip_address={SECOND}" in command and "/raylet " in command + " "]
        return pid

    def stop(self) -> None:
        for _ in range(3):
            for pid, _ in self.processes():
                with contextlib.suppress(ProcessLookupError):
                    os.kill(pid, signal.SIGKILL)
            time.sleep(0.5)
        # a later ray.init() without an address would try to join the cluster this names
        for named in (self.folder / "ray_current_cluster", Path("/tmp/ray/ray_current_cluster")):
            with contextlib.suppress(OSError):
                if named.read_text().strip() == self.address:
                    named.unlink()


def children(pid: int) -> list[int]:
    """Pids of the direct children of process ``pid``."""
    found = []
    for proc in Path("/proc").glob("[0-9]*"):
        try:
            parent = int((proc / "stat").read_text().rpartition(")")[2].split()[1])
        except (OSError, ValueError, IndexError):
            continue
        if parent == pid:
            found.append(int(proc.name))
    return found


def lose_the_second_node(tmp: str, address: str, raylet: int) -> None:
    """The child process: a search on the cluster whose second node is lost (its raylet and
    the Ray workers it started, SIGKILLed together, as when the machine goes) while both slots
    evaluate."""
    from concurrent.futures import ThreadPoolExecutor

    from sga_agent import registry, runner

    from .test_ray import Scripted, answer, code, config

    registry.load_task = registry.resolve_task
    tmp_path = Path(tmp)
    release = tmp_path / "release"
    waiting = f"wait:{release}"
    cfg = config(executor="ray", ray_address=address, iterations=2, exploit=1, explore=1)
    store = RunStore.create(tmp_path / "runs", cfg, {})
    proposer = Scripted([answer(code(waiting, 0.5)), answer(code(waiting, 0.25)),
                         answer(code("ok", 0.1)), answer(code("ok", 0.2))])  # fmt: skip
    with ThreadPoolExecutor(1) as background:
        search = background.submit(runner.run, cfg, store, None, proposer)
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not search.done():
            if sum(waiting in s for *_, s in sandbox_workers(tmp_path)) == 2:
                break
            time.sleep(0.05)
        workers = children(raylet)
        for pid in [raylet, *workers]:
            os.kill(pid, signal.SIGKILL)
        print(f"second node killed while both slots evaluated ({len(workers)} workers)",
              flush=True)  # fmt: skip
        release.touch()
        result = search.result(timeout=240)
    print(f"search finished: {result.totals.evaluations} evaluations", flush=True)


@needs_ray
@pytest.mark.slow
def test_losing_a_node_mid_search_loses_nothing_and_records_nothing_twice(tmp_path):
    # Ray's socket paths live under its folder and must stay short: not under tmp_path
    cluster = Cluster(Path(tempfile.mkdtemp(prefix="ray-", dir="/tmp")))
    try:
        raylet = cluster.second_raylet()
        program = ("from tests.sga_agent.test_ray_cluster import lose_the_second_node; "
                   f"lose_the_second_node({str(tmp_path)!r}, {cluster.address!r}, {raylet})")
        run = subprocess.run([sys.executable, "-c", program], cwd=REPO_ROOT, env=cluster.env,
                             capture_output=True, text=True, timeout=420)  # fmt: skip
    finally:
        cluster.stop()
        shutil.rmtree(cluster.folder, ignore_errors=True)
    assert "second node killed while both slots evaluated" in run.stdout, run.stderr[-3000:]
    assert "search finished: 5 evaluations" in run.stdout, run.stderr[-3000:]
    # Ray's messages about the dead node and its workers stay in Ray's logs
    assert "raylet" not in run.stderr and "Worker" not in run.stderr, run.stderr[-3000:]
    (folder,) = (tmp_path / "runs").iterdir()
    store = RunStore.open(folder)
    evaluated = [event["candidate"] for event in store.events()
                 if event["type"] == "evaluation"]  # fmt: skip
    assert len(evaluated) == len(set(evaluated)) == 5  # the seed and four offspring, once each
    records = {
        name: json.loads((folder / "candidates" / name / "evaluation.json").read_text())
        for name in evaluated
    }
    assert {name: (r["status"], r["loss"]) for name, r in records.items()} == {
        "00-seed": ("ok", 3.0), "01-exploit-00": ("ok", 0.5), "01-explore-00": ("ok", 0.25),
        "02-exploit-00": ("ok", 0.1), "02-explore-00": ("ok", 0.2),
    }  # fmt: skip
    nodes = {r["extras"]["node"] for r in records.values()}
    assert nodes == {HEAD, SECOND} or nodes == {HEAD}, nodes
    retried = [name for name, r in records.items() if "retried" in r["extras"]]
    assert len(retried) == 1 and retried[0].startswith("01-"), records
    assert records[retried[0]]["extras"]["node"] == HEAD
