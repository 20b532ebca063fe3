"""Layering as a contract: imports point downwards, heavy frameworks stay in their layer.

The layers are those of ``ARCHITECTURE.md`` (docs/concepts.md shows them), bottom first.
Every module of ``src/`` and of the plugin packages in ``plugins/*/src`` is read with
:mod:`ast` (module-level, function-level and ``TYPE_CHECKING`` imports alike), so a lazy
import inside a function cannot hide a dependency. On top of the static checks, the
light packages are imported in a fresh interpreter to see what they really pull in.
"""

from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
FRAMEWORK = REPO / "src" / "skelagnostic"

#: Layer of every top-level unit (a subpackage or module of skelagnostic, a plugin
#: package, ``hydra_plugins``); a unit may import only units of a lower layer.
#: ``TYPE_CHECKING`` imports are exempt from the order (they cost nothing at run time)
#: but not from the third-party rules below. A new unit must be placed here.
LAYERS: dict[str, int] = {
    "skelagnostic._shadow": 0,
    "skelagnostic.errors": 0,
    "skelagnostic.filenames": 0,
    "skelagnostic.lazy": 0,
    "skelagnostic.version": 0,
    "skelagnostic.core": 1,
    "skelagnostic.io": 2,
    "skelagnostic.analysis": 3,
    "skelagnostic.baselines": 4,
    "skelagnostic.representations": 4,
    "skelagnostic.procedural": 4,
    "skelagnostic.metrics": 5,
    "skelagnostic.matching": 5,
    "skelagnostic.viz": 5,
    "skelagnostic.aligners": 6,
    "skelagnostic.data": 6,
    "skelagnostic.callbacks": 6,
    "skelagnostic.cleanup": 6,
    "skelagnostic.evaluation": 6,
    "skelagnostic.plugins": 8,
    "skelagnostic_humot": 9,
    "skelagnostic_pcmrl": 9,
    "skelagnostic_vqpae": 9,
    "skelagnostic_example": 9,
    "skelagnostic.cli": 10,
    "hydra_plugins": 11,
    "skelagnostic.testing": 11,
}
#: The method plugins: they build on the framework, never on the CLI or on each other.
PLUGIN_PACKAGES = (
    "skelagnostic_humot",
    "skelagnostic_pcmrl",
    "skelagnostic_vqpae",
    "skelagnostic_example",
)
#: Packages other projects reuse: torch (and torchmetrics) only, no training framework.
LIGHT = (
    "skelagnostic.core",
    "skelagnostic.analysis",
    "skelagnostic.io",
    "skelagnostic.representations",
    "skelagnostic.procedural",
    "skelagnostic.metrics",
    "skelagnostic.matching",
    "skelagnostic.viz",
    "skelagnostic.baselines",
    "skelagnostic.cleanup",
)
FRAMEWORKS = ("lightning", "pytorch_lightning", "lightning_fabric", "hydra", "omegaconf", "pluggy")
#: Third-party packages allowed only inside the given units.
ONLY_IN = {
    "hydra": ("skelagnostic.cli", "hydra_plugins"),
    "pluggy": ("skelagnostic.plugins",),
}
#: Upward imports that exist today, each with the reason it is tolerated. An entry that
#: no longer matches an import fails the test, so the list only shrinks.
KNOWN_UPWARD: dict[tuple[str, str], str] = {}
#: Floors inside each method plugin, bottom first (ARCHITECTURE.md: the model < its
#: embedding/inference < applications (transfer, retarget) < evaluation protocols < the
#: public aligner, where the model's class gains what those floors do (VQ-PAE) < the
#: plugin's wiring): a module may import modules of its own floor or lower ones, never a
#: higher one (``TYPE_CHECKING`` imports aside). Keys are module names or prefixes (the
#: longest that matches decides; the plugin's own name matches its ``__init__`` only); a
#: plugin module that matches none fails the test.
#: PC-MRL: one subpackage per stage (``recon``, ``interp``) on the model floor, the
#: Table 1 protocol of ``interp`` and the plugin's protocols above them.
PLUGIN_FLOORS: dict[str, dict[str, int]] = {
    "skelagnostic_vqpae": {
        "skelagnostic_vqpae.model": 0,
        "skelagnostic_vqpae.codebook": 0,
        "skelagnostic_vqpae.schedule": 0,
        "skelagnostic_vqpae.data": 0,
        "skelagnostic_vqpae.features": 0,
        "skelagnostic_vqpae.training": 0,
        "skelagnostic_vqpae.graphs": 0,
        "skelagnostic_vqpae.options": 0,
        "skelagnostic_vqpae.losses": 0,
        "skelagnostic_vqpae.predictions": 0,
        "skelagnostic_vqpae.embed": 1,
        "skelagnostic_vqpae.transfer": 2,
        "skelagnostic_vqpae.picture": 2,
        "skelagnostic_vqpae.protocols": 3,
        # the public aligner: the model with its fit summary and transfer
        "skelagnostic_vqpae.aligner": 4,
        "skelagnostic_vqpae.authors": 4,
        "skelagnostic_vqpae.plugin": 5,
        "skelagnostic_vqpae": 5,
    },
    "skelagnostic_humot": {
        "skelagnostic_humot.xcit": 0,
        "skelagnostic_humot.model": 0,
        "skelagnostic_humot.template": 0,
        "skelagnostic_humot.data": 0,
        "skelagnostic_humot.aligner": 0,
        "skelagnostic_humot.receptive": 1,
        "skelagnostic_humot.evaluation": 3,
        "skelagnostic_humot.ablations": 3,
        "skelagnostic_humot.plugin": 4,
        "skelagnostic_humot": 4,
    },
    "skelagnostic_pcmrl": {
        "skelagnostic_pcmrl.points": 0,
        "skelagnostic_pcmrl.layouts": 0,
        "skelagnostic_pcmrl.recon": 0,
        "skelagnostic_pcmrl.interp": 0,
        "skelagnostic_pcmrl.authors": 0,
        "skelagnostic_pcmrl.interp.evaluation": 3,
        "skelagnostic_pcmrl.evaluation": 3,
        "skelagnostic_pcmrl.plugin": 4,
        "skelagnostic_pcmrl": 4,
    },
}
#: Upward imports inside plugins that exist today (module, target) -> why: none tolerated.
KNOWN_UPWARD_IN_PLUGINS: dict[tuple[str, str], str] = {}
#: Import cycles among the modules of ``src/`` and ``plugins/*/src`` that exist today, each
#: a set of modules. An entry that no longer matches a cycle fails the test (the set only
#: shrinks); any other cycle fails it too.
KNOWN_CYCLES: set[frozenset[str]] = set()


