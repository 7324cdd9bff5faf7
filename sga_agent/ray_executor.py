"""Evaluating candidates on a Ray cluster: :class:`RayPool`, the distributed twin of SandboxPool.

The pool keeps one Ray actor per evaluation slot of the cluster (its CPUs divided by the CPUs
an evaluation reserves). Each actor holds an :class:`~sga_agent.sandbox.EvaluationSlot` on its
node: a confined capture server and a trusted fit worker, started once and kept warm from
candidate to candidate, exactly as the local pool keeps its slots. An evaluation therefore
costs on a node what it costs here, with the same limits, isolation, timeouts and outcomes; its
``extras`` name the node (``node``). Ray places the actors from the resources each reserves
(``cpus_per_task``, ``memory_mb``); every node needs this project installed at the same version
(and the path of ``extra_python_path``, if any).

Failures
--------
A candidate is not blamed for its slot: when an actor's process or node dies while it
evaluates, the candidate is evaluated once more on another slot, and its ``extras["retried"]``
says why; a replacement actor is started in the background. If the second slot dies too, its
future holds an invalid :class:`~sga_agent.task.Evaluation` with status "crashed" whose reason
names Ray and its error ("error" when Ray cannot run it at all); the search records it as any
other outcome. One failure is not an
outcome of the candidate: when the Ray node of the search's own machine stops (the cluster was
shut down, or its head node died), every later evaluation would fail too, so the futures raise
:class:`RayClusterLostError` instead; the search stops, leaves these candidates unrecorded, and
``sga-agent resume`` evaluates them once a cluster is back. Slots whose processes outlive
their raylet may answer first, or finish the search: what they answer is recorded once, like
any other evaluation.

The search must run on a node of the cluster (usually the head), as every Ray driver does. Ray's
own messages about lost workers and nodes go to its log files, not to the search's screen. Ray
runs its workers, and so the slots' helpers, at nice 15 unless a node is started with
``RAY_worker_niceness=0``: on nodes shared with other work, start them so (the local instance
a pool starts itself does).

Ray is an optional dependency (:data:`RAY_INSTALL`), imported when a pool is created.
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import queue
import socket
import threading
from collections.abc import Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from types import ModuleType
from typing import Any

from sga_agent.helper_protocol import FitSettings
from sga_agent.isolation import Isolation, detect_isolation
from sga_agent.sandbox import EvaluationSlot, SandboxLimits
from sga_agent.task import Evaluation, EvaluationSettings

#: How to install the optional dependency.
RAY_INSTALL = 'pip install "sga-agent[ray]"'
#: Ray's setting of its workers' nice value (15 unless set when a node starts).
WORKER_NICENESS = "RAY_worker_niceness"
#: Further slots a candidate is tried on when its slot's process or node dies meanwhile
#: (failures of the candidate itself are never retried).
SLOT_RETRIES = 1
#: Seconds a replacement slot may take to be placed and answer before it is given up.
REPLACEMENT_TIMEOUT_S = 300.0
#: Seconds the slots may take to stop their helpers when the pool closes.
CLOSE_TIMEOUT_S = 60.0
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
    """Evaluate candidates on the slots of a Ray cluster, each a warm actor on a node.

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
        Limits of every evaluation, applied on the node (``limits.threads`` should match
        ``cpus_per_task``: the threads of the fit's parallel loops).
    cpus_per_task : float
        CPUs each slot reserves on its node (Ray's ``num_cpus``).
    memory_mb : int, optional
        Memory each slot reserves on its node in MiB (Ray's ``memory``; a scheduling
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
        self._options: dict[str, Any] = {"num_cpus": cpus_per_task}
        if memory_mb is not None:
            self._options["memory"] = memory_mb * 2**20
        self._connected_here = not self._ray.is_initialized()
        if self._connected_here:
            _connect(self._ray, address, local_cpus)
        try:
            self._check_feasible()
        except RayUnavailableError:
            self.close()
            raise
        self._actor_class = self._ray.remote(**self._options)(NodeSlot)
        self._lock = threading.Lock()
        self._free: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self._slots: list[Any] = []  # every actor started, live or starting
        self._replacements: set[Any] = set()  # actors started for dead slots, not ready yet
        self._warm: set[tuple[str, str]] = set()  # (task, options) the slots were warmed for
        self._closed = False
        for _ in range(self._slot_count()):
            actor = self._actor_class.remote(self.limits, self.extra_python_path)
            self._slots.append(actor)
            self._free.put(actor)
        self._executor = ThreadPoolExecutor(len(self._slots), thread_name_prefix="sga-ray")

    def _slot_count(self) -> int:
        """Slots the cluster's CPUs hold (at least one: the feasibility check passed)."""
        cpus = self._ray.cluster_resources().get("CPU", 0.0)
        return max(1, math.floor(cpus / self.cpus_per_task + 1e-9))

    def isolation(self) -> Isolation:
        """How the workers are isolated, for the run's record (probed on one Ray node)."""
        if not self.limits.isolation:
            return Isolation.none("disabled (SandboxLimits.isolation=False)")
        probe = self._ray.remote(num_cpus=0)(_node_isolation)
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
            "slots": len(self._slots),
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

    def submit(
        self,
        task: str,
        solution: str,
        settings: EvaluationSettings,
        captured: dict[str, Any] | None = None,
    ) -> Future[Evaluation]:
        """Start evaluating one solution on the cluster; the future's result is its Evaluation.
        ``captured`` fits it again without a capture (see
        :meth:`~sga_agent.sandbox.EvaluationSlot.evaluate`).

        Raises ``TypeError`` at once if ``settings.options`` cannot be sent (see
        :func:`~sga_agent.sandbox.evaluate_in_sandbox`); a bad candidate or a lost Ray slot
        never raises: its future holds an invalid Evaluation (only the loss of this machine's
        Ray node makes it raise :class:`RayClusterLostError`). The options travel to the slots
        as their JSON text.
        """
        sent = FitSettings.of(settings)
        self._warm_up(task, sent.options)
        return self._executor.submit(self._evaluate, task, solution, sent, captured)

    def _warm_up(self, task: str, options: str) -> None:
        """Have every slot start its helpers for ``task`` and ``options``, once: they load
        while the first candidates are captured, so no slot's first candidate waits for them."""
        with self._lock:
            if (task, options) in self._warm:
                return
            self._warm.add((task, options))
            slots = list(self._slots)
        for actor in slots:
            actor.start_helpers.remote(task, options)

    def _evaluate(
        self, task: str, solution: str, settings: FitSettings, captured: dict[str, Any] | None
    ) -> Evaluation:
        """One candidate on a free slot; once more on another if the slot dies meanwhile."""
        retried = ""
        for attempt in range(1 + SLOT_RETRIES):
            actor = self._take_slot()
            if actor is None:
                return Evaluation.invalid(
                    "lost on Ray: no slot of the cluster is left to evaluate it", status="crashed"
                )
            try:
                running = actor.evaluate.remote(task, solution, settings, captured)
                evaluation = self._ray.get(running)
            except self._ray.exceptions.LocalRayletDiedError as error:
                raise _cluster_lost(error) from error
            except self._ray.exceptions.RayActorError as error:
                self._replace(actor)
                if attempt < SLOT_RETRIES:
                    retried = f"its Ray slot died ({type(error).__name__}: {_first_line(error)})"
                    continue
                return _lost(self._ray, error)
            except Exception as error:  # Ray could not run it at all
                self._free.put(actor)
                return _lost(self._ray, error)
            self._free.put(actor)
            if retried:  # after any retry of the slot's own (a helper that died on the node)
                earlier = evaluation.extras.get("retried")
                evaluation.extras["retried"] = f"{retried}; then {earlier}" if earlier else retried
            return evaluation
        raise AssertionError("unreachable")

    def _take_slot(self) -> Any | None:
        """A free slot, waiting for one; None when no slot is left or starting."""
        while True:
            try:
                return self._free.get(timeout=1.0)
            except queue.Empty:
                with self._lock:
                    if self._closed or (not self._slots and not self._replacements):
                        return None

    def _replace(self, dead: Any) -> None:
        """Forget a dead slot and start another; it joins the free slots once Ray has placed
        it and it answers (never, if the cluster has no room left)."""
        with self._lock:
            if dead in self._slots:
                self._slots.remove(dead)
            if self._closed:
                return
            actor = self._actor_class.remote(self.limits, self.extra_python_path)
            self._replacements.add(actor)
            warm = set(self._warm)
        threading.Thread(target=self._await_replacement, args=(actor, warm), daemon=True).start()

    def _await_replacement(self, actor: Any, warm: set[tuple[str, str]]) -> None:
        """Wait for a replacement slot to answer, then warm it and free it (or give it up)."""
        try:
            ready, _ = self._ray.wait([actor.node.remote()], timeout=REPLACEMENT_TIMEOUT_S)
        except Exception:  # the cluster went away meanwhile
            ready = []
        with self._lock:
            self._replacements.discard(actor)
            if not ready or self._closed:
                with contextlib.suppress(Exception):  # Ray may be shut down already
                    self._ray.kill(actor)
                return
            self._slots.append(actor)
        for task, options in warm:
            actor.start_helpers.remote(task, options)
        self._free.put(actor)

    def close(self, wait_for_pending: bool = True) -> None:
        """Wait for running evaluations (or cancel them), stop every slot's helpers, then
        disconnect if connected here.

        Disconnecting stops a local instance the pool started; a connection made before the
        pool stays open.
        """
        executor = getattr(self, "_executor", None)
        if executor is not None:
            if not wait_for_pending:
                with self._lock:
                    self._closed = True
                    slots = list(self._slots)
                for actor in slots:  # running evaluations end at once, invalid
                    self._ray.kill(actor)
            executor.shutdown(wait=True, cancel_futures=not wait_for_pending)
            with self._lock:
                self._closed = True
                slots, self._slots = list(self._slots), []
                waiting = list(self._replacements)
            for actor in waiting:  # never placed (no room left) or not ready yet
                with contextlib.suppress(Exception):
                    self._ray.kill(actor)
            if wait_for_pending:
                closing = [actor.close.remote() for actor in slots]
                with contextlib.suppress(Exception):
                    self._ray.wait(closing, num_returns=len(closing), timeout=CLOSE_TIMEOUT_S)
                for actor in slots:
                    self._ray.kill(actor)
        if self._connected_here and self._ray.is_initialized():
            self._ray.shutdown()

    def terminate(self) -> None:
        """Stop now: every slot is killed, so running evaluations end at once, invalid (a
        caller that terminates must not record them); then as :meth:`close`."""
        self.close(wait_for_pending=False)

    def __enter__(self) -> RayPool:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, *exc_info: object) -> None:
        self.close(wait_for_pending=exc_type is None)


class NodeSlot:
    """The Ray actor of one slot: an :class:`~sga_agent.sandbox.EvaluationSlot` on its node,
    whose capture server and fit worker stay warm from one candidate to the next."""

    def __init__(self, limits: SandboxLimits, extra_python_path: tuple[str, ...]) -> None:
        self._slot = EvaluationSlot(limits, extra_python_path)
        self._node = socket.gethostname()
        with contextlib.suppress(Exception):
            import ray

            self._node = ray.util.get_node_ip_address()

    def node(self) -> str:
        """The address of this slot's node (also: the actor is placed and answers)."""
        return self._node

    def start_helpers(self, task: str, options: str) -> None:
        """Start the helpers without waiting for them (see EvaluationSlot.start_helpers)."""
        with contextlib.suppress(OSError):  # the evaluation that needs them will report it
            self._slot.start_helpers(task, options)

    def evaluate(
        self,
        task: str,
        solution: str,
        settings: FitSettings,
        captured: dict[str, Any] | None = None,
    ) -> Evaluation:
        """One sandboxed evaluation on this node (never raises); its extras name the node."""
        try:
            evaluation = self._slot.evaluate(task, solution, settings, captured=captured)
        except Exception as error:  # the sandbox itself failed, e.g. no space for its folder
            reason = f"the sandbox failed on Ray node {self._node}: "
            evaluation = Evaluation.invalid(f"{reason}{type(error).__name__}: {error}",
                                            status="error")  # fmt: skip
        evaluation.extras["node"] = self._node
        return evaluation

    def close(self) -> None:
        """Stop the helpers, letting them exit normally (Taichi writes its kernel cache)."""
        self._slot.close()


def _connect(ray: ModuleType, address: str | None, local_cpus: int | None) -> None:
    """``ray.init``: a new local instance for None, else the cluster at ``address``."""
    quiet = {"log_to_driver": False, "logging_level": logging.WARNING}
    if address is None:
        # Ray starts its workers at nice 15 by default, behind every other process of the
        # machine: the instance of this run evaluates at the search's own priority instead
        given = os.environ.get(WORKER_NICENESS)
        os.environ[WORKER_NICENESS] = given or "0"  # read by the processes ray.init starts
        try:
            ray.init(address="local", num_cpus=local_cpus, include_dashboard=False, **quiet)
        finally:
            if given is None:
                del os.environ[WORKER_NICENESS]
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


def _node_isolation() -> Isolation:
    """The Ray task probing a node's isolation."""
    return detect_isolation()


def _lost(ray: ModuleType, error: Exception) -> Evaluation:
    """The evaluation of a candidate whose slots died (its retry included) or that Ray could
    not run."""
    described = f"{type(error).__name__}: {_first_line(error)}"
    if isinstance(error, ray.exceptions.OutOfMemoryError):
        reason = f"Ray's memory monitor killed the worker evaluating it ({described})"
        return Evaluation.invalid(reason, status="out_of_memory")
    exceptions = ray.exceptions
    lost = (exceptions.RayActorError, exceptions.WorkerCrashedError, exceptions.NodeDiedError,
            exceptions.ObjectLostError)  # fmt: skip
    if isinstance(error, lost):
        tries = f"tried on {1 + SLOT_RETRIES} slots"
        reason = f"lost on Ray: the slot or node evaluating it died ({tries}; {described})"
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
