"""Isolation of a sandbox worker beyond resource limits: no network, no writes outside its folder.

Static checks of a candidate's code are no sandbox (torch and numpy can write files, open URLs
and compile code), so the worker process itself is contained. :func:`isolate` applies, to the
calling process and everything it starts later, the strongest mechanisms the host allows:

- **Network**: a fresh network namespace (``unshare(CLONE_NEWNET)``; inside a new user namespace
  when not root), which has only a loopback interface, down. Landlock (ABI >= 4) also denies
  every TCP bind and connect.
- **Filesystem**: writes (creating, changing, removing, renaming files) only beneath
  :func:`writable_paths`: the working directory, the caches tasks legitimately write,
  ``/dev/null`` and GPU device nodes; reads stay allowed everywhere. Two independent layers:
  Landlock, and a private mount namespace where every mount is read-only except bind mounts of
  those folders (which also stops ``chmod`` and ``chown``, which Landlock does not cover).
- **Processes**: all capabilities are dropped (a candidate running as root can then neither
  raise its resource limits nor administer the host), and Landlock (ABI >= 6) stops signals
  to processes outside the worker, such as the search itself.

``unshare`` of a user namespace needs a single-threaded process and Landlock binds only the
calling thread, so :func:`isolate` runs before the worker imports the task (torch and Taichi
start threads). Each layer degrades gracefully: the :class:`Isolation` returned says what was
applied, "none: <why>" where nothing could be. :func:`detect_isolation` runs the same code in a
throw-away process (``python -m sga_agent.isolation``) so that the search can record it, and the
sandbox refuses to evaluate in a worker whose isolation differs from it.

Not covered: connections to path-named Unix sockets, and signals to the worker's own user's
processes on kernels with Landlock ABI < 6.
"""

from __future__ import annotations

import ctypes
import functools
import json
import os
import stat
import subprocess
import sys
import tempfile
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass
from glob import glob
from pathlib import Path

# Linux constants (uapi headers): namespaces, prctl, capabilities, Landlock, mount_setattr.
_CLONE_NEWNS = 0x00020000
_CLONE_NEWUSER = 0x10000000
_CLONE_NEWNET = 0x40000000
_PR_CAPBSET_DROP = 24
_PR_SET_NO_NEW_PRIVS = 38
_PR_CAP_AMBIENT = 47
_PR_CAP_AMBIENT_CLEAR_ALL = 4
_CAPABILITY_VERSION_3 = 0x20080522
_SYS_MOUNT_SETATTR = 442
_SYS_LANDLOCK_CREATE_RULESET = 444
_SYS_LANDLOCK_ADD_RULE = 445
_SYS_LANDLOCK_RESTRICT_SELF = 446
_LANDLOCK_CREATE_RULESET_VERSION = 1
_LANDLOCK_RULE_PATH_BENEATH = 1
_AT_FDCWD = -100
_AT_RECURSIVE = 0x8000
_MOUNT_ATTR_RDONLY = 0x1
_MS_BIND = 0x1000
_MS_REC = 0x4000
_MS_PRIVATE = 1 << 18

# Landlock filesystem rights that change the filesystem, by the ABI that introduced them.
_WRITE_FILE = 1 << 1
_TRUNCATE = 1 << 14  # ABI 3
_DIRECTORY_WRITES = sum(1 << bit for bit in (4, 5, 6, 7, 8, 9, 10, 11, 12))  # remove, make *
_REFER = 1 << 13  # ABI 2: link or rename into another directory
_NET_TCP = (1 << 0) | (1 << 1)  # ABI 4: bind, connect
_SCOPES = (1 << 0) | (1 << 1)  # ABI 6: abstract Unix sockets, signals

#: Device nodes a worker may open for writing: the null device and GPUs (CUDA, Vulkan).
DEVICE_PATTERNS = ("/dev/null", "/dev/nvidia*", "/dev/nvidia-caps/*", "/dev/dri/*")


