"""Fingerprints of candidate code: equal for candidates that differ only in form.

Two candidates whose code has the same abstract syntax tree, once docstrings are dropped, behave
the same, so the search evaluates them once. Whitespace, comments, docstrings and the
quoting style of strings do not change the fingerprint; names, literals and structure do.
Text that does not parse (a broken proposal) is compared with its runs of whitespace collapsed
instead. :func:`form_fingerprint` goes further: numbers count as one, so the same law with
other constants (other starting values of its fit) has the same form. Comments being dropped,
this assumes solutions are Python code, as the solutions of
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


def form_fingerprint(code: str) -> str:
    """A digest equal for code that differs only in its numbers (and what
    :func:`fingerprint` ignores): the same law with other constants.

    Examples
    --------
    >>> form_fingerprint("k = 2.0 * x") == form_fingerprint("k = -3 * x")
    True
    >>> form_fingerprint("k = 2.0 * x") == form_fingerprint("k = 2.0 + x")
    False
    """
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tree = ast.parse(code)
    except (SyntaxError, ValueError):
        return fingerprint(code)
    normalized = ast.dump(_NumbersAsOne().visit(_without_docstrings(tree)), annotate_fields=False)
    return hashlib.sha256(normalized.encode("utf-8", errors="surrogatepass")).hexdigest()


class _NumbersAsOne(ast.NodeTransformer):
    """Every number, signed or not, becomes the same constant."""

    def visit_Constant(self, node: ast.Constant) -> ast.AST:
        if isinstance(node.value, int | float | complex) and not isinstance(node.value, bool):
            return ast.Constant(0)
        return node

    def visit_UnaryOp(self, node: ast.UnaryOp) -> ast.AST:
        operand = self.visit(node.operand)
        signed = isinstance(node.op, ast.USub | ast.UAdd) and isinstance(operand, ast.Constant)
        if signed and operand.value == 0 and not isinstance(operand.value, bool):
            return operand
        node.operand = operand
        return node


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
