"""Size limits of the code (issue 49): one room per idea, functions a reader can hold.

No module of ``src/`` or ``plugins/`` is longer than 700 lines, and no function has
more than 80 lines of code (docstrings, comments and blank lines not counted)
unless a comment ``# long function:`` on its first line of code says why.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
MAX_FILE_LINES = 700
MAX_FUNCTION_LINES = 80
WHY = "# long function:"


def _sources() -> list[Path]:
    files = sorted((REPO / "src").rglob("*.py"))
    files += sorted(p for p in (REPO / "plugins").rglob("*.py") if "/src/" in p.as_posix())
    return files


def _code_lines(node: ast.FunctionDef | ast.AsyncFunctionDef, lines: list[str]) -> int:
    body = node.body
    start = body[0].lineno
    first = body[0]
    if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
        if isinstance(first.value.value, str):  # the docstring
            start = (first.end_lineno or first.lineno) + 1
    text = lines[start - 1 : node.end_lineno]
    return sum(1 for line in text if line.strip() and not line.strip().startswith("#"))


def _excused(node: ast.FunctionDef | ast.AsyncFunctionDef, lines: list[str]) -> bool:
    window = lines[node.lineno - 1 : node.body[0].lineno + 1]
    return any(WHY in line for line in window)


def test_the_sources_are_found() -> None:
    files = _sources()
    assert len(files) > 150
    assert any("skelagnostic_vqpae" in p.as_posix() for p in files)


@pytest.mark.parametrize("path", _sources(), ids=lambda p: p.relative_to(REPO).as_posix())
def test_module_and_function_sizes(path: Path) -> None:
    text = path.read_text(encoding="utf-8")
    lines = text.splitlines()
    assert len(lines) <= MAX_FILE_LINES, (
        f"{path.relative_to(REPO)}: {len(lines)} lines (at most {MAX_FILE_LINES}: split it by idea)"
    )
    long = [
        f"{node.name} ({_code_lines(node, lines)} lines of code, line {node.lineno})"
        for node in ast.walk(ast.parse(text))
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
        and _code_lines(node, lines) > MAX_FUNCTION_LINES
        and not _excused(node, lines)
    ]
    assert not long, f"{path.relative_to(REPO)}: functions over {MAX_FUNCTION_LINES} lines: {long}"