@dataclass(frozen=True)
class Edge:
    """One import statement: who imports what, where, and whether only for type checking."""

    module: str
    target: str
    file: Path
    line: int
    type_checking: bool
    #: The names of a ``from target import ...`` (a name may be a submodule of ``target``).
    names: tuple[str, ...] = ()

    def __str__(self) -> str:
        return f"{self.file.relative_to(REPO)}:{self.line}: {self.module} imports {self.target}"


def _roots() -> dict[str, Path]:
    """Top-level package name -> its directory, for the framework, hydra_plugins and plugins."""
    roots = {"skelagnostic": FRAMEWORK, "hydra_plugins": REPO / "src" / "hydra_plugins"}
    for init in sorted(REPO.glob("plugins/*/src/*/__init__.py")):
        roots[init.parent.name] = init.parent
    return roots


def _facade_names() -> dict[str, str]:
    """Names the top-level ``skelagnostic`` namespace re-exports lazily -> defining module."""
    tree = ast.parse((FRAMEWORK / "__init__.py").read_text())
    for node in tree.body:
        target = (
            node.target
            if isinstance(node, ast.AnnAssign)
            else (node.targets[0] if isinstance(node, ast.Assign) else None)
        )
        if isinstance(target, ast.Name) and target.id == "_LAZY" and node.value is not None:
            return {name: module for name, (module, _) in ast.literal_eval(node.value).items()}
    return {}