@dataclass(frozen=True)
class Isolation:
    """What confines a worker, in words; each field starts with "none:" where nothing does.

    Parameters
    ----------
    network : str
        What stops network access, e.g. "network namespace (unshare)".
    filesystem : str
        What stops writes outside the worker's folder, e.g. "landlock ABI 7: ...".
    processes : str
        What stops the worker from acting on other processes and on the host.
    """

    network: str
    filesystem: str
    processes: str

    @classmethod
    def none(cls, why: str) -> Isolation:
        """No isolation at all, for one reason."""
        return cls(f"none: {why}", f"none: {why}", f"none: {why}")


def writable_paths(workdir: Path, environ: Mapping[str, str]) -> list[Path]:
    """Folders and device nodes a worker may write: its folder, devices, the tasks' caches.

    The caches are Taichi's (its offline kernel cache, ``$XDG_CACHE_HOME/taichi`` or
    ``~/.cache/taichi``, and ``$TI_OFFLINE_CACHE_FILE_PATH``) and this project's
    (``$SGA_CACHE_DIR``, else ``$XDG_CACHE_HOME/sga`` or ``~/.cache/sga``: ground-truth
    trajectories). Missing cache folders are created, so that a rule can name them.
    """
    home = Path(environ["HOME"]) if environ.get("HOME") else Path.home()
    cache_home = Path(environ.get("XDG_CACHE_HOME") or home / ".cache")
    caches = [cache_home / "taichi", Path(environ.get("SGA_CACHE_DIR") or cache_home / "sga")]
    if environ.get("TI_OFFLINE_CACHE_FILE_PATH"):
        caches.append(Path(environ["TI_OFFLINE_CACHE_FILE_PATH"]))
    paths = [workdir]
    for cache in caches:
        try:
            cache.mkdir(parents=True, exist_ok=True)
        except OSError:
            continue  # unwritable anyway: the task will report it
        paths.append(cache)
    devices = [Path(match) for pattern in DEVICE_PATTERNS for match in glob(pattern)]
    return [path.resolve() for path in paths] + [path for path in devices if _is_device(path)]


def _is_device(path: Path) -> bool:
    try:
        return stat.S_ISCHR(path.stat().st_mode)
    except OSError:
        return False


def isolate(writable: Iterable[Path]) -> Isolation:
    """Confine this process and its future children; writes stay allowed beneath ``writable``.

    Irreversible. Call it while the process has a single thread. Never raises: a mechanism
    that is unavailable is reported as "none: <why>" in the result.
    """
    if not sys.platform.startswith("linux"):
        return Isolation.none(f"unsupported on {sys.platform} (Linux only)")
    threads = len(os.listdir("/proc/self/task"))
    if threads > 1:
        return Isolation.none(f"the process already runs {threads} threads")
    libc = ctypes.CDLL(None, use_errno=True)
    writable = list(writable)
    namespace = _network_namespace(libc)
    mounts = _read_only_mounts(libc, writable)  # before Landlock, which forbids mounting
    landlock, landlock_network, scopes = _landlock(libc, writable)
    applied = [part for part in (landlock, mounts) if not part.startswith("none:")]
    filesystem = "; ".join(applied) or f"none: {_why(landlock)}; {_why(mounts)}"
    if not landlock_network:
        network = namespace
    elif namespace.startswith("none:"):
        network = f"{landlock_network} (no network namespace: {_why(namespace)})"
    else:
        network = f"{namespace}; {landlock_network}"
    processes = ["all capabilities dropped"] if _drop_capabilities(libc) else []
    processes += [scopes] if scopes else []
    return Isolation(
        network,
        filesystem,
        "; ".join(processes) or "none: capabilities kept, signals unrestricted",
    )


@functools.cache
def detect_isolation() -> Isolation:
    """The isolation a sandbox worker gets on this host (probed once per process).

    Runs :func:`isolate` in a short-lived ``python -m sga_agent.isolation`` (~0.1 s), so the
    answer is what workers really get, not a guess.
    """
    with tempfile.TemporaryDirectory(prefix="sga-isolation-") as folder:
        try:
            probe = subprocess.run(
                [sys.executable, "-m", "sga_agent.isolation"],
                cwd=folder,
                stdin=subprocess.DEVNULL,
                capture_output=True,
                text=True,
                timeout=60,
                check=True,
            )
            return Isolation(**json.loads(probe.stdout.splitlines()[-1]))
        except (OSError, subprocess.SubprocessError, ValueError, TypeError, IndexError) as error:
            return Isolation.none(f"the isolation probe failed ({type(error).__name__}: {error})")


