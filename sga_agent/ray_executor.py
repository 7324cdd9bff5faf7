"""Evaluating candidates on a Ray cluster: :class:`RayPool`, the distributed twin of SandboxPool.

Each evaluation is a Ray task that calls :func:`~sga_agent.sandbox.evaluate_in_sandbox` on the
node Ray schedules it on, so it is captured in the same confined process and fitted by the
same trusted fit worker as on this machine, with the same limits, isolation, timeouts and
outcomes (the helpers start afresh for each evaluation there, not warm). Ray picks the node
from the resources each task reserves (``cpus_per_task``, ``memory_mb``); every node needs this
project installed at the same version (and the path of ``extra_python_path``, if any).

Failures
--------
A task whose Ray worker process or node dies is retried once (:data:`TASK_RETRIES`, Ray's
``max_retries``; the capture server and fit worker die with their Ray worker, so nothing is
left running). If the retry is lost too, or Ray cannot run the task at all, its future holds an
invalid :class:`~sga_agent.task.Evaluation` whose reason names Ray and its error: status
"crashed" for a lost worker, node or result, "out_of_memory" when Ray's memory monitor killed
the worker, "error" otherwise; the search records it as any other outcome. One failure is not
an outcome of the candidate: when the Ray node of the search's own machine stops (the cluster
was shut down, or its head node died), every later task would fail too, so the futures raise
:class:`RayClusterLostError` instead; the search stops, leaves these candidates unrecorded,
and ``sga-agent resume`` evaluates them once a cluster is back.

The search must run on a node of the cluster (usually the head), as every Ray driver does.

Ray is an optional dependency (:data:`RAY_INSTALL`), imported when a pool is created.
"""

from __future__ import annotations

import functools
import logging
import os
import socket
import threading
from collections.abc import Sequence
from concurrent.futures import Future, wait
from types import ModuleType
from typing import Any

from sga_agent.isolation import Isolation, detect_isolation
from sga_agent.sandbox import SandboxLimits, _settings_json, evaluate_in_sandbox
from sga_agent.task import Evaluation, EvaluationSettings

#: How to install the optional dependency.
RAY_INSTALL = 'pip install "sga-agent[ray]"'
#: Retries of a task whose Ray worker or node died (failures of the candidate are not retried).
TASK_RETRIES = 1
#: Seconds to wait for a TCP connection to the head node before giving up on it.
CONNECT_TIMEOUT_S = 10.0


class RayUnavailableError(RuntimeError):
    """Ray is not installed or its cluster cannot be reached; the message says what to do."""


class RayClusterLostError(RayUnavailableError):
    """This machine's Ray node stopped (the cluster is gone): no evaluation can run any more."""


def import_ray() -> ModuleType:
    """The ``ray`` module, or :class:`RayUnavailableError` naming the install command."""
    try:
        import ray
    except ImportError as error:
        raise RayUnavailableError(
            f"the ray executor needs Ray, which is not installed here: {RAY_INSTALL} (in a "
            'checkout: pip install -e ".[ray]"), or evaluate here with --executor local'
        ) from error
    return ray


