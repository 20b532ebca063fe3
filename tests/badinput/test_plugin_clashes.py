"""Hostile plugins: names another plugin already holds, SystemExit and KeyboardInterrupt at import.

The plugin loaded first (the built-in one, then entry points by name) keeps a
name; a later plugin registering it again is skipped with one warning line
naming both, is listed as ``failed``, and the rest keeps working. A plugin
whose import raises ``SystemExit``, or a ``KeyboardInterrupt`` of its own, is
skipped and named like any broken plugin; a Ctrl-C the user presses while
plugins load still stops the command.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from skelagnostic import cli
from skelagnostic.plugins import (
    LOAD_PLUGINS_ENV,
    PluginLoadWarning,
    PluginManager,
    get_plugin_manager,
)

REPO = Path(__file__).resolve().parents[2]
TROUBLESHOOTING = REPO / "docs" / "troubleshooting.md"
SMOKE = ["experiment=smoke", "data.window=2", "data.stride=1", "model.hidden=8", "model.latent=4"]

#: A plugin registering, per kind, a name the example plugin or the built-in one holds.
CLASHING_HEADER = """
from skelagnostic.plugins import hookimpl
from skelagnostic.data import ProceduralSource
from skelagnostic.representations import GlobalPositions
from skelagnostic_example.aligner import ExampleAligner, ExampleDataModule

@hookimpl
"""
CLASHING_HOOK = {
    "aligner": "def register_aligners(register):\n"
    "    register('example', ExampleAligner, ExampleDataModule)\n",
    "evaluation": "def register_evaluations(register):\n"
    "    register('example.reconstruction', lambda *a: None, model='example')\n",
    "dataset": "def register_datasets(register):\n    register('procedural', ProceduralSource)\n",
    "representation": "def register_representations(register):\n"
    "    register('global_positions', GlobalPositions)\n",
}
READER = """
from skelagnostic.plugins import hookimpl

@hookimpl
def register_checkpoint_readers(register):
    register("{scheme}", lambda path: None, model="example")
