"""Writing a report's sections as Markdown and as static HTML (images are files next to it)."""

from __future__ import annotations

import html
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import quote

from sga_agent.task.report import Code, Image, Section, Table, Text

__all__ = [
    "Code", "Fold", "FoldedTable", "Image", "Section", "Table", "Text", "markdown", "to_html",
    "write",
]  # fmt: skip


@dataclass
class Fold:
    """A titled text folded into a table row; ``file`` is where it can be read, relative to
    the report's folder ("" for none)."""

    title: str
    text: str
    file: str = ""


@dataclass
class FoldedTable(Table):
    """A table whose rows each end in a cell of folded texts (``folds``, one list per row):
    a ``<details>`` in HTML, links to their files in Markdown."""

    folds: list[list[Fold]] = field(default_factory=list)
    fold_header: str = "details"


def _md_cell(text: str) -> str:
    """``text`` as one cell of a Markdown table: one line, its pipes and tags inert."""
    return text.replace("\n", " ").replace("|", "\\|").replace("<", "&lt;")


def _md_folds(folds: list[Fold]) -> str:
    return ", ".join(f"[{fold.title}]({quote(fold.file)})" if fold.file else fold.title
                     for fold in folds)  # fmt: skip


def _html_folds(folds: list[Fold]) -> str:
    if not folds:
        return ""
    summary = html.escape(", ".join(fold.title for fold in folds))
    texts = "".join(f"<p><b>{html.escape(fold.title)}</b></p><pre>{html.escape(fold.text)}</pre>"
                    for fold in folds)  # fmt: skip
    return f"<details><summary>{summary}</summary>{texts}</details>"


def _runs(text: str) -> list[tuple[bool, list[str]]]:
    """``text``'s lines grouped into paragraphs and lists: (is_list, lines), a list's lines
    being its items without the ``- `` marker."""
    runs: list[tuple[bool, list[str]]] = []
    for line in text.split("\n"):
        is_item = line.startswith("- ")
        if not runs or runs[-1][0] != is_item:
            runs.append((is_item, []))
        runs[-1][1].append(line[2:] if is_item else line)
    return runs


def _fence(text: str) -> str:
    longest = max((len(run) for run in text.split("\n") if set(run) == {"`"}), default=2)
    return "`" * max(3, longest + 1)


def markdown(title: str, sections: list[Section]) -> str:
    """The report as Markdown."""
    lines = [f"# {title}", ""]
    for section in sections:
        if section.collapsed:  # GitHub renders the Markdown inside, blank lines around it
            lines += ["<details>", f"<summary><b>{html.escape(section.title)}</b></summary>", ""]
        else:
            lines += [f"## {section.title}", ""]
        for block in section.blocks:
            if isinstance(block, Text):  # a blank line before and after each list
                for is_list, run in _runs(block.text):
                    lines += [f"- {item}" for item in run] if is_list else run
                    lines.append("")
            elif isinstance(block, FoldedTable):
                header = [*block.header, block.fold_header]
                lines.append("| " + " | ".join(header) + " |")
                lines.append("|" + "---|" * len(header))
                for row, folds in zip(block.rows, block.folds, strict=True):
                    cells = [*map(_md_cell, row), _md_folds(folds)]
                    lines.append("| " + " | ".join(cells) + " |")
                lines.append("")
            elif isinstance(block, Table):
                lines.append("| " + " | ".join(block.header) + " |")
                lines.append("|" + "---|" * len(block.header))
                lines += ["| " + " | ".join(row) + " |" for row in block.rows]
                lines.append("")
            elif isinstance(block, Image):
                lines += [f"![{block.alt}]({block.file})", ""]
            else:
                fence = _fence(block.text)
                lines += [f"{fence}{block.language}", block.text.rstrip("\n"), fence, ""]
        if section.collapsed:
            lines += ["</details>", ""]
    return "\n".join(lines)


STYLE = """body{font-family:sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222}
table{border-collapse:collapse}td,th{border:1px solid #bbb;padding:3px 8px;text-align:right}
pre{background:#f4f4f4;padding:1em;overflow-x:auto}img{max-width:100%}
details{margin:1em 0}summary{cursor:pointer;font-size:1.2em}
table.folded td{text-align:left;vertical-align:top}table.folded details{margin:0}
table.folded summary{font-size:1em}table.folded pre{white-space:pre-wrap;max-width:60em}"""


def _inline(text: str) -> str:
    """Escape, then turn Markdown's `code` and **bold** into tags (all the report uses)."""
    parts = html.escape(text).split("`")
    out = "".join(f"<code>{p}</code>" if i % 2 else p for i, p in enumerate(parts))
    bold = out.split("**")
    return "".join(f"<b>{p}</b>" if i % 2 else p for i, p in enumerate(bold))


def to_html(title: str, sections: list[Section]) -> str:
    """The report as one static HTML page."""
    body = [f"<h1>{html.escape(title)}</h1>"]
    for section in sections:
        if section.collapsed:
            body.append(f"<details><summary><b>{html.escape(section.title)}</b></summary>")
        else:
            body.append(f"<h2>{html.escape(section.title)}</h2>")
        for block in section.blocks:
            if isinstance(block, Text):
                for is_list, run in _runs(block.text):
                    if is_list:
                        body.append("<ul>" + "".join(f"<li>{_inline(i)}</li>" for i in run)
                                    + "</ul>")  # fmt: skip
                    else:
                        paragraph = "\n".join(run)
                        body.append(f"<p>{_inline(paragraph)}</p>")
            elif isinstance(block, FoldedTable):
                head = "".join(f"<th>{html.escape(cell)}</th>"
                               for cell in [*block.header, block.fold_header])  # fmt: skip
                rows = "".join(
                    "<tr>" + "".join(f"<td>{html.escape(cell)}</td>" for cell in row)
                    + f"<td>{_html_folds(folds)}</td></tr>"
                    for row, folds in zip(block.rows, block.folds, strict=True)
                )  # fmt: skip
                body.append(f'<table class="folded"><tr>{head}</tr>{rows}</table>')
            elif isinstance(block, Table):
                head = "".join(f"<th>{html.escape(cell)}</th>" for cell in block.header)
                rows = "".join(
                    "<tr>" + "".join(f"<td>{html.escape(cell)}</td>" for cell in row) + "</tr>"
                    for row in block.rows
                )
                body.append(f"<table><tr>{head}</tr>{rows}</table>")
            elif isinstance(block, Image):
                body.append(f'<p><img src="{html.escape(block.file)}" '
                            f'alt="{html.escape(block.alt)}"></p>')  # fmt: skip
            else:
                body.append(f"<pre><code>{html.escape(block.text)}</code></pre>")
        if section.collapsed:
            body.append("</details>")
    return (
        '<!DOCTYPE html>\n<html><head><meta charset="utf-8">'
        f"<title>{html.escape(title)}</title><style>{STYLE}</style></head>\n<body>\n"
        + "\n".join(body)
        + "\n</body></html>\n"
    )


def write(folder: Path, title: str, sections: list[Section]) -> tuple[Path, Path]:
    """Write ``report.md`` and ``report.html`` into ``folder``."""
    md, page = folder / "report.md", folder / "report.html"
    md.write_text(markdown(title, sections), encoding="utf-8")
    page.write_text(to_html(title, sections), encoding="utf-8")
    return md, page
