"""The search with a model, against the stand-in provider: how many readable answers are
evaluated, whether every failure reaches the next prompt, how long the prompts are, and how
fast a provider that fails is found.

Everything runs for real: ``sga-agent search`` in a subprocess, litellm as its client, the
stand-in server (:mod:`sga_agent.standin`) on 127.0.0.1 answering with the corpus of model
answers, the sandboxed capture and the fit. Four parts:

1. **corpus**: per task (elastic gets the corpus's elastic answers, granular its plastic ones),
   a two-iteration search whose first iteration is every corpus answer of that task. Each
   answer is found again in the run folder by its text; an answer a person can read (code
   present and complete) counts as evaluated when its code reached the fit (``ok`` or
   ``unstable``, or identical code that did). Every failed or repeated answer of iteration 1
   must be named, with its cause, in each prompt of iteration 2.
2. **prompt**: iteration 2's prompt at K = 5, counted with litellm's counter for ``gpt-4o``,
   and checked for every section of the paper's prompt.
3. **down**: a search whose provider is down (a closed port): seconds to the exit, its code,
   and whether a run folder was left.
4. **hang**: a provider that never answers, ``--request-timeout 5 --retries 1``: at the start
   (seconds to the exit, no run folder), and mid-run (the first iteration answered, then
   silence: seconds from the first unanswered request to the exit, then ``sga-agent resume``
   once the provider answers again).

Usage::

    python benchmarks/llm_path.py [--parts corpus,prompt,down,hang] [--tasks elastic,granular]
        [--json results.json]

It prints one table per part and, with ``--json``, writes the numbers to a file.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from sga_agent.causes import cause_of, top_causes
from sga_agent.proposers.litellm_backbone import PING_TOKENS
from sga_agent.standin import CorpusScript, Reply, ScriptedOpenAIServer, load_corpus

MODEL = "openai/standin"
KEY = {"OPENAI_API_KEY": "sk-standin-not-a-key"}
CORPUS_TASK = {"elastic": "elastic", "granular": "plastic"}
#: A short fit: enough to tell a law that runs from one that does not.
SHORT_FIT = ("--epochs", "1", "--option", "steps=100", "--workers", "2", "--timeout", "300")
EVALUATED = ("ok", "unstable")
#: Marks of every section of the paper's prompt, as ours words them.
SECTIONS = (
    "## Task", "## Earlier solutions", "### Iteration 5", "Feedback on iteration 5",
    "## Format requirements", "### Code template", '"### Analysis"',
    '"### Step-by-Step Plan"', '"### Code"',
)  # fmt: skip


def search(out: Path, url: str, task: str, *args: str, timeout_s: float = 1800) -> dict:
    """One ``sga-agent search`` against ``url``: its exit code, seconds, output and folder."""
    command = [sys.executable, "-m", "sga_agent", "search", "--task", task, "--model", MODEL,
               "--api-base", url, "--out-dir", str(out), *args]  # fmt: skip
    return _run(command, timeout_s) | {"folder": _folder(out)}


def resume(folder: Path, timeout_s: float = 1800) -> dict:
    """``sga-agent resume FOLDER``: its exit code, seconds and output."""
    return _run([sys.executable, "-m", "sga_agent", "resume", str(folder)], timeout_s)


def _run(command: list[str], timeout_s: float) -> dict:
    env = os.environ | KEY | {"LITELLM_LOCAL_MODEL_COST_MAP": "True"}
    started = time.monotonic()
    done = subprocess.run(command, capture_output=True, text=True, env=env, timeout=timeout_s)
    return {"code": done.returncode, "seconds": time.monotonic() - started,
            "output": done.stdout + done.stderr}  # fmt: skip


def _folder(out: Path) -> Path | None:
    folders = sorted(out.glob("*/events.jsonl")) if out.is_dir() else []
    return folders[-1].parent if folders else None


# ---------------------------------------------------------------------- 1 and 2: the corpus


def answering(script: CorpusScript) -> Any:
    """``script`` for the search's requests; "ready" to the one-word request it sends first."""

    def answer(body: dict[str, Any]) -> Reply:
        return Reply(texts="ready") if body.get("max_tokens") == PING_TOKENS else script(body)

    return answer


