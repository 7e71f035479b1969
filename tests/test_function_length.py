"""No function or method of ours has more than :data:`LIMIT` code lines.

A function that does not fit on two screens is read as a list of steps whose names are
missing; the rule makes the steps functions with names. It is checked here, from the source
(:mod:`ast`, and :mod:`tokenize` where the tree leaves a line's kind open), because a rule
that no machine checks is not kept.

What is checked: every ``.py`` file under :data:`CHECKED` (the four packages, the
benchmarks, the tests themselves, and the scripts that make the notebooks and the data),
outside hidden folders (the benchmarks' virtual environments); in each, every ``def`` and
``async def`` at any depth (functions, methods, nested functions).

How a function's code lines are counted (:func:`code_lines`):

- its *span* runs from its ``def`` line to its last line (``end_lineno``); decorators,
  which stand above the ``def``, are not part of it;
- a line of the span counts when it holds a token other than a comment, that is, when it
  is neither blank nor comment-only; each line of a string literal that spans several lines
  counts (a long help text is code the reader reads), except blank lines inside it;
- the lines of docstrings are not counted: the function's own, and those of the functions
  and classes nested in it (prose that explains the code is not the code);
- a nested function's lines count toward its parent too (they lie in the parent's span,
  and the reader of the parent reads them), and the nested function is checked on its own.
"""

from __future__ import annotations

import ast
import io
import tokenize
from pathlib import Path
from typing import NamedTuple

ROOT = Path(__file__).resolve().parents[1]
LIMIT = 100
CHECKED = (
    "relation_metric",
    "recovery",
    "landmark_graph",
    "slamrel",
    "benchmarks",
    "tests",
    "notebooks",
    "data",
)
_FUNCTIONS = (ast.FunctionDef, ast.AsyncFunctionDef)
# tokens that do not make a line code (a line of INDENT or DEDENT alone is blank)
_NOT_CODE = {
    tokenize.COMMENT,
    tokenize.NL,
    tokenize.NEWLINE,
    tokenize.INDENT,
    tokenize.DEDENT,
    tokenize.ENCODING,
    tokenize.ENDMARKER,
}


class LongFunction(NamedTuple):
    """One function over the limit: where it is and how many code lines it has."""

    path: str
    line: int
    name: str
    lines: int

    def __str__(self) -> str:
        return f"{self.path}:{self.line} {self.name}: {self.lines} code lines"


class _Tree(NamedTuple):
    """What :func:`code_lines` needs of a syntax tree, collected in one traversal."""

    #: every function: its ``def`` line, last line and qualified name
    functions: list[tuple[int, int, str]]
    #: the lines of every docstring (module, class, function)
    docstrings: set[int]
    #: the lines after the first of every string literal that spans several
    in_string: set[int]


def _scan(tree: ast.AST) -> _Tree:
    """The functions, docstring lines and string lines of ``tree``."""
    out = _Tree([], set(), set())
    stack: list[tuple[ast.AST, str]] = [(tree, "")]
    while stack:
        node, prefix = stack.pop()
        if isinstance(node, (ast.Constant, ast.JoinedStr)) and node.end_lineno:
            out.in_string.update(range(node.lineno + 1, node.end_lineno + 1))
        if isinstance(node, (*_FUNCTIONS, ast.ClassDef, ast.Module)) and node.body:
            first = node.body[0]
            if (
                isinstance(first, ast.Expr)
                and isinstance(first.value, ast.Constant)
                and isinstance(first.value.value, str)
            ):
                out.docstrings.update(range(first.lineno, (first.end_lineno or first.lineno) + 1))
        if isinstance(node, _FUNCTIONS):
            prefix += node.name
            out.functions.append((node.lineno, node.end_lineno or node.lineno, prefix))
            prefix += "."
        elif isinstance(node, ast.ClassDef):
            prefix += node.name + "."
        stack.extend((child, prefix) for child in ast.iter_child_nodes(node))
    return out


def _code_lines(source: str, in_string: set[int]) -> set[int]:
    """Numbers of the lines (1-based) of ``source`` that hold code: neither blank nor
    comment-only (``in_string``: the lines after the first of its multi-line strings).

    A line that starts with ``#`` is a comment unless it lies inside a string literal that
    spans several lines. The syntax tree tells where such literals are, but not whether a
    ``#`` line inside one is string (a line of a triple-quoted string) or comment (between
    implicitly joined strings); for the files that have such a line the tokenizer decides
    (it is slower: most files do without it).
    """
    lines = source.replace("\r\n", "\n").replace("\r", "\n").split("\n")  # as ast counts
    if any(lines[row - 1].lstrip().startswith("#") for row in in_string):
        return _token_lines(source, lines)
    return {
        row
        for row, text in enumerate(lines, start=1)
        if text.strip() and not text.lstrip().startswith("#")
    } | {row for row in in_string if lines[row - 1].strip()}


