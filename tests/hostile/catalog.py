"""The hostile corpus: candidate laws written the way a reward-hacking model would write them.

Each file in ``candidates/`` is one complete answer (a ``class Physics(nn.Module)``) that tries
to lower its reported loss by other means than physics, or to damage or read the host. Its
module docstring describes the attack (``Attack:``) and what it aims at (``Target:``) and ends
with header lines::

    expected: refused | honest
    category: monkeypatch | subclass | mode | hook | forge | process | cost | cache | secret |
      names
    static: passes | rejected
    task: granular | elastic          (optional; granular when absent)
    check: what a harness must verify beyond the outcome (optional, repeatable;
      a line indented by two spaces continues the header above it)

``refused``: the candidate must come back not ok (invalid, error, crashed, timeout,
out_of_memory or unstable). ``honest``: it may come back ok, but then its reported loss must
equal an honest re-evaluation of its captured graph. ``static`` records whether
:func:`sga_agent.parsing.check_candidate` accepts the code; either way, ``expected`` holds for the
sandbox alone (static checks bypassed) as much as for the whole path.

The files are data. Loading the catalog parses them (``ast``) and runs nothing; never import or
execute a candidate outside the capture sandbox: they are destructive by design.
"""

from __future__ import annotations

import ast
import re
from dataclasses import dataclass
from pathlib import Path

CANDIDATES = Path(__file__).parent / "candidates"
EXPECTED = ("refused", "honest")
CATEGORIES = ("monkeypatch", "subclass", "mode", "hook", "forge", "process", "cost", "cache",
              "secret", "names")  # fmt: skip
STATIC = ("passes", "rejected")
TASKS = ("granular", "elastic")
#: The secret the tests plant in /root/.sga-hostile-secret (and in the caller's environment).
MARKER = "SGA-HOSTILE-MARKER-7f3a"

_FILE_NAME = re.compile(r"\d{2}_[a-z0-9_]+\.py\Z")
_HEADER = re.compile(r"(expected|category|static|task|check):[ \t]*(.*?)\s*\Z")
_CONTINUATION = "  "
_SINGLE = ("expected", "category", "static", "task")


class CatalogError(ValueError):
    """A candidate file is misnamed or its headers are missing or malformed."""


@dataclass(frozen=True)
class HostileCandidate:
    """One hostile candidate and what its headers promise.

    ``name`` is the file's stem (``01_patch_tensor_item``), ``description`` the docstring
    without its header lines, ``checks`` the ``check:`` headers, continuations joined.
    """

    name: str
    path: Path
    code: str
    expected: str
    category: str
    description: str
    static: str
    task: str = "granular"
    checks: tuple[str, ...] = ()

    @property
    def summary(self) -> str:
        """The docstring's first line."""
        return self.description.splitlines()[0]


def parse_candidate(path: Path) -> HostileCandidate:
    """Read one candidate file's headers (parsing only; nothing is executed)."""
    path = Path(path)
    if not _FILE_NAME.match(path.name):
        raise CatalogError(f"{path.name}: candidate files are named NN_short_name.py")
    code = path.read_text(encoding="utf-8")
    try:
        docstring = ast.get_docstring(ast.parse(code, filename=str(path)))
    except SyntaxError as error:
        raise CatalogError(
            f"{path.name}: not valid Python ({error.msg}, line {error.lineno})"
        ) from None
    if not docstring:
        raise CatalogError(f"{path.name}: no module docstring")
    headers: dict[str, str] = {}
    checks: list[str] = []
    description: list[str] = []
    last: str | None = None
    for line in docstring.splitlines():
        match = _HEADER.match(line)
        if match:
            key, value = match.groups()
            if not value:
                raise CatalogError(f"{path.name}: empty header {key!r}")
            if key == "check":
                checks.append(value)
            elif key in headers:
                raise CatalogError(f"{path.name}: header {key!r} given twice")
            else:
                headers[key] = value
            last = key
        elif last is not None and line.startswith(_CONTINUATION) and line.strip():
            if last == "check":
                checks[-1] += " " + line.strip()
            else:
                headers[last] += " " + line.strip()
        else:
            last = None
            description.append(line)
    for key, allowed in (("expected", EXPECTED), ("category", CATEGORIES), ("static", STATIC)):
        if key not in headers:
            raise CatalogError(f"{path.name}: missing header {key!r}")
        if headers[key] not in allowed:
            raise CatalogError(f"{path.name}: {key} must be one of {allowed}, not {headers[key]!r}")
    task = headers.get("task", "granular")
    if task not in TASKS:
        raise CatalogError(f"{path.name}: task must be one of {TASKS}, not {task!r}")
    return HostileCandidate(
        name=path.stem,
        path=path,
        code=code,
        expected=headers["expected"],
        category=headers["category"],
        description="\n".join(description).strip(),
        static=headers["static"],
        task=task,
        checks=tuple(checks),
    )


def load_catalog(folder: Path = CANDIDATES) -> list[HostileCandidate]:
    """Every candidate in ``folder``, in file-name order."""
    return [parse_candidate(path) for path in sorted(Path(folder).glob("*.py"))]