def corpus_part(task: str, out: Path) -> dict[str, Any]:
    """Iteration 1: every corpus answer of ``task``; iteration 2: two more, whose prompts
    are read."""
    answers = [a for a in load_corpus() if a.task == CORPUS_TASK[task]]
    with ScriptedOpenAIServer(answering(CorpusScript(answers))) as server:
        run = search(
            out, server.url, task, "--iterations", "2", "--top-k", "5", "--exploit", "0",
            "--explore", str(len(answers)), *SHORT_FIT, "--json",
        )  # fmt: skip
        requests = len(server.requests)
    folder = run["folder"]
    if run["code"] != 0 or folder is None:
        sys.exit(f"the {task} search failed:\n{run['output'][-3000:]}")
    candidates = _candidates(folder)
    rows = []
    for answer in answers:
        found = next((c for c in candidates if c["text"] == answer.text), None)
        status = found["status"] if found else "not asked"
        if found is None and answer.finish_reason == "length" and _asked_again(folder):
            status = "cut off, asked again"
        evaluated = found is not None and (
            status in EVALUATED or bool(found["evaluation"].get("extras", {}).get("duplicate_of"))
        )
        rows.append({"file": answer.file, "style": answer.style, "readable": answer.readable,
                     "expect": answer.expect, "candidate": found["id"] if found else "",
                     "status": status, "evaluated": evaluated,
                     "cause": cause_of(found["evaluation"]) if found else ""})  # fmt: skip
    readable = [row for row in rows if row["readable"] and row["candidate"]]
    ours = [row for row in readable if row["expect"] != "runtime error"]
    told = _told_in_next_prompt(folder, candidates)
    prompts = _prompt_sizes(folder)
    return {
        "task": task,
        "requests": requests,
        "seconds": run["seconds"],
        "answers": len(answers),
        "readable": len(readable),
        "evaluated": sum(row["evaluated"] for row in readable),
        "acceptance": sum(row["evaluated"] for row in readable) / max(1, len(readable)),
        "acceptance_without_model_errors": sum(row["evaluated"] for row in ours)
        / max(1, len(ours)),
        "causes": top_causes([c["evaluation"] for c in candidates if c["iteration"] == 1], 10),
        "failed": told["failed"],
        "untold": told["untold"],
        "prompts": prompts,
        "rows": rows,
        "folder": str(folder),
    }


def _asked_again(folder: Path) -> bool:
    """Whether some answer of the run replaced one cut off at the token limit."""
    return any(
        json.loads(path.read_text()).get("truncated_before", 0)
        for path in folder.glob("candidates/*/proposal.json")
    )


def _candidates(folder: Path) -> list[dict[str, Any]]:
    found = []
    for path in sorted((folder / "candidates").iterdir()):
        response = path / "response.txt"
        record = path / "evaluation.json"
        if not (response.is_file() and record.is_file()):
            continue
        evaluation = json.loads(record.read_text())
        found.append({"id": path.name, "iteration": int(path.name[:2]),
                      "text": response.read_text(), "status": evaluation["status"],
                      "evaluation": evaluation})  # fmt: skip
    return found


def _told_in_next_prompt(folder: Path, candidates: list[dict[str, Any]]) -> dict[str, Any]:
    """Iteration 1's failed and repeated answers, and those that some prompt of iteration 2
    does not tell: by id, and for a failure by its reason (numbers aside: alike failures are
    told once, with the first one's line numbers)."""
    failed = [c for c in candidates if c["iteration"] == 1 and cause_of(c["evaluation"])]
    sections = []
    for path in sorted(folder.glob("candidates/02-*/messages.json")):
        prompt = json.loads(path.read_text())[-1]["content"]
        part = prompt.split("## What went wrong in the last iteration", 1)[1:] or [""]
        sections.append(part[0].split("## Format requirements", 1)[0])
    untold = []
    for candidate in failed:
        reason = _plain(str(candidate["evaluation"].get("reason", "")))[:40]
        repeat = bool(candidate["evaluation"].get("valid"))
        for section in sections:
            if candidate["id"] not in section or not (repeat or reason in _plain(section)):
                untold.append(candidate["id"])
                break
    return {"failed": [c["id"] for c in failed], "untold": untold, "prompts": len(sections)}


def _plain(text: str) -> str:
    """``text`` on one line, its digits as N."""
    return re.sub(r"\d+", "N", " ".join(text.split()))


def _prompt_sizes(folder: Path) -> list[dict[str, Any]]:
    """Each iteration-2 prompt's tokens (litellm's counter for gpt-4o) and sections."""
    from sga_agent.proposers.litellm_backbone import import_litellm

    litellm = import_litellm()
    sizes = []
    for path in sorted(folder.glob("candidates/02-*/messages.json")):
        messages = json.loads(path.read_text())
        user = messages[-1]["content"]
        sizes.append({
            "candidate": path.parent.name,
            "tokens": litellm.token_counter(model="gpt-4o", messages=messages),
            "shown": user.count("\n### Iteration "),
            "missing_sections": [mark for mark in SECTIONS if mark not in user],
            "shortened_feedbacks": user.count("more lines of this feedback left out"),
        })  # fmt: skip
    return sizes


# ---------------------------------------------------------------------- 3 and 4: failures


