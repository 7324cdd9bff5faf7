"""Isolation of capture processes: no network, no writes, no secrets, no signals out, as recorded.

The behaviour tests run a candidate in the real sandbox (its capture step executes it) and skip,
with the recorded reason, where this host does not offer the mechanism (macOS, a container
without namespaces).
"""

import errno
import json
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import uuid
from pathlib import Path

import pytest

from sga_agent.isolation import Isolation, detect_isolation, paths_inside, readable_paths
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
    lines = ["import os, signal, socket", "report = {}"]
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


def test_host_unix_sockets_are_out_of_reach():
    require("filesystem", "private")
    folder = Path(tempfile.mkdtemp(prefix="sga-socket-", dir="/tmp"))
    path = folder / "host.sock"
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as server:
        server.bind(str(path))
        os.chmod(folder, 0o755)
        os.chmod(path, 0o777)
        server.listen(1)
        server.setblocking(False)
        candidate = attempts(
            path_socket=f"socket.socket(socket.AF_UNIX).connect({str(path)!r})",
            listing="report['tmp'] = os.listdir('/tmp')",
        )
        evaluation = sandboxed(candidate)
        assert evaluation.valid, evaluation.reason
        report = evaluation.extras["report"]
        assert report["path_socket"] in (errno.ENOENT, errno.EACCES), report
        assert report.get("tmp", []) == [] or report["listing"] != "done"
        with pytest.raises(BlockingIOError):
            server.accept()
    shutil.rmtree(folder)


def test_nothing_can_be_written(tmp_path):
    require("filesystem")
    outside = [tmp_path / "outside.txt", REPO_ROOT / f"outside-{uuid.uuid4().hex}.txt"]
    cache = Path.home() / ".cache" / "sga" / f"probe-{uuid.uuid4().hex}"
    candidate = attempts(
        cwd="open('inside.txt', 'w').write('ok')",
        temporary=f"open({str(outside[0])!r}, 'w').write('escaped')",
        repository=f"open({str(outside[1])!r}, 'w').write('escaped')",
        cache=f"open({str(cache)!r}, 'w').write('poison')",
        tmp="open('/tmp/left-behind', 'w').write('x')",
        chmod=f"os.chmod({str(tmp_path)!r}, 0o777)",
    )
    try:
        evaluation = sandboxed(candidate)
        report = evaluation.extras["report"]
        refused = {errno.EACCES, errno.EPERM, errno.EROFS, errno.ENOENT}
        assert set(report.values()) <= refused, report
        assert not any(path.exists() for path in [*outside, cache])
    finally:
        for path in outside:
            path.unlink(missing_ok=True)


def test_secrets_cannot_be_read(tmp_path):
    require("filesystem", "reads only")
    secret = tmp_path / "secret.txt"
    secret.write_text("SGA-ISOLATION-SECRET")
    secret.chmod(0o600)
    candidate = attempts(
        shadow="open('/etc/shadow').read()",
        secret=f"open({str(secret)!r}).read()",
        home=f"os.listdir({str(Path.home())!r})",
        parent=f"open('/proc/{os.getpid()}/environ').read()",
    )
    evaluation = sandboxed(candidate)
    report = evaluation.extras["report"]
    assert set(report.values()) <= {errno.EACCES, errno.EPERM, errno.ENOENT}, report
    assert "SGA-ISOLATION-SECRET" not in json.dumps(evaluation.to_dict())


def test_a_python_environment_under_tmp_stays_importable():
    """A package first imported inside the capture, from a folder under /tmp (a venv there),
    is found; the rest of /tmp stays hidden."""
    require("filesystem", "private")
    folder = Path(tempfile.mkdtemp(dir="/tmp"))
    try:
        folder.chmod(0o755)
        environment = folder / "site-packages"
        package = environment / f"lazy_{uuid.uuid4().hex}"
        package.mkdir(parents=True)
        (package / "__init__.py").write_text("VALUE = 'imported lazily'\n")
        (folder / "secret.txt").write_text("SGA-ISOLATION-SECRET")
        candidate = (
            f"import importlib\nmodule = importlib.import_module({package.name!r})\n"
            "report = {'value': module.VALUE}\n"
            f"try:\n    report['secret'] = open({str(folder / 'secret.txt')!r}).read()\n"
            "except OSError as error:\n    report['secret'] = error.errno\n"
        )
        evaluation = evaluate_in_sandbox(
            DOUBLE, candidate, EvaluationSettings(), SandboxLimits(timeout_s=60),
            extra_python_path=[REPO_ROOT, environment],
        )  # fmt: skip
        assert evaluation.valid, evaluation.reason
        report = evaluation.extras["report"]
        assert report["value"] == "imported lazily"
        assert report["secret"] in (errno.EACCES, errno.EPERM, errno.ENOENT)
    finally:
        shutil.rmtree(folder)


def test_signals_to_other_processes_are_refused():
    require("processes", "signals")
    sleeper = subprocess.Popen(["sleep", "60"])
    try:
        evaluation = sandboxed(attempts(kill=f"os.kill({sleeper.pid}, signal.SIGKILL)"))
        assert evaluation.extras["report"]["kill"] in (errno.EPERM, errno.ESRCH)
        assert sleeper.poll() is None
    finally:
        sleeper.kill()
        sleeper.wait()


@pytest.mark.skipif(not LINUX or os.getuid() != 0, reason="as root only")
def test_root_becomes_nobody_without_capabilities():
    require("processes", "nobody")
    candidate = (
        "import ctypes, os\n"
        "libc = ctypes.CDLL(None)\n"
        "header = (ctypes.c_uint32 * 2)(0x20080522, 0)\n"
        "data = (ctypes.c_uint32 * 6)()\n"
        "libc.capget(header, data)\n"
        "report = [os.getuid(), os.getgid(), os.getgroups(), list(data)]\n"
    )
    evaluation = sandboxed(candidate)
    assert evaluation.extras["report"] == [65534, 65534, [], [0] * 6]


def test_readable_paths_are_python_packages_and_libraries():
    paths = readable_paths()
    assert Path(sys.base_prefix).resolve() in paths
    assert REPO_ROOT.resolve() / "sga_agent" in paths or any(
        REPO_ROOT.resolve().is_relative_to(path) for path in paths
    )
    assert not {Path("/"), Path("/etc"), Path.home(), Path("/tmp")} & set(paths)


@pytest.mark.skipif(
    not (LINUX and os.geteuid() == 0 and shutil.which("setpriv")), reason="needs root, setpriv"
)
def test_an_unprivileged_user_gets_namespaces_in_a_user_namespace(tmp_path):
    require("network", "namespace")
    completed = subprocess.run(
        ["setpriv", "--inh-caps=-all", "--bounding-set=-all", "--reuid=65534", "--regid=65534",
         "--clear-groups", sys.executable, "-m", "sga_agent.isolation"],
        cwd=tmp_path, capture_output=True, text=True, timeout=60,
        env={**os.environ, "PYTHONPATH": str(REPO_ROOT)},
    )  # fmt: skip
    if completed.returncode != 0:
        pytest.skip(f"python is not usable as nobody here: {completed.stderr[-200:]}")
    report = json.loads(completed.stdout.splitlines()[-1])
    assert report["network"].startswith("network namespace"), report
    assert "not root" in report["processes"]


def test_only_the_outermost_paths_inside_a_private_folder_are_bound():
    paths = [Path("/tmp/x/.venv/lib"), Path("/tmp/x/.venv"), Path("/usr/lib"), Path("/tmp")]
    assert paths_inside(paths, ("/tmp", "/run")) == [Path("/tmp/x/.venv")]
