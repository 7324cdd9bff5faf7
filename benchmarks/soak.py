"""Soak: a long LLM-free search, with every helper's memory and the evaluation rate over time.

Runs one search of ``--evaluations`` evaluations (default 1,000) with the task's built-in
proposer (the constitutive tasks' genetic programming) on a short scene and one inner epoch,
through :func:`sga_agent.runner.run` and the local pool, exactly as ``sga-agent search`` does.
A thread samples, every ``--interval`` seconds, the resident memory (``VmRSS`` in
``/proc/PID/status``) of each helper this process started: the capture servers and the fit
workers (a helper is named by its role and its slot, the folder it runs in; a recycled fit
worker keeps its slot's name, its new process id is in the CSV).

It writes, into ``--out`` (default ``soak-<time>``): ``samples.csv`` (seconds, evaluations
done, helper, process id, RSS in MB), ``rate.csv`` (evaluations per minute, per hundred
evaluations), ``soak.png`` (the two over time) and the run folder. It prints each helper's RSS
after the first 50 evaluations and at the end with their ratio, the evaluations per minute of
the first and last hundred, and every ``out_of_memory`` or ``crashed`` verdict evaluated again
alone, in a fresh process (:func:`sga_agent.sandbox.evaluate_in_sandbox`), with both verdicts.

The search's candidates grow over a long run (the genetic programming's trees get larger),
so the later ones cost more to capture and fit; the rate of the search alone cannot tell
that from helpers that slow down. So after the search, the same helpers evaluate the first
hundred candidates again, in the same batches, and it prints both rates and both sums of
the evaluations' own seconds for those hundred, and whether each kept its verdict.

It runs outside CI (see ``docs/benchmarks.md`` for the last run's numbers). Usage::

    python benchmarks/soak.py [--evaluations 1000] [--task elastic] [--steps 100]
        [--epochs 1] [--workers 2] [--interval 10] [--seed 0] [--out DIR]
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

ROLES = {"sga_agent.capture_server": "capture", "sga_agent.fit_worker": "fit"}
#: Evaluations after which each helper's memory is the reference (the issue's acceptance).
REFERENCE_EVALUATIONS = 50
#: Evaluations per window of the rate (first and last).
RATE_WINDOW = 100


@dataclass
class Recorder:
    """The evaluations' finishing times and the helpers' memory samples, shared by threads."""

    started: float = field(default_factory=time.monotonic)
    finished: list[float] = field(default_factory=list)  # seconds since start, in order
    samples: list[tuple[float, int, str, int, float, float]] = field(default_factory=list)
    verdicts: dict[str, str] = field(default_factory=dict)  # candidate -> status
    seconds: dict[str, float] = field(default_factory=dict)  # candidate -> its evaluation's
    order: list[str] = field(default_factory=list)  # candidates, as they finished
    lock: threading.Lock = field(default_factory=threading.Lock)

    def on_event(self, event: dict) -> None:
        if event.get("type") != "evaluation":
            return
        evaluation = event["evaluation"]
        if "duplicate_of" in evaluation.get("extras", {}):
            return
        with self.lock:
            self.finished.append(time.monotonic() - self.started)
            self.verdicts[event["candidate"]] = evaluation.get("status", "")
            self.seconds[event["candidate"]] = float(evaluation.get("seconds", 0.0))
            self.order.append(event["candidate"])

    def sample(self) -> None:
        now = time.monotonic() - self.started
        with self.lock:
            done = len(self.finished)
        for name, pid, rss, data in helpers(os.getpid()):
            self.samples.append((now, done, name, pid, rss, data))

    def by_helper(self) -> dict[str, list[tuple[float, int, float]]]:
        """Each helper's (seconds, evaluations done, RSS) per sample; while a slot's fit
        worker and its replacement both run, the larger."""
        largest: dict[tuple[str, float], tuple[int, float]] = {}
        for seconds, done, name, _, rss, _ in self.samples:
            previous = largest.get((name, seconds), (done, 0.0))
            largest[(name, seconds)] = (done, max(previous[1], rss))
        series: dict[str, list[tuple[float, int, float]]] = {}
        for (name, seconds), (done, rss) in sorted(largest.items()):
            series.setdefault(name, []).append((seconds, done, rss))
        return series


@dataclass
class Again:
    """The first evaluations run again at the end: their summed evaluation seconds then and
    now, the rerun's finishing times (seconds from its start), and how many kept their
    verdict."""

    first_seconds: float
    seconds: float = 0.0
    finished: list[float] = field(default_factory=list)
    count: int = 0
    same_verdict: int = 0


def helpers(parent: int) -> list[tuple[str, int, float, float]]:
    """(name, pid, RSS in MB, writable private memory in MB) of the helper processes whose
    parent is ``parent``; a helper's name is its role and its slot (the last part of the
    folder it runs in). The second figure (``VmData``) is what the fit's ``RLIMIT_DATA``
    limits."""
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            status = Path(f"/proc/{entry}/status").read_text()
            fields = dict(line.split(":", 1) for line in status.splitlines() if ":" in line)
            if int(fields["PPid"]) != parent:
                continue
            command = Path(f"/proc/{entry}/cmdline").read_bytes().split(b"\0")
            role = next((ROLES[a.decode()] for a in command if a.decode() in ROLES), None)
            if role is None or "VmRSS" not in fields:
                continue
            slot = Path(os.readlink(f"/proc/{entry}/cwd")).name.removeprefix("sga-sandbox-")
            rss = int(fields["VmRSS"].split()[0]) / 1024
            data = int(fields["VmData"].split()[0]) / 1024
        except (OSError, ValueError, KeyError):  # it exited meanwhile
            continue
        found.append((f"{role}-{slot}", int(entry), rss, data))
    return found


def run_search(args: argparse.Namespace, out: Path, recorder: Recorder):
    from sga_agent import registry, runner
    from sga_agent.config import SearchConfig
    from sga_agent.run_store import RunStore
    from sga_agent.search import Search
    from sga_agent.task import configured

    loaded = registry.load_task(args.task)
    options = runner.task_options(loaded, {"steps": str(args.steps)}, runner.BUILTIN)
    per_iteration = args.exploit + args.explore
    config = SearchConfig.from_settings(
        task=args.task, proposer=runner.BUILTIN, preset="quick", top_k=5, exploit=args.exploit,
        explore=args.explore, iterations=max(1, 2 * math.ceil(args.evaluations / per_iteration)),
        epochs=args.epochs, task_options=options, workers=args.workers,
        max_evaluations=args.evaluations, seed=args.seed,
    )  # fmt: skip
    task = configured(loaded, options)
    proposer = runner.make_proposer(config, task)
    store = RunStore.create(out, config, {"proposer": "builtin", "soak": True})
    with runner.make_pool(config) as pool:
        store.append(runner.pool_record(pool))
        search = Search(config, task, proposer, pool, store, recorder.on_event)
        search.run()
        again = first_again(search, store, recorder)
    return config, store, again


def first_again(search, store, recorder: Recorder) -> Again:
    """The first RATE_WINDOW evaluations run again on the same, aged helpers, in the same
    batches (one iteration's candidates submitted together, as the search does): the like-
    for-like check of the helpers' health, since the search's own candidates grow (and so
    cost more) over a long run."""
    first = [c for c in recorder.order[:RATE_WINDOW] if c in recorder.seconds]
    batches: dict[str, list[str]] = {}
    for candidate in first:
        batches.setdefault(candidate.split("-", 1)[0], []).append(candidate)
    again = Again(first_seconds=sum(recorder.seconds[c] for c in first))
    started = time.monotonic()
    for batch in batches.values():
        futures = {
            candidate: search.evaluator.submit(
                search.config.task,
                (store.candidate_dir(candidate) / "code.py").read_text(encoding="utf-8"),
                search.settings,
            )
            for candidate in batch
        }
        for candidate, future in futures.items():
            evaluation = future.result()
            again.seconds += evaluation.seconds
            again.same_verdict += evaluation.status == recorder.verdicts[candidate]
            again.count += 1
            again.finished.append(time.monotonic() - started)
    return again


def sampling(recorder: Recorder, interval: float, stop: threading.Event) -> None:
    while not stop.wait(interval):
        recorder.sample()


def reference_and_end(recorder: Recorder) -> dict[str, tuple[float, float, float]]:
    """Each helper's RSS at the first sample after REFERENCE_EVALUATIONS (or half the
    evaluations, if fewer), at its last, and the most it had after the first."""
    reference = min(REFERENCE_EVALUATIONS, len(recorder.finished) // 2)
    result: dict[str, tuple[float, float, float]] = {}
    for name, series in recorder.by_helper().items():
        after = [rss for _, done, rss in series if done >= reference]
        if after:
            result[name] = (after[0], after[-1], max(after))
    return result


def rates(finished: list[float]) -> list[tuple[int, float]]:
    """(evaluations done, evaluations per minute of the last RATE_WINDOW) per window."""
    windows = []
    for end in range(RATE_WINDOW, len(finished) + 1, RATE_WINDOW):
        start = finished[end - RATE_WINDOW - 1] if end > RATE_WINDOW else 0.0
        windows.append((end, 60 * RATE_WINDOW / max(finished[end - 1] - start, 1e-9)))
    return windows


def window_rate(finished: list[float], first: bool) -> float:
    """Evaluations per minute of the first (or last) RATE_WINDOW evaluations (all if fewer)."""
    count = min(RATE_WINDOW, len(finished))
    if count < 2:
        return math.nan
    if first:
        return 60 * count / finished[count - 1]
    span = finished[-1] - finished[-count - 1] if len(finished) > count else finished[-1]
    return 60 * count / span


def recheck(config, store, recorder: Recorder) -> list[tuple[str, str, str, str]]:
    """(candidate, search verdict, alone verdict, alone reason) of every out_of_memory or
    crashed candidate, evaluated again alone in fresh processes."""
    from sga_agent.sandbox import evaluate_in_sandbox

    settings = config.evaluation_settings()  # as the search's
    limits = config.sandbox.limits(threads=1)
    checked = []
    for candidate, status in sorted(recorder.verdicts.items()):
        if status not in ("out_of_memory", "crashed"):
            continue
        code = (store.candidate_dir(candidate) / "code.py").read_text(encoding="utf-8")
        alone = evaluate_in_sandbox(config.task, code, settings, limits)
        checked.append((candidate, status, alone.status, alone.reason))
    return checked


def write_outputs(out: Path, recorder: Recorder) -> None:
    with open(out / "samples.csv", "w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(["seconds", "evaluations", "helper", "pid", "rss_mb", "data_mb"])
        for seconds, done, name, pid, rss, data in recorder.samples:
            writer.writerow([f"{seconds:.1f}", done, name, pid, f"{rss:.1f}", f"{data:.1f}"])
    with open(out / "rate.csv", "w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(["evaluations", "per_minute"])
        for done, rate in rates(recorder.finished):
            writer.writerow([done, f"{rate:.2f}"])
    plot(out / "soak.png", recorder)


def plot(path: Path, recorder: Recorder) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, (memory, speed) = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
    for name, series in sorted(recorder.by_helper().items()):
        memory.plot([s[0] / 60 for s in series], [s[2] for s in series], label=name, linewidth=1)
    memory.set_ylabel("resident memory (MB)")
    memory.legend(fontsize=7, ncol=2)
    finished = recorder.finished
    if len(finished) > 10:
        step = max(10, len(finished) // 50)
        times = [finished[i] / 60 for i in range(step, len(finished), step)]
        per_minute = [step / ((finished[i] - finished[i - step]) / 60)
                      for i in range(step, len(finished), step)]  # fmt: skip
        speed.plot(times, per_minute, linewidth=1)
    speed.set_ylabel(f"evaluations per minute\n(windows of {max(10, len(finished) // 50)})")
    speed.set_xlabel("minutes")
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def report(recorder: Recorder, checked: list[tuple[str, str, str, str]], out: Path) -> None:
    print(f"evaluations: {len(recorder.finished)} in {recorder.finished[-1] / 60:.1f} min"
          if recorder.finished else "evaluations: none")  # fmt: skip
    reference = min(REFERENCE_EVALUATIONS, len(recorder.finished) // 2)
    print(f"helper RSS (MB) after the first {reference} evaluations, at the end, and the most "
          "in between (a slot's fit workers, recycled, counted as one helper):")  # fmt: skip
    for name, (first, last, most) in sorted(reference_and_end(recorder).items()):
        processes = len({s[3] for s in recorder.samples if s[2] == name})
        print(
            f"  {name:24s} {first:8.1f} -> {last:8.1f}  x{last / first:.3f}  most "
            f"{most:8.1f} x{most / first:.3f}  ({processes} process{'es' * (processes > 1)})"
        )
    first, last = window_rate(recorder.finished, True), window_rate(recorder.finished, False)
    window = min(RATE_WINDOW, len(recorder.finished))
    print(f"evaluations per minute: first {window} {first:.2f}, last {window} {last:.2f} "
          f"({100 * (last / first - 1):+.1f} %)")  # fmt: skip
    print(f"out_of_memory / crashed verdicts re-checked alone: {len(checked)}")
    for candidate, status, alone, reason in checked:
        mark = "same" if alone == status else "DIFFERENT"
        print(f"  {candidate}: {status} in the search, {alone} alone ({mark}) {reason}")
    print(f"written: {out / 'samples.csv'}, {out / 'rate.csv'}, {out / 'soak.png'}")


def report_again(recorder: Recorder, again: Again, store) -> None:
    """The like-for-like check: the first evaluations at the start and again at the end."""
    count = again.count
    if count < 2:
        return
    first = recorder.finished[:count]
    then = 60 * (count - 1) / max(first[-1] - first[0], 1e-9)
    now = 60 * (count - 1) / max(again.finished[-1] - again.finished[0], 1e-9)
    print(f"the first {count} evaluations again, on the same helpers after all the others:")
    print(f"  evaluations per minute (first to last finish): {then:.2f} at the start, "
          f"{now:.2f} at the end ({100 * (now / then - 1):+.1f} %)")  # fmt: skip
    change = 100 * (again.seconds / again.first_seconds - 1)
    print(f"  their evaluations' own seconds, summed: {again.first_seconds:.1f} at the start, "
          f"{again.seconds:.1f} at the end ({change:+.1f} %)")  # fmt: skip
    print(f"  the same verdict: {again.same_verdict} of {count}")
    sizes = [len((store.candidate_dir(c) / "code.py").read_text(encoding="utf-8"))
             for c in recorder.order]  # fmt: skip
    window = min(RATE_WINDOW, len(sizes))
    first_size, last_size = sum(sizes[:window]) / window, sum(sizes[-window:]) / window
    print(f"the search's candidates' code, mean characters: first {window} {first_size:.0f}, "
          f"last {window} {last_size:.0f}")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--evaluations", type=int, default=1000)
    parser.add_argument("--task", default="elastic")
    parser.add_argument("--steps", type=int, default=100, help="steps of the scene")
    parser.add_argument("--epochs", type=int, default=1)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--exploit", type=int, default=4)
    parser.add_argument("--explore", type=int, default=12)
    parser.add_argument("--interval", type=float, default=10.0, help="seconds between samples")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=Path(f"soak-{time.strftime('%Y%m%d-%H%M%S')}"))
    args = parser.parse_args()
    os.environ.setdefault("LITELLM_LOCAL_MODEL_COST_MAP", "True")
    os.environ.setdefault("TI_ENABLE_PYBUF", "0")  # no Taichi notebook detection
    args.out.mkdir(parents=True, exist_ok=True)
    recorder = Recorder()
    stop = threading.Event()
    sampler = threading.Thread(target=sampling, args=(recorder, args.interval, stop), daemon=True)
    sampler.start()
    try:
        config, store, again = run_search(args, args.out, recorder)
    finally:
        stop.set()
        sampler.join()
        write_outputs(args.out, recorder)
    (args.out / "run.json").write_text(json.dumps({"run": str(store.path)}))
    report(recorder, recheck(config, store, recorder), args.out)
    report_again(recorder, again, store)


if __name__ == "__main__":
    main()
