"""Confining the process that runs a candidate's code (the capture process).

Static checks of a candidate's code are no sandbox (torch and numpy can write files, open URLs
and compile code), so the process that runs it is confined. :func:`run_confined` runs one
function in a grandchild process, ``G``, under every mechanism the host offers:

- **Processes**: ``G`` is process 1 of a new PID namespace, so when it ends the kernel kills
  every process it started (double-forked ``setsid`` daemons included); it dies with its parent.
  As root, ``G`` switches to the unprivileged user ``nobody`` (files only root may read become
  unreadable); it keeps no capability; Landlock (ABI >= 6) stops signals to processes outside it.
- **Network**: a new network namespace (only a loopback interface, down); Landlock (ABI >= 4)
  also denies TCP bind and connect. A new IPC namespace hides the host's System V objects.
- **Filesystem**: a private mount namespace in which ``/tmp``, ``/run``, ``/var/tmp`` and
  ``/dev/shm`` are fresh empty file systems (no host socket or shared-memory file is reachable;
  the Python environment's own folders inside them, a virtual environment under /tmp, are
  bound back in) and every mount is read-only; ``/proc`` shows only the namespace's processes.
  Landlock denies every write and every read outside the Python installation, its packages and
  the system libraries (``/etc``, home directories and caches are unreadable).
- **Resources**: address space (``RLIMIT_AS``, which counts shared mappings), process count
  (``RLIMIT_NPROC``), CPU time, file size, no core dumps.

Namespaces need root, or an unprivileged user namespace (then ``G`` stays the calling user,
mapped to root inside the namespace, and cannot become ``nobody``). Each layer degrades
gracefully: the :class:`Isolation` returned says what was applied, "none: <why>" where nothing
could be. :func:`detect_isolation` runs the same code in a throw-away process so that a search
can record it, and the capture server refuses to capture in a process confined otherwise.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import json
import os
import resource
import select
import signal
import stat
import subprocess
import sys
import sysconfig
import time
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass
from pathlib import Path

# Linux constants (uapi headers): namespaces, prctl, capabilities, Landlock, mount_setattr.
_CLONE_NEWNS = 0x00020000
_CLONE_NEWUTS = 0x04000000
_CLONE_NEWIPC = 0x08000000
_CLONE_NEWUSER = 0x10000000
_CLONE_NEWPID = 0x20000000
_CLONE_NEWNET = 0x40000000
_PR_SET_PDEATHSIG = 1
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
_MS_NOSUID, _MS_NODEV, _MS_NOEXEC = 0x2, 0x4, 0x8
_MS_BIND = 0x1000
_MS_REC = 0x4000
_MS_PRIVATE = 1 << 18

# Landlock filesystem rights, by the ABI that introduced them.
_EXECUTE, _WRITE_FILE, _READ_FILE, _READ_DIR = 1 << 0, 1 << 1, 1 << 2, 1 << 3
_DIRECTORY_WRITES = sum(1 << bit for bit in (4, 5, 6, 7, 8, 9, 10, 11, 12))  # remove, make *
_REFER = 1 << 13  # ABI 2: link or rename into another directory
_TRUNCATE = 1 << 14  # ABI 3
_NET_TCP = (1 << 0) | (1 << 1)  # ABI 4: bind, connect
_SCOPES = (1 << 0) | (1 << 1)  # ABI 6: abstract Unix sockets, signals

NOBODY = 65534
#: Fresh, empty file systems mounted over these (where they exist).
PRIVATE_FOLDERS = ("/tmp", "/var/tmp", "/run", "/dev/shm")
#: System folders the confined process may read (shared libraries loaded lazily).
SYSTEM_READABLE = ("/usr/lib", "/usr/lib64", "/usr/local/lib", "/lib", "/lib64")
#: Device nodes the confined process may open: read and write the null device, read random.
DEVICES = {"/dev/null": _READ_FILE | _WRITE_FILE, "/dev/urandom": _READ_FILE}
#: Processes (and threads) the confined user may have, when it is ``nobody``.
PROCESS_LIMIT = 256
#: Exit status of the middle process when the confined process was killed by signal ``s``.
SIGNAL_EXIT_BASE = 128


@dataclass(frozen=True)
class Isolation:
    """What confines a capture process, in words; "none: <why>" where nothing does.

    Parameters
    ----------
    network : str
        What stops network access, e.g. "network namespace; landlock ABI 7: TCP denied".
    filesystem : str
        What stops reads of secrets and writes, e.g. "read-only mounts; landlock ...".
    processes : str
        Who the process runs as, what kills its descendants, which limits hold it.
    """

    network: str
    filesystem: str
    processes: str

    @classmethod
    def none(cls, why: str) -> Isolation:
        """No isolation at all, for one reason."""
        return cls(f"none: {why}", f"none: {why}", f"none: {why}")


@dataclass(frozen=True)
class ConfinedRun:
    """How one confined run ended.

    ``status`` is "ok" (the function returned), "timeout", "crashed" (killed by a signal, or an
    exit without output) or "error" (the confinement differs from the expected one, or the
    process could not be started). ``output`` is what the function returned (at most
    ``max_output`` bytes: untrusted), ``isolation`` what ``G`` reported before running it.
    """

    status: str
    output: bytes = b""
    isolation: Isolation | None = None
    signal: int = 0
    exit_code: int = 0
    detail: str = ""


def run_confined(
    work: Callable[[], bytes],
    *,
    timeout_s: float,
    memory_mb: int,
    cpu_time_s: int,
    file_size_mb: int,
    isolate: bool = True,
    expected: Isolation | None = None,
    max_output: int = 16 * 2**20,
) -> ConfinedRun:
    """Run ``work()`` in a confined grandchild process and return its bytes.

    Call it from a single-threaded process (namespaces and Landlock need one). ``expected``,
    when given, is the isolation the caller recorded: a process confined otherwise is killed
    before ``work`` runs and the run is an "error".
    """
    result_read, result_write = os.pipe()
    control_read, control_write = os.pipe()
    started = time.monotonic()
    pid = os.fork()
    if pid == 0:  # the middle process: namespaces, then the confined grandchild
        try:
            os.close(result_read)
            os.close(control_read)
            _middle(work, result_write, control_write, isolate, memory_mb, cpu_time_s,
                    file_size_mb)  # fmt: skip
        finally:
            os._exit(70)
    os.close(result_write)
    os.close(control_write)
    buffers = {control_read: bytearray(), result_read: bytearray()}
    try:
        finished = _collect(
            buffers,
            started + timeout_s,
            {control_read: 65536, result_read: max_output},
            on_close=(control_read, lambda text: _check_isolation(text, expected, pid)),
        )
    finally:
        os.close(result_read)
        os.close(control_read)
    if not finished:
        _kill(pid)
    _, status = os.waitpid(pid, 0)
    code = os.waitstatus_to_exitcode(status)
    isolation = _parse_isolation(bytes(buffers[control_read]))
    if not finished:
        return ConfinedRun("timeout", isolation=isolation, detail=f"{timeout_s:g} s")
    output = bytes(buffers[result_read])
    if expected is not None and isolation != expected:
        return ConfinedRun("error", isolation=isolation, detail=_difference(isolation, expected))
    if code >= SIGNAL_EXIT_BASE or code < 0:
        number = code - SIGNAL_EXIT_BASE if code >= SIGNAL_EXIT_BASE else -code
        return ConfinedRun("crashed", output, isolation, signal=number)
    if code != 0 or not output:
        return ConfinedRun("crashed", output, isolation, exit_code=code)
    return ConfinedRun("ok", output, isolation)


def _collect(buffers, deadline, limits, on_close) -> bool:
    """Read the pipes in ``buffers`` until they close; False if ``deadline`` comes first.

    ``on_close`` = (fd, check): ``check(text)`` runs once ``fd`` has closed and may kill the
    process (a wrong isolation). Bytes beyond a pipe's limit are dropped.
    """
    open_fds = set(buffers)
    checked = False
    while open_fds:
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            return False
        ready, _, _ = select.select(list(open_fds), [], [], min(remaining, 0.5))
        for fd in ready:
            chunk = os.read(fd, 65536)
            if not chunk:
                open_fds.discard(fd)
                continue
            room = limits[fd] - len(buffers[fd])
            if room > 0:
                buffers[fd] += chunk[:room]
        fd, check = on_close
        if not checked and fd not in open_fds:
            checked = True
            check(bytes(buffers[fd]))
    return True


def _check_isolation(text: bytes, expected: Isolation | None, pid: int) -> None:
    if expected is not None and _parse_isolation(text) != expected:
        _kill(pid)


def _parse_isolation(text: bytes) -> Isolation | None:
    try:
        return Isolation(**json.loads(text))
    except (ValueError, TypeError):
        return None


def _difference(applied: Isolation | None, expected: Isolation) -> str:
    if applied is None:
        return "the process did not report its isolation"
    fields = [f"{key}: {value}" for key, value in asdict(applied).items()
              if value != getattr(expected, key)]  # fmt: skip
    return "; ".join(fields)


def _kill(pid: int) -> None:
    with contextlib.suppress(ProcessLookupError):
        os.kill(pid, signal.SIGKILL)


# -------------------------------------------------------------------- the two child processes


def _middle(work, result_write, control_write, isolate, memory_mb, cpu_time_s, file_size_mb):
    """Enter new namespaces, fork the confined process, wait for it, pass on its status."""
    libc = ctypes.CDLL(None, use_errno=True)
    libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
    namespaces = _unshare(libc) if isolate else "none: isolation disabled"
    child = os.fork()
    if child == 0:
        try:
            _confined(work, result_write, control_write, isolate, namespaces,
                      memory_mb, cpu_time_s, file_size_mb)  # fmt: skip
        finally:
            os._exit(71)
    os.close(result_write)
    os.close(control_write)
    _, status = os.waitpid(child, 0)
    code = os.waitstatus_to_exitcode(status)
    os._exit(code if code >= 0 else SIGNAL_EXIT_BASE - code)


def _confined(work, result_write, control_write, isolate, namespaces, memory_mb, cpu_time_s,
              file_size_mb) -> None:  # fmt: skip
    """The confined process: apply everything, report it, run ``work``, write its bytes."""
    libc = ctypes.CDLL(None, use_errno=True)
    middle = os.getppid()  # 0 as seen from inside a new PID namespace
    _die_with(libc, middle)
    os.setsid()  # no signal to its old process group reaches the server
    null = os.open(os.devnull, os.O_RDWR)
    for fd in (0, 1, 2):
        os.dup2(null, fd)
    keep = sorted({0, 1, 2, result_write, control_write})
    for low, high in zip(keep, [*keep[1:], os.sysconf("SC_OPEN_MAX")], strict=True):
        os.closerange(low + 1, high)
    if isolate:
        isolation = confine(libc, namespaces, memory_mb, cpu_time_s, file_size_mb)
    else:
        _limit(memory_mb, cpu_time_s, file_size_mb, None)
        isolation = Isolation.none("disabled (SandboxLimits.isolation=False)")
    _die_with(libc, middle)  # a change of user clears the parent-death signal
    _write_all(control_write, json.dumps(asdict(isolation)).encode())
    os.close(control_write)
    _write_all(result_write, work())
    os._exit(0)


def die_with_parent() -> None:
    """Have the kernel kill this process when its parent dies (Linux; elsewhere nothing)."""
    if sys.platform.startswith("linux"):
        _die_with(ctypes.CDLL(None, use_errno=True), os.getppid())


def _die_with(libc: ctypes.CDLL, parent: int) -> None:
    libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
    if os.getppid() != parent:
        os._exit(1)


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view) :]


# ------------------------------------------------------------------------- the mechanisms


def _unshare(libc: ctypes.CDLL) -> str:
    """New PID, network, mount, IPC and UTS namespaces (in a user namespace if not root)."""
    flags = _CLONE_NEWPID | _CLONE_NEWNET | _CLONE_NEWNS | _CLONE_NEWIPC | _CLONE_NEWUTS
    if libc.unshare(flags) == 0:
        return "namespaces"
    privileged_error = _errno_text()
    uid, gid = os.getuid(), os.getgid()
    if libc.unshare(_CLONE_NEWUSER | flags) != 0:
        return f"none: unshare failed ({privileged_error}; in a user namespace: {_errno_text()})"
    try:  # root inside the namespace (to mount), the calling user outside
        Path("/proc/self/setgroups").write_text("deny")
        Path("/proc/self/uid_map").write_text(f"0 {uid} 1")
        Path("/proc/self/gid_map").write_text(f"0 {gid} 1")
    except OSError as error:
        return f"namespaces in a user namespace (no uid map: {error.strerror})"
    return "namespaces in a user namespace"


def confine(
    libc: ctypes.CDLL, namespaces: str, memory_mb: int, cpu_time_s: int, file_size_mb: int
) -> Isolation:
    """Confine the calling process (process 1 of the namespaces ``_unshare`` made)."""
    readable = readable_paths()  # before the user changes: it may import modules
    in_namespaces = not namespaces.startswith("none:")
    mounts = _private_mounts(libc, readable) if in_namespaces else f"none: {_why(namespaces)}"
    was_root = os.getuid() == 0 and namespaces == "namespaces"
    limits = _limit(memory_mb, cpu_time_s, file_size_mb, PROCESS_LIMIT if was_root else None)
    user = _become_nobody(libc) if was_root else _drop_capabilities(libc)
    landlock, landlock_network, scopes = _landlock(libc, readable)
    network = "network namespace" if in_namespaces else f"none: {_why(namespaces)}"
    if landlock_network:
        network = (
            landlock_network if network.startswith("none:") else f"{network}; {landlock_network}"
        )
    filesystem = "; ".join(p for p in (mounts, landlock) if not p.startswith("none:"))
    processes = [user]
    if in_namespaces:
        processes.append("PID namespace: its descendants die with it")
    processes += [scopes] if scopes else []
    processes.append(limits)
    return Isolation(
        network,
        filesystem or f"none: {_why(mounts)}; {_why(landlock)}",
        "; ".join(processes),
    )


def _private_mounts(libc: ctypes.CDLL, readable: Iterable[Path]) -> str:
    """Fresh /tmp, /run, /var/tmp, /dev/shm and /proc, then everything read-only.

    The readable paths that lie inside a private folder (a virtual environment or a checkout
    under /tmp) are bound back into it, so the confined process sees the same Python.
    """

    def mount(source: str, target: str, kind: str | None, flags: int, data: str | None) -> None:
        if libc.mount(os.fsencode(source), os.fsencode(target),
                      kind.encode() if kind else None, flags,
                      data.encode() if data else None) != 0:  # fmt: skip
            raise OSError(ctypes.get_errno(), "mount failed", target)

    inside = paths_inside(readable, PRIVATE_FOLDERS)
    try:
        _mount_setattr(libc, "/", _AT_RECURSIVE, _MountAttr(propagation=_MS_PRIVATE))
        handles = {path: os.open(path, os.O_PATH) for path in inside}  # before they are hidden
        for folder in PRIVATE_FOLDERS:
            if os.path.isdir(folder):
                mount("none", folder, "tmpfs", _MS_NOSUID | _MS_NODEV | _MS_NOEXEC,
                      "size=1m,mode=755")  # fmt: skip
        for path, handle in handles.items():
            _make_mount_point(path, handle)
            mount(f"/proc/self/fd/{handle}", str(path), None, _MS_BIND | _MS_REC, None)
            os.close(handle)
        try:
            mount("proc", "/proc", "proc", _MS_NOSUID | _MS_NODEV | _MS_NOEXEC, None)
            proc = "/proc of its own PID namespace"
        except OSError as error:
            proc = f"host /proc ({error.strerror})"
        _mount_setattr(libc, "/", _AT_RECURSIVE, _MountAttr(attr_set=_MOUNT_ATTR_RDONLY))
    except OSError as error:
        return f"none: private mounts failed ({error.strerror}: {error.filename})"
    return f"read-only mounts, empty private {', '.join(PRIVATE_FOLDERS)}; {proc}"


def paths_inside(paths: Iterable[Path], folders: Iterable[str]) -> list[Path]:
    """The ``paths`` strictly inside one of ``folders``, none inside another one listed."""
    roots = [Path(folder) for folder in folders]
    inside = sorted(path for path in paths if any(root in path.parents for root in roots))
    return [path for path in inside if not any(other in path.parents for other in inside)]


def _make_mount_point(path: Path, handle: int) -> None:
    """An empty directory (or file) at ``path`` on the fresh file system, to mount onto."""
    if stat.S_ISDIR(os.fstat(handle).st_mode):
        path.mkdir(parents=True, exist_ok=True)
    else:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.touch()


def _limit(memory_mb: int, cpu_time_s: int, file_size_mb: int, processes: int | None) -> str:
    """Resource limits; the address space counts what is mapped already (Python, torch)."""
    mapped = _mapped_bytes()
    address_space = mapped + memory_mb * 2**20
    resource.setrlimit(resource.RLIMIT_AS, (address_space, address_space))
    resource.setrlimit(resource.RLIMIT_CPU, (cpu_time_s, cpu_time_s + 5))
    file_size = file_size_mb * 2**20
    resource.setrlimit(resource.RLIMIT_FSIZE, (file_size, file_size))
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    limited = "address space, CPU time, file size"
    if processes is not None:
        resource.setrlimit(resource.RLIMIT_NPROC, (processes, processes))
        limited += f", processes ({processes})"
    return f"limits on {limited}"


def _mapped_bytes() -> int:
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmSize:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return 0


def _become_nobody(libc: ctypes.CDLL) -> str:
    """Drop the bounding set, then become ``nobody`` (which empties the capability sets)."""
    last = _last_capability()
    for capability in range(last + 1):
        libc.prctl(_PR_CAPBSET_DROP, capability, 0, 0, 0)
    libc.prctl(_PR_CAP_AMBIENT, _PR_CAP_AMBIENT_CLEAR_ALL, 0, 0, 0)
    try:
        os.setgroups([])
        os.setresgid(NOBODY, NOBODY, NOBODY)
        os.setresuid(NOBODY, NOBODY, NOBODY)
    except OSError as error:
        return f"none: could not become nobody ({error.strerror})" + _capabilities(libc)
    return f"user nobody ({NOBODY}), no capabilities"


def _drop_capabilities(libc: ctypes.CDLL) -> str:
    for capability in range(_last_capability() + 1):
        libc.prctl(_PR_CAPBSET_DROP, capability, 0, 0, 0)  # fails harmlessly without the cap
    return f"user {os.getuid()} (not root: cannot become nobody)" + _capabilities(libc)


def _capabilities(libc: ctypes.CDLL) -> str:
    libc.prctl(_PR_CAP_AMBIENT, _PR_CAP_AMBIENT_CLEAR_ALL, 0, 0, 0)
    header = (ctypes.c_uint32 * 2)(_CAPABILITY_VERSION_3, 0)
    data = (ctypes.c_uint32 * 6)()  # two {effective, permitted, inheritable}, all zero
    return ", no capabilities" if libc.capset(header, data) == 0 else ", capabilities kept"


def _last_capability() -> int:
    try:
        return int(Path("/proc/sys/kernel/cap_last_cap").read_text())
    except (OSError, ValueError):
        return 63


def readable_paths() -> list[Path]:
    """What a confined process may read: Python, its packages, system libraries, devices."""
    roots = {sys.prefix, sys.base_prefix, sys.exec_prefix, sys.base_exec_prefix}
    roots.update(sysconfig.get_paths().values())
    roots.update(entry for entry in sys.path if entry and os.path.isabs(entry))
    for module in list(sys.modules.values()):
        location = getattr(module, "__file__", None)
        if location and "site-packages" not in location and "dist-packages" not in location:
            roots.add(str(Path(location).parent))  # a source checkout (editable install)
    roots.update(SYSTEM_READABLE)
    paths = [Path(root).resolve() for root in roots if os.path.exists(root)]
    return sorted({path for path in paths if path != Path("/")})


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


def _landlock(libc: ctypes.CDLL, readable: Iterable[Path]) -> tuple[str, str, str]:
    """No writes; reads beneath ``readable``; as the ABI allows, no TCP, no signals out.

    Returns the descriptions of the filesystem, network and process restrictions; the first
    is "none: <why>" and the others empty where Landlock could not be enforced.
    """
    abi = _syscall(libc, _SYS_LANDLOCK_CREATE_RULESET, None, 0, _LANDLOCK_CREATE_RULESET_VERSION)
    if abi < 1:
        return f"none: no Landlock in this kernel ({_errno_text()})", "", ""
    name = f"landlock ABI {abi}"
    writes = _WRITE_FILE | _DIRECTORY_WRITES | (_REFER if abi >= 2 else 0)
    writes |= _TRUNCATE if abi >= 3 else 0
    reads = _EXECUTE | _READ_FILE | _READ_DIR
    attr = _RulesetAttr(writes | reads, _NET_TCP if abi >= 4 else 0, _SCOPES if abi >= 6 else 0)
    ruleset = _syscall(libc, _SYS_LANDLOCK_CREATE_RULESET, ctypes.byref(attr),
                       ctypes.sizeof(attr), 0)  # fmt: skip
    if ruleset < 0:
        return f"none: {name} refused the ruleset ({_errno_text()})", "", ""
    try:
        for path in readable:
            _allow(libc, ruleset, path, reads)
        for device, rights in DEVICES.items():
            _allow(libc, ruleset, Path(device), rights)
        if libc.prctl(_PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0) != 0 or (
            _syscall(libc, _SYS_LANDLOCK_RESTRICT_SELF, ruleset, 0) != 0
        ):
            return f"none: {name} could not be enforced ({_errno_text()})", "", ""
    except OSError as error:
        return f"none: {name}: {error.strerror} ({error.filename})", "", ""
    finally:
        os.close(ruleset)
    return (
        f"{name}: no writes; reads only beneath Python, its packages and system libraries",
        f"{name}: TCP bind and connect denied" if abi >= 4 else "",
        f"{name}: signals and abstract Unix sockets confined" if abi >= 6 else "",
    )


def _allow(libc: ctypes.CDLL, ruleset: int, path: Path, rights: int) -> None:
    """Add a Landlock rule granting ``rights`` beneath ``path`` (skipped if it vanished)."""
    try:
        fd = os.open(path, os.O_PATH | os.O_CLOEXEC)
    except OSError:
        return
    try:
        if not stat.S_ISDIR(os.fstat(fd).st_mode):
            rights &= _EXECUTE | _WRITE_FILE | _READ_FILE | _TRUNCATE
        rule = _PathBeneathAttr(rights, fd)
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


def _mount_setattr(libc: ctypes.CDLL, path: str, flags: int, attr: _MountAttr) -> None:
    if _syscall(libc, _SYS_MOUNT_SETATTR, _AT_FDCWD, os.fsencode(path), flags,
                ctypes.byref(attr), ctypes.sizeof(attr)) != 0:  # fmt: skip
        raise OSError(ctypes.get_errno(), "mount_setattr failed", path)


def _why(description: str) -> str:
    """The reason in a "none: <why>" description."""
    return description.removeprefix("none: ")


def _errno_text() -> str:
    return os.strerror(ctypes.get_errno())


# ------------------------------------------------------------------------------- detection


@functools.cache
def detect_isolation() -> Isolation:
    """The isolation a capture process gets on this host (probed once per process).

    Runs :func:`run_confined` in a short-lived ``python -m sga_agent.isolation`` (~0.2 s), so
    the answer is what capture processes really get, not a guess.
    """
    if not sys.platform.startswith("linux"):
        return Isolation.none(f"unsupported on {sys.platform} (Linux only)")
    try:
        probe = subprocess.run(
            [sys.executable, "-m", "sga_agent.isolation"],
            stdin=subprocess.DEVNULL,
            capture_output=True,
            text=True,
            timeout=60,
            check=True,
        )
        return Isolation(**json.loads(probe.stdout.splitlines()[-1]))
    except (OSError, subprocess.SubprocessError, ValueError, TypeError, IndexError) as error:
        return Isolation.none(f"the isolation probe failed ({type(error).__name__}: {error})")


def _probe() -> None:
    """Confine a grandchild as a capture would be, and print what it reported, as JSON."""
    run = run_confined(lambda: b"probed", timeout_s=30, memory_mb=512, cpu_time_s=30,
                       file_size_mb=1)  # fmt: skip
    isolation = run.isolation or Isolation.none(f"the probe ended with {run.status}")
    print(json.dumps(asdict(isolation)))


if __name__ == "__main__":
    _probe()
