"""The trusted fit worker: ``python -m sga_agent.fit_worker TASK MEMORY_MB OPTIONS [STAGES]``,
run by .sandbox.

OPTIONS is the JSON text of the task options of every evaluation it makes
(:class:`~sga_agent.helper_protocol.FitSettings`); it builds the task's options object from
it once. It scores captured solutions: one request per line of its standard input::

    {"data": <what the task's capture returned>,
     "settings": {"epochs": ..., "learning_rate": ..., "seed": ..., "fidelity": ...}}

and one :class:`~sga_agent.task.Evaluation` as a JSON line per request on its standard output,
after any progress notes (:data:`~sga_agent.helper_protocol.NOTE` lines: "warming up" as each
warm-up stage starts, "fitting" as a request's fit starts, and what the task reports with
:func:`~sga_agent.task.report_progress`, such as its epochs), which its parent only shows. It
never imports or runs a candidate's code: ``data`` is inert JSON, which the task's
``evaluate`` checks before it uses it. So what it reports can be believed, and it stays warm
(torch, Taichi, kernels and ground truth loaded) from one candidate to the next.

Once it has said it is ready it runs the task's ``warm_up_fit`` with those options, so that
candidates do not pay for loading and compiling. A warm-up that returns an iterator comes in
stages, the ones every evaluation needs first: a stage starts only while no request waits, so
a waiting candidate goes before the remaining stages, which run whenever the worker next waits
for a request, and those not reached when the input ends are skipped. STAGES, if given, is
the most stages it runs ahead of requests (a worker for a single candidate needs the first
only). The request ``{"warm": true}`` runs every stage left and answers ``{"warm": true}``: a
slot sends it to the replacement it starts for a worker it recycles, and hands it candidates
once it has answered.

Its writable private memory is limited (``RLIMIT_DATA``, MEMORY_MB MiB; see :mod:`.sandbox`). A
failure to allocate becomes an ``out_of_memory`` Evaluation, after which the worker exits so
that the next candidate gets a fresh process. Prints of the task go to standard error.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import resource
import select
import sys
import time
from collections.abc import Iterator
from typing import IO, Any

from sga_agent import registry
from sga_agent.helper_protocol import NOTE, answer, describe, start_helper
from sga_agent.options import options_from_data
from sga_agent.task import (
    Evaluation,
    EvaluationSettings,
    FitProgress,
    Task,
    TaskBase,
    is_out_of_memory,
    progress_to,
    release_freed_memory,
    report_progress,
)

TRACEBACK_TAIL_CHARS = 4000
#: Seconds within which a note of the same stage as the last one sent is dropped, so that a
#: task reporting too often does not flood its parent; a new stage and a fit's last epoch go.
NOTE_INTERVAL_S = 0.05


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) not in (3, 4):
        print("usage: python -m sga_agent.fit_worker TASK MEMORY_MB OPTIONS [STAGES]",
              file=sys.stderr)  # fmt: skip
        return 2
    answers = start_helper()
    memory = int(args[1]) * 2**20
    resource.setrlimit(resource.RLIMIT_DATA, (memory, memory))
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    task, options, failure = _set_up(args[0], args[2])
    answer(answers, {"ready": failure is None})
    with progress_to(Notes(answers)):
        return serve(task, options, failure, args[3] if len(args) == 4 else None, answers)


def serve(
    task: TaskBase | None,
    options: Any,
    failure: Evaluation | None,
    ahead: str | None,
    answers: IO[str],
) -> int:
    """Warm up, then answer every request of the standard input (``ahead``: the most warm-up
    stages run ahead of requests, None for all)."""
    stages = None
    if task is not None:
        stages = warm_up(task, options)
        if stages is not None and ahead is not None:
            stages = itertools.islice(stages, int(ahead))
    while line := next_request(sys.stdin, stages):
        request = json.loads(line)
        if request.get("warm"):
            while stages is not None:
                stages = _advance(stages)
            answer(answers, {"warm": True})
            continue
        report_progress("fitting")
        evaluation = failure or score(task, request["data"], request["settings"], options)
        release_freed_memory()  # a warm worker rests at its imports' size, not at the last peak
        answer(answers, evaluation.to_dict())
        if evaluation.status == "out_of_memory":
            return 0
    return 0


class Notes:
    """Sends the progress notes of this process (:func:`~sga_agent.task.report_progress`) to
    the parent, one line each on the answer stream, less those of a stage reported again
    within :data:`NOTE_INTERVAL_S`."""

    def __init__(self, answers: IO[str]) -> None:
        self.answers = answers
        self.last: tuple[str, float] = ("", -math.inf)  # the stage last sent, and when

    def __call__(self, note: FitProgress) -> None:
        now = time.monotonic()
        final = note.epoch is not None and note.epoch == note.epochs
        if note.stage == self.last[0] and now - self.last[1] < NOTE_INTERVAL_S and not final:
            return
        self.last = (note.stage, now)
        answer(self.answers, {NOTE: note.to_dict()})


def _set_up(name: str, options: str) -> tuple[TaskBase | None, Any, Evaluation | None]:
    """The task, its options object (built from their JSON once) and, if either failed, the
    evaluation every request gets instead."""
    try:
        task = registry.resolve_task(name)
    except Exception as error:  # a plugin may fail to import in any way
        return None, None, _from_exception(f"could not load task {name!r}:", error)
    try:
        return task, options_from_data(task.options_type, json.loads(options), task.name), None
    except Exception as error:  # the task's own checks of its options may fail in any way
        return None, None, _from_exception(f"the options of task {name!r} failed:", error)


def warm_up(task: Task, options: Any) -> Iterator[None] | None:
    """The stages of the task's own ``warm_up_fit`` still to run (None: all done or none)."""
    report_progress("warming up")
    try:
        stages = task.warm_up_fit(options)
    except Exception as error:  # the first evaluation meets and reports what is wrong
        _warm_up_failed(error)
        return None
    return iter(stages) if stages is not None else None


