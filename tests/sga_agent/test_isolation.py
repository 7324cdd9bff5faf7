"""Isolation of sandbox workers: no network, no writes outside, no signals out, as recorded.

The behaviour tests run a candidate in the real sandbox and skip, with the recorded reason,
where this host does not offer the mechanism (macOS, a container without namespaces).
"""

import errno
import json
import os
import shutil
import socket
import subprocess
import sys
import uuid
from pathlib import Path

import pytest

from sga_agent.isolation import Isolation, detect_isolation, writable_paths
from sga_agent.sandbox import SandboxLimits, evaluate_in_sandbox
from sga_agent.task import EvaluationSettings

REPO_ROOT = Path(__file__).resolve().parents[2]
DOUBLE = "tests.sga_agent.doubles:ExecTask"
LINUX = sys.platform.startswith("linux")


def sandboxed(solution: str):
    limits = SandboxLimits(timeout_s=60)
    return evaluate_in_sandbox(
        DOUBLE, solution, EvaluationSettings(), limits, extra_python_path=[REPO_ROOT]
    )


def require(field: str, word: str = "") -> None:
    """Skip unless the recorded isolation has ``field`` (mentioning ``word``)."""
    value = getattr(detect_isolation(), field)
    if value.startswith("none:") or word not in value:
        pytest.skip(f"{field} isolation on this host: {value}")


def attempts(**code: str) -> str:
    """A candidate trying each snippet; ``report`` maps its name to "done" or the errno."""
    lines = ["import os, signal, socket, tempfile", "report = {}"]
    for name, snippet in code.items():
        lines += [
            "try:",
            f"    {snippet}",
            f"    report[{name!r}] = 'done'",
            "except OSError as error:",
            f"    report[{name!r}] = error.errno",
        ]
    return "\n".join(lines) + "\n"


def test_detected_isolation_is_recorded_in_words():
    isolation = detect_isolation()
    assert all(isinstance(value, str) and value for value in vars(isolation).values())
    if not LINUX:
        assert isolation == Isolation.none(f"unsupported on {sys.platform} (Linux only)")


def test_network_is_unreachable():
    require("network")
    with (
        socket.create_server(("127.0.0.1", 0)) as server,
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as udp,
    ):
        udp.bind(("127.0.0.1", 0))
        server.setblocking(False)
        udp.setblocking(False)
        tcp_port, udp_port = server.getsockname()[1], udp.getsockname()[1]
        candidate = attempts(
            local_tcp=f"socket.create_connection(('127.0.0.1', {tcp_port}), timeout=5)",
            local_udp="socket.socket(type=socket.SOCK_DGRAM).sendto("
            f"b'x', ('127.0.0.1', {udp_port}))",
            outbound="socket.create_connection(('192.0.2.1', 80), timeout=5)",
        )
        evaluation = sandboxed(candidate)
        assert evaluation.valid, evaluation.reason
        report = evaluation.extras["report"]
        assert set(report.values()) <= {errno.EACCES, errno.ENETUNREACH}, report
        with pytest.raises(BlockingIOError):
            server.accept()
        with pytest.raises(BlockingIOError):
            udp.recv(1)


def test_writes_outside_the_working_directory_are_refused(tmp_path, monkeypatch):
    require("filesystem")
    monkeypatch.setenv("SGA_CACHE_DIR", str(tmp_path / "cache"))
    outside = [tmp_path / "outside.txt", REPO_ROOT / f"outside-{uuid.uuid4().hex}.txt"]
    candidate = attempts(
        cwd="open('inside.txt', 'w').write('ok')",
        tmpdir="tempfile.mkstemp()",
        cache=f"open({str(tmp_path / 'cache' / 'trajectory.npz')!r}, 'w').write('ok')",
        temporary=f"open({str(outside[0])!r}, 'w').write('escaped')",
        repository=f"open({str(outside[1])!r}, 'w').write('escaped')",
        remove=f"os.rmdir({str(tmp_path / 'cache')!r})",
        chmod=f"os.chmod({str(tmp_path)!r}, 0o777)",
    )
    try:
        evaluation = sandboxed(candidate)
        report = evaluation.extras["report"]
        assert {key: report[key] for key in ("cwd", "tmpdir", "cache")} == dict.fromkeys(
            ("cwd", "tmpdir", "cache"), "done"
        )
        refused = {errno.EACCES, errno.EPERM, errno.EROFS}
        for key in ("temporary", "repository", "remove"):
            assert report[key] in refused, report
        if "mount namespace" in detect_isolation().filesystem:  # Landlock lets chmod through
            assert report["chmod"] == errno.EROFS
        assert not any(path.exists() for path in outside)
        assert (tmp_path / "cache" / "trajectory.npz").read_text() == "ok"
    finally:
        for path in outside:
            path.unlink(missing_ok=True)