def _network_namespace(libc: ctypes.CDLL) -> str:
    """Enter a new network namespace: directly when privileged, else in a user namespace."""
    if libc.unshare(_CLONE_NEWNET) == 0:
        return "network namespace (unshare)"
    privileged_error = _errno_text()
    uid, gid = os.getuid(), os.getgid()
    if libc.unshare(_CLONE_NEWUSER | _CLONE_NEWNET) != 0:
        return f"none: unshare failed ({privileged_error}; in a user namespace: {_errno_text()})"
    try:  # keep our own uid and gid inside, so that new files keep their owner
        Path("/proc/self/setgroups").write_text("deny")
        Path("/proc/self/uid_map").write_text(f"{uid} {uid} 1")
        Path("/proc/self/gid_map").write_text(f"{gid} {gid} 1")
    except OSError as error:
        return f"network namespace (unshare in a user namespace; no uid map: {error.strerror})"
    return "network namespace (unshare in a user namespace)"


def _syscall(libc: ctypes.CDLL, number: int, *args: object) -> int:
    """``syscall(2)`` with integer arguments passed as C longs, as the kernel reads them."""
    converted = [ctypes.c_long(arg) if isinstance(arg, int) else arg for arg in args]
    return libc.syscall(ctypes.c_long(number), *converted)


class _RulesetAttr(ctypes.Structure):
    _fields_ = [
        ("handled_access_fs", ctypes.c_uint64),
        ("handled_access_net", ctypes.c_uint64),  # ABI 4
        ("scoped", ctypes.c_uint64),  # ABI 6
    ]


class _PathBeneathAttr(ctypes.Structure):
    _pack_ = 1
    _fields_ = [("allowed_access", ctypes.c_uint64), ("parent_fd", ctypes.c_int32)]


def _landlock(libc: ctypes.CDLL, writable: list[Path]) -> tuple[str, str, str]:
    """Restrict writes to ``writable`` and, as the kernel's ABI allows, TCP and signals.

    Returns the descriptions of the filesystem, network and process restrictions; the first
    is "none: <why>" and the others empty where Landlock could not be enforced.
    """
    abi = _syscall(libc, _SYS_LANDLOCK_CREATE_RULESET, None, 0, _LANDLOCK_CREATE_RULESET_VERSION)
    if abi < 1:
        return f"none: no Landlock in this kernel ({_errno_text()})", "", ""
    name = f"landlock ABI {abi}"
    file_rights = _WRITE_FILE | (_TRUNCATE if abi >= 3 else 0)
    directory_rights = file_rights | _DIRECTORY_WRITES | (_REFER if abi >= 2 else 0)
    attr = _RulesetAttr(directory_rights, _NET_TCP if abi >= 4 else 0, _SCOPES if abi >= 6 else 0)
    ruleset = _syscall(libc, _SYS_LANDLOCK_CREATE_RULESET, ctypes.byref(attr),
                       ctypes.sizeof(attr), 0)  # fmt: skip
    if ruleset < 0:
        return f"none: {name} refused the ruleset ({_errno_text()})", "", ""
    try:
        for path in writable:
            _allow_writes(libc, ruleset, path, file_rights, directory_rights)
        if libc.prctl(_PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0) != 0 or (
            _syscall(libc, _SYS_LANDLOCK_RESTRICT_SELF, ruleset, 0) != 0
        ):
            return f"none: {name} could not be enforced ({_errno_text()})", "", ""
    except OSError as error:
        return f"none: {name}: {error.strerror} ({error.filename})", "", ""
    finally:
        os.close(ruleset)
    return (
        f"{name}: writes only in the working directory, the task caches and devices",
        f"{name}: TCP bind and connect denied" if abi >= 4 else "",
        f"{name}: signals and abstract Unix sockets confined to the worker" if abi >= 6 else "",
    )


