"""``sga-agent tasks``: list the registered tasks."""

from __future__ import annotations

from rich.console import Console
from rich.text import Text

from sga_agent import registry
from sga_agent.cli import main


@main.command()
def tasks() -> None:
    """List the registered tasks.

    One line per task: its name, kind and description. Each task is loaded to read them; a
    task that fails to load is listed with the reason instead.
    """
    console = Console(soft_wrap=True, highlight=False)
    names = registry.task_names()
    if not names:
        console.print(f"no tasks are registered in the entry-point group {registry.GROUP!r}")
        return
    width = max(len(name) for name in names)
    for name in names:
        line = Text()
        line.append(f"{name:<{width}}  ", style="bold")
        try:
            task = registry.load_task(name)
        except Exception as error:  # a plugin may fail to import in any way
            line.append(f"{'?':<8}  (failed to load: {_first_line(error)})", style="red")
        else:
            line.append(f"{task.kind:<8}  ")
            line.append(task.description.strip().splitlines()[0] if task.description else "")
        console.print(line)


def _first_line(error: Exception) -> str:
    lines = str(error).strip().splitlines()
    return f"{type(error).__name__}: {lines[0]}" if lines else type(error).__name__