def _type_checking_lines(tree: ast.Module) -> set[int]:
    """Line numbers inside ``if TYPE_CHECKING:`` blocks."""
    lines: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for inner in node.body:
                lines.update(range(inner.lineno, (inner.end_lineno or inner.lineno) + 1))
    return lines


def _scan(root: Path, facade: dict[str, str]) -> Iterator[Edge]:
    """Every import statement of every module of the package in ``root``."""
    for file in sorted(root.rglob("*.py")):
        parts = list(file.relative_to(root.parent).with_suffix("").parts)
        is_init = parts[-1] == "__init__"
        if is_init:
            parts = parts[:-1]
        module = ".".join(parts)
        tree = ast.parse(file.read_text(), filename=str(file))
        checking = _type_checking_lines(tree)
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = parts if is_init else parts[:-1]
                    base = base[: len(base) - node.level + 1]
                    source = ".".join([*base, *([node.module] if node.module else [])])
                else:
                    source = node.module or ""
                targets = [source]
                if source == "skelagnostic":  # the facade: resolve what is taken from it
                    targets = [
                        f"skelagnostic.{a.name}"
                        if (FRAMEWORK / a.name).is_dir() or (FRAMEWORK / f"{a.name}.py").is_file()
                        else facade.get(a.name, "skelagnostic")
                        for a in node.names
                    ]
            else:
                continue
            names = tuple(a.name for a in node.names) if isinstance(node, ast.ImportFrom) else ()
            for target in targets:
                yield Edge(module, target, file, node.lineno, node.lineno in checking, names)


def _unit(name: str) -> str:
    """The layered unit a module belongs to (``skelagnostic.metrics.lafan`` -> ``...metrics``)."""
    parts = name.split(".")
    return ".".join(parts[:2]) if parts[0] == "skelagnostic" and len(parts) > 1 else parts[0]


EDGES = [edge for root in _roots().values() for edge in _scan(root, _facade_names())]
OWN = set(_roots())


def test_every_unit_has_a_layer():
    units = {_unit(e.module) for e in EDGES} - {"skelagnostic"}
    missing = sorted(units - set(LAYERS))
    assert not missing, f"place {missing} in LAYERS (tests/test_layering.py, ARCHITECTURE.md)"


def test_imports_point_downwards():
    bad, used = [], set()
    for edge in EDGES:
        src, dst = _unit(edge.module), _unit(edge.target)
        if edge.type_checking or dst not in OWN | set(LAYERS) or src == dst:
            continue
        if src == "skelagnostic" or dst == "skelagnostic":
            continue  # the lazy facade itself, or a name it defines (``__version__``)
        if LAYERS[dst] < LAYERS[src]:
            continue
        key = (edge.module, dst)
        if key in KNOWN_UPWARD:
            used.add(key)
            continue
        relation = "a sibling" if LAYERS[dst] == LAYERS[src] else "a higher layer"
        bad.append(f"{edge} ({relation})")
    assert not bad, "imports must point to a lower layer:\n" + "\n".join(bad)
    assert used == set(KNOWN_UPWARD), f"stale KNOWN_UPWARD entries: {set(KNOWN_UPWARD) - used}"


@pytest.mark.parametrize("package", LIGHT)
def test_light_packages_import_no_framework_statically(package):
    bad = [
        str(e) for e in EDGES if _unit(e.module) == package and e.target.split(".")[0] in FRAMEWORKS
    ]
    assert not bad, f"{package} must not import {', '.join(FRAMEWORKS)}:\n" + "\n".join(bad)