def next_request(requests: IO[str], stages: Iterator[None] | None) -> str:
    """The next request line ("" once the input ends), running warm-up ``stages`` while none
    waits."""
    while stages is not None and not _waiting(requests):
        stages = _advance(stages)
    return requests.readline()


def _advance(stages: Iterator[None]) -> Iterator[None] | None:
    """Run the next warm-up stage; the stages left (None once none is, or one failed)."""
    report_progress("warming up")
    try:
        next(stages)
    except StopIteration:
        return None
    except Exception as error:
        _warm_up_failed(error)
        return None
    return stages


def _waiting(requests: IO[str]) -> bool:
    """Whether a request (or the end of the input) can be read without waiting."""
    return bool(select.select([requests], [], [], 0)[0])


def _warm_up_failed(error: Exception) -> None:
    described, formatted = describe(error, TRACEBACK_TAIL_CHARS)
    print(f"warm-up failed: {described}\n{formatted}", file=sys.stderr)


def score(task: Task, data: Any, settings: dict[str, Any], options: Any) -> Evaluation:
    """The task's evaluation of ``data`` with the request's ``settings`` and the worker's
    ``options``; every failure becomes an invalid Evaluation."""
    try:
        evaluation = task.evaluate(data, EvaluationSettings(**settings, options=options))
    except Exception as error:
        return _from_exception("evaluation raised", error)
    if not isinstance(evaluation, Evaluation):
        return Evaluation.invalid(
            f"the task returned {type(evaluation).__name__} from evaluate, "
            "not an sga_agent.task.Evaluation",
            status="error",
        )
    if evaluation.valid and not math.isfinite(evaluation.loss):
        reason = f"the loss is {evaluation.loss} (numerically unstable)"
        return dataclasses.replace(
            evaluation, valid=False, loss=math.inf, reason=reason, status="unstable"
        )
    try:
        json.dumps(evaluation.to_dict())
    except (TypeError, ValueError) as error:
        reason = f"the task's Evaluation is not JSON-serialisable: {error}"
        return Evaluation.invalid(reason, status="error")
    return evaluation


def _from_exception(prefix: str, error: BaseException) -> Evaluation:
    described, formatted = describe(error, TRACEBACK_TAIL_CHARS)
    extras = {"traceback": formatted}
    if is_out_of_memory(error):
        reason = f"exceeded the fit's memory limit ({described})"
        return Evaluation.invalid(reason, status="out_of_memory", extras=extras)
    return Evaluation.invalid(f"{prefix} {described}", status="error", extras=extras)


if __name__ == "__main__":
    sys.exit(main())
