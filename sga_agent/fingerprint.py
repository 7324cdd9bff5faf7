"""Fingerprints of candidate code: equal for candidates that differ only in form.

Two candidates whose code has the same abstract syntax tree, once docstrings are dropped, behave
the same, so the search evaluates them once. Whitespace, comments, docstrings and the
quoting style of strings do not change the fingerprint; names, literals and structure do.
Text that does not parse (a broken proposal) is compared with its runs of whitespace collapsed
instead. Comments being dropped, this assumes solutions are Python code, as the solutions of
every built-in task are (a molecule is a code block of literals): a bare SMILES "C#N" would
parse as the name ``C`` followed by a comment.
"""

from __future__ import annotations

import ast
import hashlib
import warnings

_DOCUMENTED = (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)


def fingerprint(code: str) -> str:
    """A SHA-256 hex digest of ``code``'s normalized syntax tree (or normalized text).

    Examples
    --------
    >>> fingerprint("x = 1  # one") == fingerprint('''x  =  1''')
    True
    >>> fingerprint("x = 1") == fingerprint("x = 1.0")
    False
    """
    try:
        with warnings.catch_warnings():  # e.g. invalid escapes such as the "\\C" of a SMILES
            warnings.simplefilter("ignore")
            tree = ast.parse(code)
    except (SyntaxError, ValueError):  # ValueError: null bytes
        normalized = "text:" + " ".join(code.split())
    else:
        normalized = ast.dump(_without_docstrings(tree), annotate_fields=False)
    return hashlib.sha256(normalized.encode("utf-8", errors="surrogatepass")).hexdigest()


def _without_docstrings(tree: ast.Module) -> ast.Module:
    """Drop docstrings in place; a body left empty gets ``pass``, which means the same."""
    for node in ast.walk(tree):
        if not isinstance(node, _DOCUMENTED) or not node.body:
            continue
        first = node.body[0]
        value = first.value if isinstance(first, ast.Expr) else None
        if isinstance(value, ast.Constant) and isinstance(value.value, str):
            node.body = node.body[1:] or [ast.Pass()]
    return tree