@pytest.mark.parametrize("framework", sorted(ONLY_IN))
def test_framework_only_in_its_layer(framework):
    allowed = ONLY_IN[framework]
    bad = [
        str(e)
        for e in EDGES
        if e.target.split(".")[0] == framework and _unit(e.module) not in allowed
    ]
    assert not bad, f"{framework} is imported outside {allowed}:\n" + "\n".join(bad)


@pytest.mark.parametrize("plugin", PLUGIN_PACKAGES)
def test_plugins_import_neither_the_cli_nor_each_other(plugin):
    forbidden = {"skelagnostic.cli", *PLUGIN_PACKAGES} - {plugin}
    bad = [str(e) for e in EDGES if _unit(e.module) == plugin and _unit(e.target) in forbidden]
    assert not bad, "\n".join(bad)


def test_the_scan_sees_every_kind_of_import(tmp_path):
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("from skelagnostic import Motion, viz\n")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "sub" / "mod.py").write_text(
        "from typing import TYPE_CHECKING\n"
        "if TYPE_CHECKING:\n    import lightning as L\n"
        "def f():\n    import hydra\n    from .. import other\n    from .sib import x\n"
    )
    found = {
        (e.module, e.target, e.type_checking)
        for e in _scan(pkg, {"Motion": "skelagnostic.core.motion"})
    }
    assert found == {
        ("pkg", "skelagnostic.core.motion", False),
        ("pkg", "skelagnostic.viz", False),
        ("pkg.sub.mod", "typing", False),
        ("pkg.sub.mod", "lightning", True),
        ("pkg.sub.mod", "hydra", False),
        ("pkg.sub.mod", "pkg", False),
        ("pkg.sub.mod", "pkg.sub.sib", False),
    }


def _floor(plugin: str, module: str) -> int | None:
    """The floor of ``module`` inside ``plugin`` (longest matching key), or None."""
    floors = PLUGIN_FLOORS[plugin]
    # the plugin's own name stands for its package ``__init__`` only, not for every module
    keys = [k for k in floors if module == k or (k != plugin and module.startswith(k + "."))]
    return floors[max(keys, key=len)] if keys else None


@pytest.mark.parametrize("plugin", sorted(PLUGIN_FLOORS))
def test_every_plugin_module_has_a_floor(plugin):
    modules = sorted({e.module for e in EDGES if e.module.split(".")[0] == plugin})
    missing = [m for m in modules if _floor(plugin, m) is None]
    assert not missing, f"place {missing} in PLUGIN_FLOORS[{plugin!r}] (tests/test_layering.py)"


@pytest.mark.parametrize("plugin", sorted(PLUGIN_FLOORS))
def test_imports_inside_a_plugin_point_down_its_floors(plugin):
    bad, used = [], set()
    for edge in EDGES:
        if edge.type_checking or edge.module.split(".")[0] != plugin:
            continue
        if edge.target.split(".")[0] != plugin:
            continue
        src, dst = _floor(plugin, edge.module), _floor(plugin, edge.target)
        if src is None or dst is None or dst <= src:
            continue
        key = (edge.module, edge.target)
        if key in KNOWN_UPWARD_IN_PLUGINS:
            used.add(key)
            continue
        bad.append(f"{edge} (floor {src} imports floor {dst})")
    assert not bad, "imports inside a plugin must point to its own or a lower floor:\n" + (
        "\n".join(bad)
    )
    stale = {k for k in KNOWN_UPWARD_IN_PLUGINS if k[0].split(".")[0] == plugin} - used
    assert not stale, f"stale KNOWN_UPWARD_IN_PLUGINS entries: {stale}"


def _import_graph(edges: list[Edge]) -> dict[str, set[str]]:
    """Module -> the modules it imports at run time (``TYPE_CHECKING`` imports left out).

    ``from package import name`` points at ``package.name`` when that is a module; an
    import of a name inside a module points at the module.
    """
    modules = {e.module for e in edges}

    def resolve(target: str) -> str:
        while target and target not in modules:
            target = target.rpartition(".")[0]
        return target

    graph: dict[str, set[str]] = {m: set() for m in modules}
    for edge in edges:
        if edge.type_checking:
            continue
        subs = [f"{edge.target}.{n}" for n in edge.names if f"{edge.target}.{n}" in modules]
        for target in subs or [edge.target]:
            found = resolve(target)
            if found and found != edge.module:
                graph[edge.module].add(found)
    return graph