def down_part(out: Path) -> dict[str, Any]:
    """A provider that is down: nothing listens at the address."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    run = search(out, f"http://127.0.0.1:{port}/v1", "elastic", timeout_s=120)
    return {"code": run["code"], "seconds": run["seconds"], "run_folder": run["folder"] is not None,
            "said": _error_line(run["output"])}  # fmt: skip


def hang_part(out: Path) -> dict[str, Any]:
    """A provider that never answers, at the start and in the middle of a run."""
    patience = ("--request-timeout", "5", "--retries", "1")
    with ScriptedOpenAIServer(lambda body: Reply.hang()) as server:
        start = search(out / "start", server.url, "elastic", *patience, timeout_s=300)
    script = answering(CorpusScript([a for a in load_corpus() if a.slip == ""]))
    left = [3]  # the one-word request and iteration 1's two batches, then silence
    first_silent: list[float] = []

    def fickle(body: dict[str, Any]) -> Reply:
        if left[0] > 0:
            left[0] -= 1
            return script(body)
        if not first_silent:
            first_silent.append(time.monotonic())
        return Reply.hang()

    with ScriptedOpenAIServer(fickle) as server:
        args = ("--iterations", "2", "--exploit", "1", "--explore", "1", *SHORT_FIT, *patience)
        middle = search(out / "middle", server.url, "elastic", *args)
        ended = time.monotonic()
        left[0] = 1_000_000  # it answers again
        resumed = resume(middle["folder"]) if middle["folder"] else {"code": None, "seconds": 0}
    if not first_silent:
        sys.exit(f"the provider never fell silent:\n{middle['output'][-3000:]}")
    return {
        "start": {"code": start["code"], "seconds": start["seconds"],
                  "run_folder": start["folder"] is not None, "said": _error_line(start["output"])},
        "middle": {"code": middle["code"], "seconds_after_silence": ended - first_silent[0],
                   "said": _error_line(middle["output"]),
                   "resume_code": resumed["code"], "resume_seconds": resumed["seconds"]},
    }  # fmt: skip


def _error_line(output: str) -> str:
    return next((line for line in output.splitlines() if line.startswith("Error:")), "")


# ---------------------------------------------------------------------- the report


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--parts", default="corpus,prompt,down,hang")
    parser.add_argument("--tasks", default="elastic,granular")
    parser.add_argument("--json", type=Path, help="write the numbers to this file")
    args = parser.parse_args()
    parts = set(args.parts.split(","))
    results: dict[str, Any] = {"load": os.getloadavg()[0]}
    with tempfile.TemporaryDirectory(prefix="llm-path-") as folder:
        out = Path(folder)
        if parts & {"corpus", "prompt"}:
            results["corpus"] = [corpus_part(task, out / task) for task in args.tasks.split(",")]
            for part in results["corpus"]:
                _print_corpus(part)
        if "down" in parts:
            results["down"] = down_part(out / "down")
            print(f"\nprovider down: exit {results['down']['code']} after "
                  f"{results['down']['seconds']:.1f} s, run folder left: "
                  f"{results['down']['run_folder']}\n  {results['down']['said']}")  # fmt: skip
        if "hang" in parts:
            hang = results["hang"] = hang_part(out / "hang")
            start, middle = hang["start"], hang["middle"]
            print(f"\nprovider silent from the start (--request-timeout 5 --retries 1): exit "
                  f"{start['code']} after {start['seconds']:.1f} s, run folder left: "
                  f"{start['run_folder']}\n  {start['said']}")  # fmt: skip
            print(f"provider silent after iteration 1: exit {middle['code']}, "
                  f"{middle['seconds_after_silence']:.1f} s after its first unanswered request"
                  f"\n  {middle['said']}\n  resume once it answers: exit {middle['resume_code']} "
                  f"after {middle['resume_seconds']:.1f} s")  # fmt: skip
    results["load_after"] = os.getloadavg()[0]
    print(f"\nload average: {results['load']:.2f} before, {results['load_after']:.2f} after")
    if args.json:
        args.json.write_text(json.dumps(results, indent=2, default=str) + "\n")


def _print_corpus(part: dict[str, Any]) -> None:
    print(f"\n{part['task']}: {part['answers']} corpus answers, {part['readable']} readable; "
          f"{part['evaluated']} evaluated ({100 * part['acceptance']:.0f} %; "
          f"{100 * part['acceptance_without_model_errors']:.0f} % leaving out the answers "
          f"whose own code fails at run time); {part['seconds']:.0f} s")  # fmt: skip
    for row in part["rows"]:
        mark = "evaluated" if row["evaluated"] else row["status"]
        print(f"  {row['file']:<40} {row['style']:<12} {mark:<20} {row['cause'][:70]}")
    print("  causes of failure in iteration 1: " + "; ".join(
        f"{count} {cause}" for cause, count in part["causes"]))  # fmt: skip
    print(f"  failed or repeated in iteration 1: {len(part['failed'])}; missing from an "
          f"iteration-2 prompt: {part['untold'] or 'none'}")  # fmt: skip
    for prompt in part["prompts"]:
        print(f"  prompt of {prompt['candidate']}: {prompt['tokens']} tokens (gpt-4o), "
              f"{prompt['shown']} solutions shown, {prompt['shortened_feedbacks']} feedbacks "
              f"shortened, sections missing: {prompt['missing_sections'] or 'none'}")  # fmt: skip


if __name__ == "__main__":
    main()