def _token_lines(source: str, lines: list[str]) -> set[int]:
    """The lines that hold a token other than a comment (blank lines of strings excluded)."""
    code: set[int] = set()
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        if token.type not in _NOT_CODE:
            code.update(r for r in range(token.start[0], token.end[0] + 1) if lines[r - 1].strip())
    return code


def code_lines(source: str) -> dict[tuple[int, str], int]:
    """Each function's code lines in ``source``, keyed by (``def`` line, qualified name).

    The qualified name joins enclosing classes and functions with dots, as
    ``Class.method`` or ``outer.inner``.
    """
    tree = _scan(ast.parse(source))
    code = _code_lines(source, tree.in_string) - tree.docstrings
    return {
        (first, name): sum(1 for row in range(first, last + 1) if row in code)
        for first, last, name in tree.functions
    }


def long_functions(root: Path = ROOT, limit: int = LIMIT) -> list[LongFunction]:
    """Every function under ``root``'s :data:`CHECKED` folders with more than ``limit``."""
    found = []
    for folder in CHECKED:
        for path in sorted((root / folder).rglob("*.py")):
            if any(part.startswith(".") for part in path.relative_to(root).parts):
                continue  # virtual environments (benchmarks/.venv-*) and caches
            counts = code_lines(path.read_text(encoding="utf-8"))
            for (line, name), count in counts.items():
                if count > limit:
                    found.append(LongFunction(str(path.relative_to(root)), line, name, count))
    return found


SAMPLE = '''\
import os


@decorator(
    option=1,
)
def sample(a,
           b):
    """Docstring,

    over three lines."""
    # a comment-only line

    x = a + b  # a trailing comment
    text = """first
second

fourth"""

    def inner():
        """Inner's docstring."""
        return x

    class Local:
        """Local's docstring."""

        value = 1

    return text, inner, Local


class Holder:
    async def method(self):
        # comment
        return 1
'''


def test_counter_on_a_sample_counted_by_hand():
    """The counts of :data:`SAMPLE`, counted by hand line by line.

    ``sample``: ``def sample(a,`` and ``b):`` (2), ``x = ...`` (1), the four-line string
    without its blank line (3), ``def inner():`` and ``return x`` (2), ``class Local:``
    and ``value = 1`` (2), ``return ...`` (1): 11. Not counted: the decorator, its three
    docstrings, the comment-only line, the blank lines. ``sample.inner``: 2.
    ``Holder.method``: 2 (``async def`` and ``return 1``).
    """
    assert code_lines(SAMPLE) == {
        (7, "sample"): 11,
        (20, "sample.inner"): 2,
        (33, "Holder.method"): 2,
    }


# a comment between implicitly joined strings, and a string's line that starts with "#":
# the syntax tree cannot tell them apart, the tokenizer can
SAMPLE_HASHES = '''\
def joined():
    text = (
        "a"
        # a comment between implicitly joined strings
        "b"
    )
    shell = """
# a line of the string, not a comment
"""
    return text, shell
'''


def test_counter_tells_comments_from_strings_that_start_with_a_hash():
    """:data:`SAMPLE_HASHES` by hand: every line but the comment, 9; and on :data:`SAMPLE`,
    which needs no tokenizer, the tokenizer's lines are the syntax tree's."""
    assert code_lines(SAMPLE_HASHES) == {(1, "joined"): 9}
    lines = SAMPLE.split("\n")
    assert _code_lines(SAMPLE, _scan(ast.parse(SAMPLE)).in_string) == _token_lines(SAMPLE, lines)


def test_counter_finds_a_function_just_over_the_limit(tmp_path):
    """A function of ``limit + 1`` code lines is listed, one of ``limit`` is not."""
    (tmp_path / "tests").mkdir()
    body = "".join(f"    x{i} = {i}\n" for i in range(LIMIT - 1))
    (tmp_path / "tests" / "sample.py").write_text(
        f"def at_limit():\n{body}\n\ndef over_limit():\n{body}    x = 0\n"
    )
    found = long_functions(tmp_path)
    assert [(f.name, f.lines) for f in found] == [("over_limit", LIMIT + 1)]


def test_no_function_has_more_than_the_limit():
    """Every function and method of ours has at most :data:`LIMIT` code lines."""
    found = long_functions()
    assert not found, f"functions over {LIMIT} code lines:\n" + "\n".join(map(str, found))
