"""Finding tasks: the ``sga_agent.tasks`` entry-point group.

Built-in tasks register in this project's ``pyproject.toml`` exactly as a third-party plugin
would in its own::

    [project.entry-points."sga_agent.tasks"]
    my-task = "my_package.tasks:MyTask"

The entry point names a zero-argument callable (usually the task class) that returns an object
satisfying :class:`sga_agent.task.Task`. Loading is lazy: listing names imports nothing.
"""

from __future__ import annotations

import difflib
import importlib
import re
from importlib.metadata import EntryPoint, entry_points

from sga_agent.task import Task, TaskBase, as_task

GROUP = "sga_agent.tasks"


class UnknownTaskError(LookupError):
    """No registered task has the requested name."""


def task_entry_points() -> dict[str, EntryPoint]:
    """Registered tasks by name (nothing imported)."""
    return {point.name: point for point in entry_points(group=GROUP)}


def task_names() -> list[str]:
    """Sorted names of the registered tasks."""
    return sorted(task_entry_points())


def entry_point(name: str) -> EntryPoint:
    """The entry point registered as ``name`` (nothing imported).

    Raises
    ------
    UnknownTaskError
        No such task; the message lists the registered ones and the closest match.
    """
    points = task_entry_points()
    if name not in points:
        close = difflib.get_close_matches(name, points, n=1) or _described_as(name, points)
        hint = f" Did you mean {close[0]!r}?" if close else ""
        known = ", ".join(sorted(points)) or "none"
        raise UnknownTaskError(
            f"no task named {name!r} is registered (known: {known}).{hint} "
            f"Tasks register through the {GROUP!r} entry-point group; see `sga-agent tasks`."
        )
    return points[name]


def _described_as(word: str, points: dict[str, EntryPoint]) -> list[str]:
    """The one task whose description holds ``word`` ("sand": granular), if exactly one does.

    Loads the tasks to read their descriptions; a task that fails to load is passed over.
    """
    if not word.isalpha():
        return []
    pattern = re.compile(rf"\b{re.escape(word)}\b", re.IGNORECASE)
    found = []
    for name, point in sorted(points.items()):
        try:
            description = point.load()().description
        except Exception:  # a plugin may fail to import in any way
            continue
        if pattern.search(description):
            found.append(name)
    return found if len(found) == 1 else []


def load_task(name: str) -> TaskBase:
    """Instantiate the task registered as ``name``.

    Raises
    ------
    UnknownTaskError
        No such task; the message lists the registered ones and the closest match.
    TypeError
        The entry point does not produce a :class:`Task`.
    """
    point = entry_point(name)
    task = point.load()()
    if not isinstance(task, Task):
        raise TypeError(
            f"entry point {name!r} ({point.value}) returned {type(task).__name__}, which "
            "does not satisfy sga_agent.task.Task (name, description, kind, seed_solution, "
            "prompt_parts, capture, evaluate)"
        )
    return as_task(task)


def resolve_task(spec: str) -> TaskBase:
    """A registered task, or the result of ``module:callable`` (a zero-argument factory).

    The second form is a plugin-development and testing aid: no entry point needed.
    """
    if ":" not in spec:
        return load_task(spec)
    module_name, _, attribute = spec.partition(":")
    factory = importlib.import_module(module_name)
    for part in attribute.split("."):
        factory = getattr(factory, part)
    task = factory()
    if not isinstance(task, Task):
        raise TypeError(
            f"{spec} returned {type(task).__name__}, which does not satisfy sga_agent.task.Task"
        )
    return as_task(task)
