"""Module-level imports of the package use only its declared dependencies.

A fresh ``pip install -e .`` (the README's first command) installs
``[project.dependencies]`` and nothing else, while the test environment also has the
extras: an optional library imported at the top of a module the main job loads
passes every test and breaks the README. Each module of ``src/`` and
``plugins/*/src`` may import at module level only the standard library, the
project's own packages and the declared dependencies; optional libraries are
imported where they are used (inside a function, a ``try`` or under
``TYPE_CHECKING``).
"""

from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

import pytest

tomllib = pytest.importorskip("tomllib")  # Python 3.11+

REPO = Path(__file__).resolve().parents[1]
#: Distribution name -> the import names it provides (where they differ).
IMPORT_NAMES = {"pillow": {"PIL"}, "hydra-core": {"hydra", "omegaconf"}}
#: Module-level imports of optional libraries that are allowed, with the reason.
ALLOWED = {
    ("pytest", "src/skelagnostic/testing/contract.py"): "the contract test runs under pytest",
}


def _declared() -> set[str]:
    project = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    names: set[str] = set()
    for requirement in project["dependencies"]:
        dist = re.split(r"[<>=!~\[; ]", requirement, maxsplit=1)[0].strip().lower()
        names |= IMPORT_NAMES.get(dist, {dist.replace("-", "_")})
    return names


def _module_level_imports(tree: ast.Module) -> set[str]:
    """Root names imported unconditionally at module level (not in try / TYPE_CHECKING)."""
    found: set[str] = set()

    def walk(body: list[ast.stmt]) -> None:
        for node in body:
            if isinstance(node, ast.If):
                if "TYPE_CHECKING" not in ast.unparse(node.test):
                    walk(node.body)
                walk(node.orelse)
            elif isinstance(node, ast.Import):
                found.update(alias.name.split(".")[0] for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                found.add(node.module.split(".")[0])

    walk(tree.body)
    return found


def test_module_level_imports_are_declared_dependencies() -> None:
    own = {"skelagnostic", *(p.name for p in REPO.glob("plugins/*/src/*") if p.is_dir())}
    allowed = set(sys.stdlib_module_names) | own | _declared()
    files = sorted((REPO / "src").rglob("*.py"))
    files += sorted(p for p in (REPO / "plugins").rglob("*.py") if "/src/" in p.as_posix())
    bad = []
    for file in files:
        where = file.relative_to(REPO).as_posix()
        for name in _module_level_imports(ast.parse(file.read_text(encoding="utf-8"))):
            if name not in allowed and (name, where) not in ALLOWED:
                bad.append(f"{where}: {name}")
    assert not bad, f"optional libraries imported at module level: {bad}"