"""


def _plugins_json(capsys: pytest.CaptureFixture[str]) -> dict[str, dict]:
    """``skelagnostic plugins --json`` in-process: rows by listed key (name, or name + source)."""
    assert cli.main(["plugins", "--json"]) == 0
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    rows = json.loads(captured.out)
    return {
        row["name"] if row["status"] != "failed" else f"{row['name']} ({row['source']})": row
        for row in rows
    }


@pytest.mark.parametrize(
    ("kind", "name", "owner"),
    [
        ("aligner", "example", "example"),
        ("evaluation", "example.reconstruction", "example"),
        ("dataset", "procedural", "skelagnostic"),
        ("representation", "global_positions", "skelagnostic"),
    ],
)
def test_a_name_held_by_another_plugin_skips_the_later_one(
    add_plugin: Callable[..., None],
    kind: str,
    name: str,
    owner: str,
    capsys: pytest.CaptureFixture[str],
) -> None:
    # "zclash" is loaded after "example" (entry points by name), the built-in one first
    add_plugin("zclash", CLASHING_HEADER + CLASHING_HOOK[kind])
    message = (
        f"PluginError: {kind} {name!r} is registered by both plugin {owner!r} and plugin "
        "'zclash' (the first one loaded keeps it)"
    )
    with pytest.warns(PluginLoadWarning) as caught:
        pm = PluginManager()
        infos = {i.name: i for i in pm.plugins()}
    assert [str(w.message) for w in caught] == [
        f"skelagnostic plugin 'zclash' (skelagnostic-zclash) skipped: {message}"
    ]
    assert infos["zclash"].status == "failed" and infos["zclash"].error == message
    assert infos["example"].status == "loaded" and "aligner:example" in infos["example"].provides
    assert pm.aligners["example"].plugin == "example"
    rows = _plugins_json(capsys)
    assert rows["zclash (skelagnostic-zclash)"]["error"] == message
    assert rows["example"]["status"] == rows["skelagnostic"]["status"] == "loaded"


def test_two_plugins_with_one_checkpoint_reader_and_fit_still_works(
    add_plugin: Callable[..., None], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    add_plugin("reader_a", READER.replace("{scheme}", "shared"))
    add_plugin("reader_b", READER.replace("{scheme}", "shared"))
    rows = _plugins_json(capsys)
    assert rows["reader_a"]["status"] == "loaded"
    assert "checkpoint reader:shared" in rows["reader_a"]["provides"]
    assert rows["reader_b (skelagnostic-reader_b)"]["error"] == (
        "PluginError: checkpoint reader 'shared' is registered by both plugin 'reader_a' and "
        "plugin 'reader_b' (the first one loaded keeps it)"
    )
    get_plugin_manager.cache_clear()
    runs = tmp_path / "runs"
    with pytest.warns(PluginLoadWarning, match="'reader_b'"):
        code = cli.main(["fit", "model=example", *SMOKE, f"runs_dir={runs}"])
    assert code == 0, capsys.readouterr().err
    assert list(runs.glob("example/fit/*/checkpoints/last.ckpt"))


def test_an_entry_point_name_two_distributions_claim(
    add_plugin: Callable[..., None], capsys: pytest.CaptureFixture[str]
) -> None:
    add_plugin("twin", READER.replace("{scheme}", "first_twin"), dist="skelagnostic-twin-a")
    add_plugin("twin", READER.replace("{scheme}", "second_twin"), dist="skelagnostic-twin-b")
    with pytest.warns(PluginLoadWarning, match="plugin name 'twin' is registered by both"):
        pm = PluginManager()
    assert set(pm.checkpoint_readers) == {"first_twin"}
    rows = _plugins_json(capsys)
    assert rows["twin"]["status"] == "loaded" and rows["twin"]["source"] == "skelagnostic-twin-a"
    assert rows["twin (skelagnostic-twin-b)"]["error"] == (
        "PluginError: plugin name 'twin' is registered by both 'skelagnostic-twin-a' and "
        "'skelagnostic-twin-b' (the first one loaded keeps it)"
    )


@pytest.mark.parametrize(
    ("statement", "error"),
    [
        ("raise SystemExit(3)", "SystemExit: 3"),
        ("import sys; sys.exit('bye')", "SystemExit: bye"),
        ("raise KeyboardInterrupt", "KeyboardInterrupt: "),
        ("class Odd(BaseException): pass\nraise Odd('odd')", "Odd: odd"),
    ],
)
def test_a_plugin_exiting_or_interrupting_at_import_is_skipped_and_named(
    add_plugin: Callable[..., None],
    statement: str,
    error: str,
    capsys: pytest.CaptureFixture[str],
) -> None:
    add_plugin("quitter", statement + "\n")
    rows = _plugins_json(capsys)
    assert rows["quitter (skelagnostic-quitter)"]["error"] == error
    assert rows["example"]["status"] == "loaded"


def test_a_plugin_exiting_at_registration_is_skipped_and_named(
    add_plugin: Callable[..., None], capsys: pytest.CaptureFixture[str]
) -> None:
    add_plugin(
        "late",
        "from skelagnostic.plugins import hookimpl\n\n"
        "@hookimpl\ndef register_datasets(register):\n    raise SystemExit(4)\n",
    )
    rows = _plugins_json(capsys)
    assert rows["late (skelagnostic-late)"]["error"] == "SystemExit: 4"


def test_the_users_ctrl_c_while_a_plugin_imports_still_stops(
    add_plugin: Callable[..., None],
) -> None:
    # the plugin's import is where the user's SIGINT lands: that is not the plugin's fault
    add_plugin(
        "slow",
        "import os, signal, time\nos.kill(os.getpid(), signal.SIGINT)\ntime.sleep(30)\n",
    )
    with pytest.raises(KeyboardInterrupt):
        PluginManager()


def test_plugins_command_lists_the_skipped_plugins_on_one_line_each(
    add_plugin: Callable[..., None], site: Path
) -> None:
    add_plugin("quitter", "raise SystemExit(3)\n")
    add_plugin("reader_a", READER.replace("{scheme}", "shared"))
    add_plugin("reader_b", READER.replace("{scheme}", "shared"))
    env = {
        "PYTHONPATH": os.pathsep.join(
            [str(site), str(REPO / "plugins" / "example-aligner" / "src"), str(REPO / "src")]
        ),
        "PATH": "/usr/bin:/bin",
        LOAD_PLUGINS_ENV: os.environ[LOAD_PLUGINS_ENV],
    }
    done = subprocess.run(
        [sys.executable, "-m", "skelagnostic.cli", "plugins"],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    lines = done.stdout.splitlines()
    assert "quitter 0.1.0 (skelagnostic-quitter) failed: SystemExit: 3" in lines
    assert (
        "reader_b 0.1.0 (skelagnostic-reader_b) failed: PluginError: checkpoint reader "
        "'shared' is registered by both plugin 'reader_a' and plugin 'reader_b' (the first "
        "one loaded keeps it)"
    ) in lines
    # a command that loads plugins names each skipped one on one warning line
    done = subprocess.run(
        [sys.executable, "-m", "skelagnostic.cli", "evaluate", "--help"],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    warned = [line for line in done.stderr.splitlines() if "warning" in line]
    assert warned == [
        "skelagnostic: warning: skelagnostic plugin 'quitter' (skelagnostic-quitter) skipped: "
        "SystemExit: 3",
        "skelagnostic: warning: skelagnostic plugin 'reader_b' (skelagnostic-reader_b) skipped: "
        "PluginError: checkpoint reader 'shared' is registered by both plugin 'reader_a' and "
        "plugin 'reader_b' (the first one loaded keeps it)",
    ], done.stderr
    for line in warned:
        assert line in TROUBLESHOOTING.read_text(encoding="utf-8")


def test_a_misspelt_name_in_load_plugins_is_named(
    site: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(LOAD_PLUGINS_ENV, "exmaple")
    with pytest.warns(PluginLoadWarning) as caught:
        PluginManager()
    (message,) = [str(w.message) for w in caught if "exmaple" in str(w.message)]
    start = "SKELAGNOSTIC_LOAD_PLUGINS names 'exmaple', which no installed plugin is; installed: "
    assert message.startswith(start) and "example" in message
    assert f"skelagnostic: warning: {start}" in TROUBLESHOOTING.read_text(encoding="utf-8")
