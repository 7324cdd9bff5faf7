"""The contract between the search and a scientific task: the protocol package.

A task plugin (a constitutive-law search, a molecule design, a third party's problem) is an
object satisfying :class:`Task` (what every task provides); the hooks it may add are declared,
each with its default, by :class:`TaskBase`, which a task subclasses (a plugin that does not is
given the defaults by :func:`as_task`). :func:`sga_agent.testing.check_task` checks a plugin
against this contract.

The search only ever sees solutions as text (the code block a proposer wrote) and
:class:`Evaluation` records. A solution is scored in two steps so that its code can never
forge its score:

- ``capture(solution) -> data``: the only place where a solution's code may run, in a confined
  capture process (:mod:`sga_agent.capture_server`). It turns the solution into inert JSON data
  (a law's graph of tensor operations; a molecule's SMILES and coordinates). Whatever comes out
  of this step is untrusted.
- ``evaluate(data, settings) -> Evaluation``: trusted. It runs in a fit process
  (:mod:`sga_agent.fit_worker`) that never imports or runs solution code; it checks the data
  and scores it.

Its modules: :mod:`.records` (settings, evaluations, prompt parts, assessments, parents),
:mod:`.forms` (whether the data determine a solution's form: :class:`FormComparison`),
:mod:`.protocol` (:class:`Task`, :class:`TaskBase`, :class:`BuiltinProposer`), :mod:`.code`
(reading a solution's code without running it: :class:`CodeRejected`), :mod:`.device` (the
device evaluations compute on: :func:`selected_device`), :mod:`.progress` (the
optional progress notes of a fit: :func:`report_progress`) and :mod:`.report` (the blocks a
task's report sections are made of). A task package imports nothing else of
``sga_agent``, and this package imports nothing beyond the standard library, so that task
packages can import it cheaply.
"""

from __future__ import annotations

from sga_agent.task.code import CodeRejected, Problem
from sga_agent.task.device import selected_device
from sga_agent.task.forms import FormComparison, Probe, compared, within_noise
from sga_agent.task.memory import release_freed_memory
from sga_agent.task.progress import FitProgress, progress_to, report_progress
from sga_agent.task.protocol import (
    BuiltinProposer,
    Task,
    TaskBase,
    as_task,
    configured,
    has_hook,
    options_type,
    solution_with_parameters,
)
from sga_agent.task.records import (
    STATUSES,
    Assessment,
    Evaluation,
    EvaluationSettings,
    InvalidSolution,
    NoOptions,
    Parent,
    PromptParts,
    Simplified,
    TaskKind,
    is_out_of_memory,
)
from sga_agent.task.report import (
    DPI,
    FONT,
    Block,
    CandidateRecord,
    Code,
    Image,
    ReportView,
    Section,
    Table,
    Text,
)

__all__ = [
    "DPI", "FONT", "STATUSES", "Assessment", "Block", "BuiltinProposer", "CandidateRecord",
    "Code", "CodeRejected", "Evaluation", "EvaluationSettings", "FitProgress", "FormComparison",
    "Image", "InvalidSolution", "NoOptions", "Parent", "Probe", "Problem", "PromptParts",
    "ReportView", "Section", "Simplified", "Table", "Task", "TaskBase", "TaskKind", "Text",
    "as_task", "compared", "configured", "has_hook", "is_out_of_memory", "options_type",
    "progress_to", "release_freed_memory", "report_progress", "selected_device",
    "solution_with_parameters", "within_noise",
]  # fmt: skip