def _cycles(graph: dict[str, set[str]]) -> set[frozenset[str]]:
    """The import cycles of ``graph``: its strongly connected components of two or more."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: set[frozenset[str]] = set()
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        while work:  # Tarjan's algorithm without recursion
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    work.append((child, iter(sorted(graph.get(child, ())))))
                elif child in stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = {stack.pop()}
                while node not in component:
                    component.add(stack.pop())
                if len(component) > 1:
                    found.add(frozenset(component))
    return found


def test_no_import_cycles():
    cycles = _cycles(_import_graph(EDGES))
    new = [sorted(c) for c in cycles - KNOWN_CYCLES]
    assert not new, "import cycles (module-level and function-level imports):\n" + "\n".join(
        " <-> ".join(c) for c in sorted(new)
    )
    stale = [sorted(c) for c in KNOWN_CYCLES - cycles]
    assert not stale, f"stale KNOWN_CYCLES entries (the cycle is gone: remove them): {stale}"


def test_the_cycle_check_finds_a_loop_through_a_lazy_import(tmp_path):
    pkg = tmp_path / "loop"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "model.py").write_text("def f():\n    from loop import report\n")
    (pkg / "report.py").write_text(
        "from typing import TYPE_CHECKING\nfrom loop.model import f\n"
        "if TYPE_CHECKING:\n    from loop import other\n"
    )
    (pkg / "other.py").write_text("from loop import report\n")
    edges = list(_scan(pkg, {}))
    assert _cycles(_import_graph(edges)) == {frozenset({"loop.model", "loop.report"})}


def _python(code: str) -> subprocess.CompletedProcess[str]:
    """Run ``code`` in a fresh interpreter that finds the modules this process finds."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}
    return subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        env=env,
        timeout=180,
        check=False,
    )


@pytest.mark.parametrize("package", LIGHT)
def test_light_packages_import_no_framework_at_run_time(package):
    if not (FRAMEWORK / package.split(".")[1]).is_dir():
        pytest.skip(f"{package} does not exist (yet)")
    heavy = [*FRAMEWORKS, *(["matplotlib"] if package == "skelagnostic.viz" else [])]
    code = (
        f"import sys, {package}\n"
        f"print(sorted({{m.split('.')[0] for m in sys.modules}} & {set(heavy)!r}))\n"
    )
    result = _python(code)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]", f"import {package} pulls in {result.stdout.strip()}"


@pytest.mark.parametrize(
    "plugin", ["skelagnostic_humot", "skelagnostic_pcmrl", "skelagnostic_vqpae"]
)
def test_method_packages_import_lazily(plugin):
    """``import skelagnostic_<method>`` loads no submodule (no torch) until a name is used."""
    code = (
        "import importlib, json, sys\n"
        f"package = importlib.import_module({plugin!r})\n"
        "loaded = sorted(m for m in sys.modules if m.startswith(package.__name__ + '.')\n"
        "                or m.split('.')[0] in ('torch', 'lightning'))\n"
        "names = {n: getattr(package, n).__module__ for n in package.__all__}\n"
        "print(json.dumps({'loaded': loaded, 'names': names, 'dir': dir(package)}))\n"
    )
    result = _python(code)
    assert result.returncode == 0, result.stderr
    out = json.loads(result.stdout)
    assert out["loaded"] == [], f"import {plugin} loads {out['loaded']}"
    assert out["names"], f"{plugin}.__all__ is empty"
    for name, module in out["names"].items():
        assert module.startswith(f"{plugin}."), (name, module)
        assert name in out["dir"]
