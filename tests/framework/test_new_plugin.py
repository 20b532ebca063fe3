"""``skelagnostic new-plugin``: the generated package installs, trains and passes its own test."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
import venv
from pathlib import Path

import pytest
import yaml

from skelagnostic.cli import new_plugin
from skelagnostic.plugins import LOAD_PLUGINS_ENV

REPO = Path(__file__).resolve().parents[2]


def test_files_are_named_after_the_plugin() -> None:
    layout = new_plugin.files("tiny_net")
    assert set(layout) == {
        "pyproject.toml",
        "README.md",
        "constraints.txt",
        "src/skelagnostic_tiny_net/__init__.py",
        "src/skelagnostic_tiny_net/plugin.py",
        "src/skelagnostic_tiny_net/aligner.py",
        "src/skelagnostic_tiny_net/conf/__init__.py",
        "src/skelagnostic_tiny_net/conf/tiny_net.yaml",
        "src/skelagnostic_tiny_net/conf/experiment/tiny_net_quick.yaml",
        "tests/test_tiny_net.py",
    }
    assert 'tiny_net = "skelagnostic_tiny_net.plugin"' in layout["pyproject.toml"]
    assert "class TinyNetAligner(Aligner):" in layout["src/skelagnostic_tiny_net/aligner.py"]
    for text in layout.values():
        assert "__NAME__" not in text and "__PKG__" not in text and "__CLASS__" not in text
    assert (
        'distribution_version("skelagnostic-tiny_net")'
        in layout["src/skelagnostic_tiny_net/__init__.py"]
    )


def test_the_printed_install_command_keeps_the_installed_torch(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # issue 48, item 9: `pip install -e DIR` alone may pull a CUDA torch
    from importlib.metadata import version

    target = tmp_path / "pkg"
    assert new_plugin.main(["tiny", "--dir", str(target)]) == 0
    out = capsys.readouterr().out
    assert f"pip install -c {target / 'constraints.txt'} -e {target}" in out
    pins = [
        line for line in (target / "constraints.txt").read_text().splitlines() if line[:1] != "#"
    ]
    assert pins == [f"torch=={version('torch')}"]
    assert "pip install -c constraints.txt -e ." in (target / "README.md").read_text()


def test_generated_model_yaml_equals_the_generated_constructor_defaults() -> None:
    layout = new_plugin.files("tiny_net")
    config = yaml.safe_load(layout["src/skelagnostic_tiny_net/conf/tiny_net.yaml"])["model"]
    assert config.pop("_target_") == "skelagnostic_tiny_net.aligner.TinyNetAligner"
    tree = ast.parse(layout["src/skelagnostic_tiny_net/aligner.py"])
    (init,) = [
        node
        for cls in tree.body
        if isinstance(cls, ast.ClassDef) and cls.name == "TinyNetAligner"
        for node in cls.body
        if isinstance(node, ast.FunctionDef) and node.name == "__init__"
    ]
    # module constants (OPTIMIZER = MappingProxyType({...})) stand for their mapping
    constants = {
        node.targets[0].id: ast.literal_eval(node.value.args[0])
        for node in tree.body
        if isinstance(node, ast.Assign)
        and isinstance(node.value, ast.Call)
        and getattr(node.value.func, "id", None) == "MappingProxyType"
    }
    names = [a.arg for a in init.args.args[1:]]
    defaults = [
        constants[d.id] if isinstance(d, ast.Name) else ast.literal_eval(d)
        for d in init.args.defaults
    ]
    assert dict(zip(names, defaults, strict=True)) == config


@pytest.mark.parametrize("name", ["Tiny", "1net", "tiny-net", ""])
def test_bad_names_are_refused(tmp_path: Path, name: str, capsys) -> None:
    assert new_plugin.main([name, "--dir", str(tmp_path / "pkg")]) == 1
    assert f"plugin name {name!r} must be lowercase letters" in capsys.readouterr().err
    assert not (tmp_path / "pkg").exists()


def test_a_non_empty_directory_is_refused(tmp_path: Path, capsys) -> None:
    (tmp_path / "keep.txt").write_text("mine")
    assert new_plugin.main(["tiny", "--dir", str(tmp_path)]) == 1
    assert "is not an empty directory" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.txt"]


@pytest.mark.slow
def test_generated_package_installs_fits_and_passes_its_test(tmp_path: Path) -> None:
    work = tmp_path / "work"  # outside the repository
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k != LOAD_PLUGINS_ENV}
    env.update(OMP_NUM_THREADS="1", SKELAGNOSTIC_CACHE=str(tmp_path / "cache"))
    # a throwaway venv on top of this interpreter's packages (torch, lightning, ...)
    env_dir = tmp_path / "env"
    venv.create(env_dir, system_site_packages=True, with_pip=False)
    py = str(env_dir / "bin" / "python")
    purelib = subprocess.run(
        [py, "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    deps = [p for p in sys.path if p.endswith("site-packages")]
    # addsitedir (not a bare path) so that the .pth files there, e.g. the editable
    # install's finder that maps skelagnostic.conf onto the top-level conf/, run too
    Path(purelib, "deps.pth").write_text(
        "".join(f"import site; site.addsitedir({p!r})\n" for p in deps)
    )
    script = Path(sys.executable).with_name("skelagnostic")  # the installed console script
    command = [py, str(script)] if script.is_file() else [py, "-m", "skelagnostic.cli"]

    def run(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run(
            list(args), cwd=work, capture_output=True, text=True, env=env, timeout=600
        )

    made = run(*command, "new-plugin", "tiny", "--dir", str(tmp_path / "pkg"))
    assert made.returncode == 0, made.stderr
    assert f"pip install -c {tmp_path / 'pkg' / 'constraints.txt'} -e" in made.stdout
    installed = run(
        sys.executable,
        "-m",
        "pip",
        "--python",
        py,
        "install",
        "-q",
        "--no-deps",
        "--no-build-isolation",
        "--no-index",
        "-e",
        str(tmp_path / "pkg"),
    )
    assert installed.returncode == 0, installed.stderr[-2000:]
    env[LOAD_PLUGINS_ENV] = "tiny"  # only the new plugin (and the built-ins)
    fit = run(*command, "fit", "model=tiny", "experiment=smoke", "threads=1")
    assert fit.returncode == 0, fit.stderr[-2000:]
    (ckpt,) = work.glob("runs/tiny/fit/*/checkpoints/last.ckpt")
    assert ckpt.stat().st_size > 0
    listed = run(*command, "plugins", "tiny")
    assert "aligner tiny (plugin tiny 0.1.0, skelagnostic-tiny)" in listed.stdout
    version = run(py, "-c", "import skelagnostic_tiny; print(skelagnostic_tiny.__version__)")
    assert version.stdout.strip() == "0.1.0", version.stderr[-2000:]
    own = run(py, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(tmp_path / "pkg" / "tests"))
    assert own.returncode == 0, own.stdout[-3000:]
    assert "6 passed" in own.stdout  # the six contract tests