class RayPool:
    """Evaluate candidates as Ray tasks, each captured and fitted on a node of the cluster.

    Same interface as :class:`~sga_agent.sandbox.SandboxPool`. If this process is already
    connected to Ray (``ray.init`` was called), that connection is used and left open;
    otherwise the pool connects (or starts a local instance) and disconnects in :meth:`close`.

    Parameters
    ----------
    address : str, optional
        The cluster: "HOST:PORT" of its head node, or "auto" (Ray's own lookup:
        ``RAY_ADDRESS``, else a cluster started on this machine with ``ray start``). None
        starts a private local Ray instance with ``local_cpus`` CPUs, stopped by :meth:`close`.
    limits : SandboxLimits
        Limits of every evaluation, applied on the node.
    cpus_per_task : float
        CPUs each evaluation reserves on its node (Ray's ``num_cpus``).
    memory_mb : int, optional
        Memory each evaluation reserves on its node in MiB (Ray's ``memory``; a scheduling
        reservation, the enforced limit is ``limits.memory_mb``).
    local_cpus : int, optional
        CPUs of the local instance (default: this machine's); ignored with an address.
    extra_python_path : sequence of path-like
        As for :func:`~sga_agent.sandbox.evaluate_in_sandbox`; the same paths on every node.

    Raises
    ------
    RayUnavailableError
        Ray is not installed, or no cluster answers at ``address``.
    """

    def __init__(
        self,
        address: str | None = None,
        limits: SandboxLimits = SandboxLimits(),  # noqa: B008 (frozen)
        *,
        cpus_per_task: float = 1.0,
        memory_mb: int | None = None,
        local_cpus: int | None = None,
        extra_python_path: Sequence[str | os.PathLike[str]] = (),
    ) -> None:
        self._ray = import_ray()
        self.limits = limits
        self.cpus_per_task = cpus_per_task
        self.memory_mb = memory_mb
        self.extra_python_path = tuple(os.path.abspath(path) for path in extra_python_path)
        self._options: dict[str, Any] = {"num_cpus": cpus_per_task, "max_retries": TASK_RETRIES}
        if memory_mb is not None:
            self._options["memory"] = memory_mb * 2**20
        self._pending: dict[Future[Evaluation], Any] = {}  # our future -> its ObjectRef
        self._lock = threading.Lock()
        self._connected_here = not self._ray.is_initialized()
        if self._connected_here:
            _connect(self._ray, address, local_cpus)
        try:
            self._check_feasible()
        except RayUnavailableError:
            self.close()
            raise
        self._evaluate = self._ray.remote(**self._options)(_evaluate_on_node)

    def isolation(self) -> Isolation:
        """How the workers are isolated, for the run's record (probed on one Ray node)."""
        if not self.limits.isolation:
            return Isolation.none("disabled (SandboxLimits.isolation=False)")
        probe = self._ray.remote(**self._options)(_node_isolation)
        try:
            return self._ray.get(probe.remote())
        except self._ray.exceptions.LocalRayletDiedError as error:
            raise _cluster_lost(error) from error
        except self._ray.exceptions.RayError as error:
            return Isolation.none(f"the isolation probe on a Ray node failed: {_first_line(error)}")

    def describe(self) -> dict[str, Any]:
        """The cluster and the resources per evaluation, for the run's record."""
        ray = self._ray
        return {
            "executor": "ray",
            "ray_address": ray.get_runtime_context().gcs_address,
            "nodes": sum(1 for node in ray.nodes() if node.get("Alive")),
            "cpus": ray.cluster_resources().get("CPU", 0.0),
            "cpus_per_task": self.cpus_per_task,
            "memory_mb_per_task": self.memory_mb,
        }

    def _check_feasible(self) -> None:
        """Fail now, rather than wait forever, if no node has the resources of an evaluation."""
        needed = {"CPU": self.cpus_per_task, "memory": self._options.get("memory", 0)}
        nodes = [node.get("Resources", {}) for node in self._ray.nodes() if node.get("Alive")]
        if any(all(node.get(key, 0) >= value for key, value in needed.items()) for node in nodes):
            return
        largest = max((node.get("CPU", 0) for node in nodes), default=0)
        memory = f" and {self.memory_mb} MiB" if self.memory_mb is not None else ""
        raise RayUnavailableError(
            f"no node of the Ray cluster can run an evaluation reserving {self.cpus_per_task:g} "
            f"CPUs{memory} (the largest has {largest:g} CPUs); lower --ray-cpus or "
            "--ray-memory-mb, or add larger nodes"
        )

    def submit(self, task: str, solution: str, settings: EvaluationSettings) -> Future[Evaluation]:
        """Start evaluating one solution on the cluster; the future's result is its Evaluation.

        Raises ``TypeError`` at once if ``settings.options`` is not JSON-serialisable; a bad
        candidate or a lost Ray task never raises: its future holds an invalid Evaluation
        (only the loss of this machine's Ray node makes it raise :class:`RayClusterLostError`).
        """
        _settings_json(settings)  # the sandbox's own check, here
        reference = self._evaluate.remote(
            task, solution, settings, self.limits, self.extra_python_path
        )
        result: Future[Evaluation] = Future()
        with self._lock:
            self._pending[result] = reference
        reference.future().add_done_callback(functools.partial(self._settle, result))
        return result

    def close(self, wait_for_pending: bool = True) -> None:
        """Wait for running evaluations (or cancel them), then disconnect if connected here.

        Disconnecting stops a local instance the pool started, and ends the pool's tasks on a
        cluster; a connection made before the pool stays open.
        """
        with self._lock:
            pending = dict(self._pending)
        if wait_for_pending:
            wait(pending)
        elif not self._connected_here:
            for reference in pending.values():
                self._ray.cancel(reference, force=True)
        if self._connected_here and self._ray.is_initialized():
            self._ray.shutdown()

    def __enter__(self) -> RayPool:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, *exc_info: object) -> None:
        self.close(wait_for_pending=exc_type is None)

    def _settle(self, result: Future[Evaluation], ray_future: Future[Evaluation]) -> None:
        """Resolve ``result`` from the Ray task's outcome; a Ray failure becomes an Evaluation."""
        with self._lock:
            self._pending.pop(result, None)
        try:
            evaluation = ray_future.result()
        except self._ray.exceptions.LocalRayletDiedError as error:
            result.set_exception(_cluster_lost(error))
            return
        except Exception as error:  # the task was lost (after its retry) or never ran
            evaluation = _lost(self._ray, error)
        result.set_result(evaluation)