def _allow_writes(
    libc: ctypes.CDLL, ruleset: int, path: Path, file_rights: int, directory_rights: int
) -> None:
    """Add a Landlock rule allowing writes beneath ``path`` (skipped if it vanished)."""
    try:
        fd = os.open(path, os.O_PATH | os.O_CLOEXEC)
    except OSError:
        return
    try:
        is_directory = stat.S_ISDIR(os.fstat(fd).st_mode)
        rule = _PathBeneathAttr(directory_rights if is_directory else file_rights, fd)
        if _syscall(libc, _SYS_LANDLOCK_ADD_RULE, ruleset, _LANDLOCK_RULE_PATH_BENEATH,
                    ctypes.byref(rule), 0) != 0:  # fmt: skip
            raise OSError(ctypes.get_errno(), "rule rejected", str(path))
    finally:
        os.close(fd)


class _MountAttr(ctypes.Structure):
    _fields_ = [
        ("attr_set", ctypes.c_uint64),
        ("attr_clr", ctypes.c_uint64),
        ("propagation", ctypes.c_uint64),
        ("userns_fd", ctypes.c_uint64),
    ]


def _read_only_mounts(libc: ctypes.CDLL, writable: list[Path]) -> str:
    """A private mount namespace, read-only but for bind mounts of the writable folders.

    Needs ``CAP_SYS_ADMIN`` (root, or the user namespace entered for the network) and
    ``mount_setattr`` (Linux >= 5.12). Besides writes, it stops ``chmod`` and ``chown``.
    """
    if libc.unshare(_CLONE_NEWNS) != 0:
        return f"none: no mount namespace ({_errno_text()})"

    def set_attributes(path: Path, flags: int, attr: _MountAttr) -> None:
        if _syscall(libc, _SYS_MOUNT_SETATTR, _AT_FDCWD, os.fsencode(path), flags,
                    ctypes.byref(attr), ctypes.sizeof(attr)) != 0:  # fmt: skip
            raise OSError(ctypes.get_errno(), "mount_setattr failed", str(path))

    root = Path("/")
    folders = [path for path in writable if path.is_dir()]
    try:
        set_attributes(root, _AT_RECURSIVE, _MountAttr(propagation=_MS_PRIVATE))
        for folder in folders:  # a mount of its own, made writable again below
            if libc.mount(os.fsencode(folder), os.fsencode(folder), None, _MS_BIND | _MS_REC,
                          None) != 0:  # fmt: skip
                raise OSError(ctypes.get_errno(), "bind mount failed", str(folder))
        set_attributes(root, _AT_RECURSIVE, _MountAttr(attr_set=_MOUNT_ATTR_RDONLY))
        for folder in folders:
            set_attributes(folder, 0, _MountAttr(attr_clr=_MOUNT_ATTR_RDONLY))
        os.chdir(os.getcwd())  # the old working directory lies on the mount under the bind
    except OSError as error:
        return f"none: read-only mounts failed ({error.strerror}: {error.filename})"
    return "mount namespace: read-only except the working directory and the task caches"


def _drop_capabilities(libc: ctypes.CDLL) -> bool:
    """Empty the bounding, ambient, effective, permitted and inheritable capability sets."""
    try:
        last = int(Path("/proc/sys/kernel/cap_last_cap").read_text())
    except (OSError, ValueError):
        last = 63
    for capability in range(last + 1):
        libc.prctl(_PR_CAPBSET_DROP, capability, 0, 0, 0)  # fails harmlessly without CAP_SETPCAP
    libc.prctl(_PR_CAP_AMBIENT, _PR_CAP_AMBIENT_CLEAR_ALL, 0, 0, 0)
    header = (ctypes.c_uint32 * 2)(_CAPABILITY_VERSION_3, 0)
    data = (ctypes.c_uint32 * 6)()  # two {effective, permitted, inheritable}, all zero
    return libc.capset(header, data) == 0


def _why(description: str) -> str:
    """The reason in a "none: <why>" description."""
    return description.removeprefix("none: ")


def _errno_text() -> str:
    return os.strerror(ctypes.get_errno())


def _probe() -> None:
    """Isolate this process in the current directory and print the result as JSON."""
    isolation = isolate(writable_paths(Path.cwd(), os.environ))
    print(json.dumps(asdict(isolation)))


if __name__ == "__main__":
    _probe()
