"""Contributions registered by reference (``"package.module:name"``): imported on first use."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from skelagnostic.plugins import PluginError, PluginManager, hookimpl
from skelagnostic.plugins.specs import resolve_ref

REPO = Path(__file__).resolve().parents[2]


def _manager(plugin: object, name: str = "refs") -> PluginManager:
    pm = PluginManager(load_entrypoints=False)
    pm.register(plugin, name)
    return pm


def _write_module(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, name: str, text: str) -> None:
    (tmp_path / f"{name}.py").write_text(text)
    monkeypatch.syspath_prepend(str(tmp_path))


def test_a_reference_is_imported_only_when_used(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    _write_module(
        tmp_path,
        monkeypatch,
        "ref_aligner_mod",
        "from skelagnostic.aligners import Aligner\n"
        "IMPORTED = True\n"
        "class RefAligner(Aligner):\n"
        "    def __init__(self, hidden: int = 2):\n"
        "        super().__init__()\n"
        "        self.save_hyperparameters()\n"
        "    def encode(self, motion):\n"
        "        raise NotImplementedError\n"
        "    def decode(self, latent, skeleton):\n"
        "        raise NotImplementedError\n"
        "def protocol(aligner, held_out, out_dir):\n"
        "    'A protocol.'\n",
    )

    class Plugin:
        @hookimpl
        def register_aligners(self, register: Any) -> None:
            register(
                "refd",
                "ref_aligner_mod:RefAligner",
                config={"model": {"_target_": "ref_aligner_mod.RefAligner", "hidden": 2}},
            )

        @hookimpl
        def register_evaluations(self, register: Any) -> None:
            register("refd.eval", "ref_aligner_mod:protocol", model="refd", description="d")

    pm = _manager(Plugin())
    spec = pm.aligner("refd")
    assert "ref_aligner_mod" not in sys.modules  # registered, listed, not imported
    assert spec.target == "ref_aligner_mod.RefAligner" and dict(spec.config) == {"hidden": 2}
    assert spec.module.__name__ == "RefAligner" and "ref_aligner_mod" in sys.modules
    assert spec.module(hidden=3).hparams.hidden == 3
    assert pm.evaluations["refd.eval"].function.__doc__ == "A protocol."
    from skelagnostic.data import MotionDataModule

    assert spec.datamodule is MotionDataModule  # None: the framework's


@pytest.mark.parametrize(
    ("ref", "message"),
    [
        ("nosuch_mod_xyz:Thing", r"cannot load 'nosuch_mod_xyz:Thing' \(ModuleNotFoundError"),
        ("os.path:nothing_here", r"cannot load 'os.path:nothing_here' \(AttributeError"),
        ("os.path:join", r"module must be an Aligner subclass, got <function join"),
    ],
)
def test_a_bad_reference_fails_when_used_naming_plugin_and_reference(
    ref: str, message: str
) -> None:
    target = ref.replace(":", ".")

    class Plugin:
        @hookimpl
        def register_aligners(self, register: Any) -> None:
            register("bad", ref, config={"model": {"_target_": target}})

    spec = _manager(Plugin(), "badref").aligner("bad")  # registering imports nothing
    with pytest.raises(PluginError, match=message) as info:
        spec.module  # noqa: B018
    assert "aligner 'bad'" in str(info.value)


def test_malformed_or_mismatched_references_are_refused_at_registration() -> None:
    from skelagnostic.plugins import PluginLoadWarning

    class NoColon:
        @hookimpl
        def register_aligners(self, register: Any) -> None:
            register("nocolon", "ref_aligner_mod.RefAligner")

    class Mismatch:
        @hookimpl
        def register_aligners(self, register: Any) -> None:
            register("mismatch", "a.b:C", config={"model": {"_target_": "a.b.D"}})

    with pytest.warns(PluginLoadWarning, match="is neither an object nor a reference"):
        assert "nocolon" not in _manager(NoColon(), "nocolon").aligners
    with pytest.warns(PluginLoadWarning, match=r"_target_='a\.b\.D' does not name .*'a\.b\.C'"):
        assert "mismatch" not in _manager(Mismatch(), "mismatch").aligners
    with pytest.raises(PluginError, match=r"is not a reference 'package\.module:name'"):
        resolve_ref("a.b:", "aligner 'x'", "p")


#: Commands that answer without the training stack (issue 48, item 10), with a line each prints.
LIGHT_COMMANDS = {
    "plugins": "aligners (model=): humot",
    "fit --help": "== Configuration groups ==",
    "validate --help": "== Configuration groups ==",
    "test --help": "== Configuration groups ==",
    "predict --help": "== Configuration groups ==",
    "evaluate --help": "Evaluation protocols (protocol=NAME",
    "retarget --help": "usage: skelagnostic retarget",
    "interpolate --help": "usage: skelagnostic interpolate",
    "transfer --help": "usage: skelagnostic transfer",
    "export --help": "usage: skelagnostic export",
    "render --help": "usage: skelagnostic render",
}


def test_light_commands_import_no_lightning_and_no_model() -> None:
    """``plugins`` and every verb's ``--help`` (issue 48, item 10) load no Lightning, no aligner.

    The built-in plugins register by reference, and the Hydra verbs import the run
    machinery only when a job runs. The commands run one after another in one fresh
    interpreter; after each, the Lightning packages and aligner modules loaded so far
    are printed, so the first command that loads one is the one named.
    """
    paths = [str(REPO / "src"), *sorted(str(p) for p in (REPO / "plugins").glob("*/src"))]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(paths)}
    code = (
        "import json, sys\n"
        "from skelagnostic.cli import main\n"
        "for command in json.loads(sys.argv[1]):\n"
        "    sys.argv = ['skelagnostic', *command.split()]\n"
        "    try:\n"
        "        code = main()\n"
        "    except SystemExit as exc:\n"
        "        code = exc.code\n"
        "    top = {m.split('.')[0] for m in sys.modules}\n"
        "    heavy = sorted(top & {'lightning', 'pytorch_lightning', 'lightning_fabric'})\n"
        "    heavy += sorted(m for m in sys.modules if m.endswith('.aligner'))\n"
        "    print('HEAVY', json.dumps([command, code, heavy]), flush=True)\n"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code, json.dumps(list(LIGHT_COMMANDS))],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr
    reports = [json.loads(line[6:]) for line in proc.stdout.splitlines() if line[:6] == "HEAVY "]
    assert [command for command, _, _ in reports] == list(LIGHT_COMMANDS), proc.stderr
    for command, code, heavy in reports:
        assert (code, heavy) == (0, []), f"skelagnostic {command} (exit {code}) loaded {heavy}"
    for command, line in LIGHT_COMMANDS.items():
        assert line in proc.stdout, f"skelagnostic {command} did not print {line!r}"