def _connect(ray: ModuleType, address: str | None, local_cpus: int | None) -> None:
    """``ray.init``: a new local instance for None, else the cluster at ``address``."""
    quiet = {"log_to_driver": False, "logging_level": logging.WARNING}
    if address is None:
        ray.init(address="local", num_cpus=local_cpus, include_dashboard=False, **quiet)
        return
    if address != "auto":  # ray.init would retry an unreachable address for minutes
        host, _, port = address.rpartition(":")
        try:
            socket.create_connection((host, int(port)), timeout=CONNECT_TIMEOUT_S).close()
        except OSError as error:
            raise RayUnavailableError(
                f"no Ray head node answers at {address} ({error.strerror or error}); start one "
                f"there with `ray start --head --port={port}` or correct --ray-address"
            ) from error
    try:
        ray.init(address=address, **quiet)
    except ConnectionError as error:
        raise RayUnavailableError(
            f"could not connect to a Ray cluster at {address}: {_first_line(error)} (start "
            "one with `ray start --head`; a cluster with token authentication, the default "
            "from Ray 2.59, also needs RAY_AUTH_MODE=token and its token here)"
        ) from error


def _evaluate_on_node(
    task: str,
    solution: str,
    settings: EvaluationSettings,
    limits: SandboxLimits,
    extra_python_path: tuple[str, ...],
) -> Evaluation:
    """The Ray task: one sandboxed evaluation on this node (never raises)."""
    try:
        return evaluate_in_sandbox(
            task, solution, settings, limits, extra_python_path=extra_python_path
        )
    except Exception as error:  # the sandbox itself failed, e.g. no space for its folder
        reason = f"the sandbox failed on Ray node {socket.gethostname()}: "
        return Evaluation.invalid(f"{reason}{type(error).__name__}: {error}", status="error")


def _node_isolation() -> Isolation:
    """The Ray task probing a node's isolation."""
    return detect_isolation()


def _lost(ray: ModuleType, error: Exception) -> Evaluation:
    """The evaluation of a Ray task that failed (its retry included) or never ran."""
    described = f"{type(error).__name__}: {_first_line(error)}"
    if isinstance(error, ray.exceptions.OutOfMemoryError):
        reason = f"Ray's memory monitor killed the worker evaluating it ({described})"
        return Evaluation.invalid(reason, status="out_of_memory")
    exceptions = ray.exceptions
    lost = (exceptions.WorkerCrashedError, exceptions.NodeDiedError, exceptions.ObjectLostError)
    if isinstance(error, lost):
        tries = f"tried {1 + TASK_RETRIES} times"
        reason = f"lost on Ray: the worker or node evaluating it died ({tries}; {described})"
        return Evaluation.invalid(reason, status="crashed")
    return Evaluation.invalid(f"Ray could not evaluate it ({described})", status="error")


def _cluster_lost(error: Exception) -> RayClusterLostError:
    return RayClusterLostError(
        f"the Ray node of this machine stopped ({_first_line(error)}); the search stops, and "
        "the candidates it was evaluating are not recorded"
    )


def _first_line(error: BaseException) -> str:
    lines = str(error).strip().splitlines()
    return lines[0] if lines else ""
