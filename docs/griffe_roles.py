"""Griffe extension of the docs site: Sphinx roles in docstrings become cross-references.

The docstrings are written for Sphinx (``:func:`~taichi_mpm.sysid.fit```, ``:class:`Task```,
``:mod:`.sandbox```, ...), which mkdocstrings does not read: left alone, the roles show as raw
text on the API pages. mkdocs.yml loads this module as a Griffe extension of the mkdocstrings
Python handler. Once a package is loaded, every role in its docstrings is rewritten, before
rendering, into an mkdocs-autorefs reference marked optional::

    <autoref identifier="taichi_mpm.sysid.fit.fit" optional><code>fit()</code></autoref>

mkdocs-autorefs turns it into a link when the target is documented on the site, and into plain
inline code (``<span title="...">``) otherwise, without a warning, so that a reference to an
undocumented object (``pathlib.Path``, a private helper) does not fail ``mkdocs build
--strict``. The source files stay as they are.

The shown text follows Sphinx: the target as written, only its last component with a leading
``~``, an explicit title for ``:role:`title <target>```, and ``()`` after a function or method.
The target is resolved as Sphinx would: a dotted name is looked up in the scope of the object
whose docstring holds it (its members, then its class's, its module's imports and members),
a name starting with ``.`` in the current package (then the packages above it), anything else
as an absolute path. A known target is replaced by its canonical path (where it is defined),
the name under which mkdocstrings registers it besides the page's own name. A ``:func:``,
``:class:``, ... whose path names a module with a member of the same name
(``taichi_mpm.sysid.fit``, the module and its function ``fit``) means that member.
"""

from __future__ import annotations

import contextlib
import html
import re
from typing import Any

import griffe

#: A role: ``:func:`target```, ``:py:class:`~target```, ``:meth:`title <target>```.
ROLE = re.compile(
    r":(?:py:)?(?P<role>func|class|meth|attr|mod|data|exc|obj|const|type|term|ref):"
    r"`(?P<content>[^`]+)`"
)
#: ``title <target>``: a role with an explicit title.
EXPLICIT = re.compile(r"^(?P<title>.+?)\s*<(?P<target>[^<>]+)>$")
#: Roles whose shown text gets ``()``, as Sphinx's ``add_function_parentheses`` (default on).
CALLABLE = {"func", "meth"}
#: Roles that name a module; every other role names something inside one.
MODULE = {"mod"}
#: A fenced code block's fence line (a role in an example is left as written).
FENCE = re.compile(r"^\s*(```|~~~)")


class SphinxRoles(griffe.Extension):
    """Rewrite the Sphinx roles of every docstring of a loaded package (see the module)."""

    def on_package(self, *, pkg: griffe.Module, **kwargs: Any) -> None:
        for obj in _objects(pkg):
            if obj.docstring is not None and ":" in obj.docstring.value:
                obj.docstring.value = rewrite(obj.docstring.value, obj)


def _objects(obj: griffe.Object):
    """``obj`` and every object defined under it (aliases, i.e. imports, are skipped)."""
    yield obj
    for member in list(obj.members.values()):
        if not member.is_alias:
            yield from _objects(member)


def rewrite(text: str, obj: griffe.Object) -> str:
    """``text`` with each role outside fenced code blocks replaced by an optional autoref."""
    lines = text.split("\n")
    fenced = False
    for number, line in enumerate(lines):
        if FENCE.match(line):
            fenced = not fenced
        elif not fenced and "`" in line:
            lines[number] = ROLE.sub(lambda match: _reference(match, obj), line)
    return "\n".join(lines)


def _reference(match: re.Match, obj: griffe.Object) -> str:
    role, content = match["role"], match["content"].strip()
    explicit = EXPLICIT.match(content)
    if explicit:
        title, target = explicit["title"], explicit["target"].strip()
    else:
        target = content.lstrip("!")
        title = target.lstrip(".")
        if title.startswith("~"):
            title = title[1:].rsplit(".", 1)[-1]
        target = target.lstrip("~")
        if role in CALLABLE and not title.endswith(")"):
            title += "()"
    identifier = target if role in ("term", "ref") else _resolve(target, role, obj)
    return (
        f'<autoref identifier="{html.escape(identifier)}" optional>'
        f"<code>{html.escape(title)}</code></autoref>"
    )


def _resolve(target: str, role: str, obj: griffe.Object) -> str:
    """The canonical path of ``target`` seen from ``obj``'s docstring, or the best guess."""
    collection = obj.modules_collection
    if target.startswith("."):
        candidates = [f"{package}{target}" for package in _packages(obj)]
    else:
        head, _, rest = target.partition(".")
        candidates = []
        # A name of the docstring's scope (griffe.NameResolutionError when it is none).
        with contextlib.suppress(griffe.GriffeError):
            resolved = obj.resolve(head)
            candidates.append(f"{resolved}.{rest}" if rest else resolved)
        candidates.append(target)
    for candidate in candidates:
        found = _lookup(collection, candidate)
        if found is None:
            continue
        # A module ``a.b`` and its function ``a.b.b``: any role but :mod: means the function.
        with contextlib.suppress(griffe.GriffeError):
            if role not in MODULE and found.is_module:
                member = found.members.get(candidate.rsplit(".", 1)[-1])
                if member is not None and not member.is_module:
                    found = member
        return _canonical(found, candidate)
    return candidates[0]


def _packages(obj: griffe.Object) -> list[str]:
    """The package holding ``obj``'s module, then each package above it."""
    module = obj.module
    package = module if module.is_init_module else module.parent
    paths = []
    while package is not None:
        paths.append(package.path)
        package = package.parent
    return paths


def _lookup(collection: griffe.ModulesCollection, path: str) -> griffe.Object | None:
    try:
        return collection.get_member(path)
    except (KeyError, ValueError, griffe.GriffeError):  # unknown, or behind an unloaded alias
        return None


def _canonical(found: griffe.Object | griffe.Alias, fallback: str) -> str:
    try:
        return found.canonical_path
    except griffe.GriffeError:  # an alias whose target's package is not loaded (yet)
        return getattr(found, "target_path", None) or fallback