def test_signals_to_other_processes_are_refused():
    require("processes", "signals")
    sleeper = subprocess.Popen(["sleep", "60"])
    try:
        evaluation = sandboxed(attempts(kill=f"os.kill({sleeper.pid}, signal.SIGKILL)"))
        assert evaluation.extras["report"] == {"kill": errno.EPERM}
        assert sleeper.poll() is None
    finally:
        sleeper.kill()
        sleeper.wait()


def test_capabilities_are_dropped():
    require("processes", "capabilities")
    candidate = "report = open('/proc/self/status').read().split('CapEff:')[1].split()[0]\n"
    assert sandboxed(candidate).extras["report"] == "0" * 16


def run_probe(code: str, cwd: Path, prefix: tuple[str, ...] = ()) -> dict:
    """Run ``code`` (which prints JSON) in a fresh interpreter in ``cwd``."""
    completed = subprocess.run(
        [*prefix, sys.executable, "-c", code],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ, "PYTHONPATH": str(REPO_ROOT)},
    )
    assert completed.returncode == 0, completed.stderr
    return json.loads(completed.stdout)


@pytest.mark.skipif(not LINUX, reason="Linux isolation")
def test_without_landlock_the_mounts_are_read_only(tmp_path):
    code = """if True:
        import json, os
        from dataclasses import asdict
        from pathlib import Path
        from sga_agent import isolation
        isolation._landlock = lambda libc, writable: ("none: pretend", "", "")
        applied = isolation.isolate(isolation.writable_paths(Path.cwd(), os.environ))
        report = {"isolation": asdict(applied)}
        for name, path in [("inside", "inside.txt"), ("outside", "../outside.txt")]:
            try:
                Path(path).write_text("x")
                report[name] = "done"
            except OSError as error:
                report[name] = error.errno
        print(json.dumps(report))
    """
    (tmp_path / "work").mkdir()
    report = run_probe(code, tmp_path / "work")
    filesystem = report["isolation"]["filesystem"]
    if not filesystem.startswith("mount namespace"):
        pytest.skip(f"no mount namespace here: {filesystem}")
    assert (report["inside"], report["outside"]) == ("done", errno.EROFS)
    assert not (tmp_path / "outside.txt").exists()


@pytest.mark.skipif(not LINUX, reason="Linux isolation")
def test_isolation_is_refused_once_threads_run(tmp_path):
    code = """if True:
        import json, threading, time
        from dataclasses import asdict
        from sga_agent.isolation import isolate
        threading.Thread(target=time.sleep, args=(5,), daemon=True).start()
        print(json.dumps(asdict(isolate([]))))
    """
    report = run_probe(code, tmp_path)
    assert report == vars(Isolation.none("the process already runs 2 threads"))


@pytest.mark.skipif(
    not (LINUX and os.geteuid() == 0 and shutil.which("setpriv")), reason="needs root, setpriv"
)
def test_unprivileged_process_gets_its_network_namespace_in_a_user_namespace(tmp_path):
    require("network", "namespace")
    code = """if True:
        import json
        from dataclasses import asdict
        from sga_agent.isolation import isolate
        print(json.dumps(asdict(isolate([]))))
    """
    no_capabilities = ("setpriv", "--inh-caps=-all", "--bounding-set=-all")
    report = run_probe(code, tmp_path, prefix=no_capabilities)
    assert report["network"].startswith("network namespace (unshare in a user namespace")


def test_writable_paths_are_the_working_directory_caches_and_devices(tmp_path):
    environ = {
        "HOME": str(tmp_path / "home"),
        "XDG_CACHE_HOME": str(tmp_path / "xdg"),
        "SGA_CACHE_DIR": str(tmp_path / "sga"),
        "TI_OFFLINE_CACHE_FILE_PATH": str(tmp_path / "ticache"),
    }
    paths = writable_paths(tmp_path / "work", environ)
    expected = [tmp_path / name for name in ("work", "xdg/taichi", "sga", "ticache")]
    assert paths[:4] == [path.resolve() for path in expected]
    assert all(path.is_dir() for path in expected[1:])  # created, so that rules can name them
    if LINUX:
        assert Path("/dev/null") in paths
    defaults = writable_paths(tmp_path, {"HOME": str(tmp_path / "home")})
    assert defaults[1:3] == [tmp_path / "home/.cache/taichi", tmp_path / "home/.cache/sga"]
