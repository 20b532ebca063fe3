"""Plugin manager: hook registration, collisions, broken plugins, env filtering, docs coverage."""

from __future__ import annotations

import inspect
import json
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

import skelagnostic.plugins as plugins
from skelagnostic.aligners import Aligner, CapabilityError
from skelagnostic.plugins import (
    PluginError,
    PluginLoadWarning,
    PluginManager,
    hookimpl,
    hookspecs,
)

REPO = Path(__file__).resolve().parents[2]
EXAMPLE_SRC = REPO / "plugins" / "example-aligner" / "src"
HOOKS = [
    name
    for name, f in inspect.getmembers(hookspecs, inspect.isfunction)
    if name.startswith("register_")
]

REGISTERING_PLUGIN = """
from skelagnostic.plugins import hookimpl
from skelagnostic.representations import GlobalPositions
from skelagnostic.data import ProceduralSource

class Mine(GlobalPositions):
    name = "mine"

@hookimpl
def register_representations(register):
    register("mine", Mine)

@hookimpl
def register_datasets(register):
    register("tiny", ProceduralSource, "one-kind procedural data")

@hookimpl
def register_config_paths(register):
    register("file:///nonexistent/conf")
"""


def test_hookspecs_are_the_documented_six() -> None:
    assert sorted(HOOKS) == [
        "register_aligners",
        "register_checkpoint_readers",
        "register_config_paths",
        "register_datasets",
        "register_evaluations",
        "register_representations",
    ]


@pytest.mark.parametrize("hook", HOOKS)
def test_every_hook_is_documented(hook: str) -> None:
    assert hook in (REPO / "docs" / "plugins.md").read_text()


def test_builtin_registers_through_hooks() -> None:
    pm = PluginManager(load_entrypoints=False)
    (info,) = pm.plugins()
    assert (info.name, info.source, info.status) == ("skelagnostic", "built-in", "loaded")
    assert set(info.hooks) == {"register_representations", "register_datasets"}
    assert {
        "global_positions",
        "root_local_velocities",
        "local_quaternions",
        "local_rot6d",
        "local_axis_angle",
        "foq",
        "point_cloud",
    } == set(pm.representations)
    assert {"procedural", "bvh", "lafan1", "cmu", "mann_dog", "bandai"} == set(pm.datasets)
    assert pm.aligners == {}


def test_entry_point_plugin_registers_everything(add_plugin) -> None:
    add_plugin("good", REGISTERING_PLUGIN)
    pm = PluginManager()
    info = {i.name: i for i in pm.plugins()}["good"]
    assert (info.version, info.source, info.status) == ("1.2.3", "fake-good", "loaded")
    assert pm.representation("mine").plugin == "good"
    assert pm.dataset("tiny").description == "one-kind procedural data"
    # other installed plugins (e.g. the example package) may add their own paths
    assert "file:///nonexistent/conf" in pm.config_paths
    assert "representation:mine" in info.provides


def test_example_aligner_is_listed_and_loadable(example_plugin) -> None:
    assert plugins.list_aligners() == ["example"]
    spec = plugins.get_plugin_manager().aligner("example")
    assert spec.plugin == "example" and spec.config["hidden"] == 64
    model = plugins.load_aligner("example", hidden=8)
    assert isinstance(model, Aligner) and not model.training
    assert model.hparams.hidden == 8


def test_unknown_names_list_the_known_ones(example_plugin) -> None:
    pm = plugins.get_plugin_manager()
    with pytest.raises(PluginError, match="unknown aligner 'nope'; registered: example"):
        pm.aligner("nope")
    with pytest.raises(PluginError, match="unknown dataset 'x'"):
        pm.dataset("x")
    with pytest.raises(FileNotFoundError, match=r"missing\.ckpt"):
        plugins.load_aligner("example", checkpoint="missing.ckpt")


def test_name_collision_between_plugins_skips_the_second(add_plugin) -> None:
    add_plugin("first", REGISTERING_PLUGIN)
    add_plugin("second", REGISTERING_PLUGIN)
    pm = PluginManager()
    with pytest.warns(
        PluginLoadWarning,
        match="'second' .* representation 'mine' is registered by both plugin 'first' and "
        "plugin 'second'",
    ):
        representations = pm.representations
    assert representations["mine"].plugin == "first"
    infos = {i.name: i for i in pm.plugins()}
    assert infos["first"].status == "loaded" and infos["second"].status == "failed"


def test_collision_with_a_builtin_skips_the_plugin() -> None:
    class Clash:
        @hookimpl
        def register_datasets(self, register):
            register("procedural", lambda: None)

    pm = PluginManager(load_entrypoints=False)
    pm.register(Clash(), "clash")
    with pytest.warns(
        PluginLoadWarning,
        match="dataset 'procedural' is registered by both plugin 'skelagnostic' and plugin 'clash'",
    ):
        datasets = pm.datasets
    assert datasets["procedural"].plugin == "skelagnostic"


def test_duplicate_plugin_name_raises() -> None:
    pm = PluginManager(load_entrypoints=False)
    with pytest.raises(PluginError, match="plugin name 'skelagnostic' is registered twice"):
        pm.register(object(), "skelagnostic")


def test_unknown_hook_is_rejected() -> None:
    class Typo:
        @hookimpl
        def register_aligner(self, register):  # missing "s"
            pass

    with pytest.raises(PluginError, match="register_aligner"):
        PluginManager(load_entrypoints=False).register(Typo(), "typo")


def test_a_distribution_without_a_summary_loads(add_plugin, monkeypatch) -> None:
    """importlib_metadata's metadata raises KeyError for a missing key (the stdlib's gives None).

    wandb and mlflow install that backport; a plugin distribution without a
    ``Summary`` line then broke every plugin listing.
    """
    from importlib import metadata

    add_plugin("nosummary", REGISTERING_PLUGIN)
    real = metadata.entry_points

    class StrictMetadata:
        def __init__(self, inner):
            self.inner = inner

        def __getitem__(self, key):
            value = self.inner[key]
            if value is None:
                raise KeyError(key)
            return value

        def get(self, key, default=None):
            return self.inner.get(key, default)

    class StrictDist:
        def __init__(self, dist):
            self._dist = dist
            self.metadata = StrictMetadata(dist.metadata)

        def __getattr__(self, name):
            return getattr(self._dist, name)

    class StrictEntryPoint:
        def __init__(self, ep):
            self._ep, self.dist = ep, StrictDist(ep.dist)

        def __getattr__(self, name):
            return getattr(self._ep, name)

    monkeypatch.setattr(
        metadata,
        "entry_points",
        lambda **kw: [StrictEntryPoint(ep) for ep in real(**kw)],
    )
    infos = {i.name: i for i in PluginManager().plugins()}
    assert infos["nosummary"].status == "loaded"


def test_plugin_failing_at_import_is_skipped_with_warning(add_plugin) -> None:
    add_plugin("broken", "raise RuntimeError('boom at import')\n")
    add_plugin("good", REGISTERING_PLUGIN)
    with pytest.warns(PluginLoadWarning, match="'broken'.*RuntimeError: boom at import"):
        pm = PluginManager()
    infos = {i.name: i for i in pm.plugins()}
    assert infos["broken"].status == "failed"
    assert infos["broken"].error == "RuntimeError: boom at import"
    assert infos["good"].status == "loaded" and "mine" in pm.representations


def test_plugin_failing_at_registration_is_skipped(add_plugin) -> None:
    add_plugin(
        "badreg",
        """
from skelagnostic.plugins import hookimpl

@hookimpl
def register_aligners(register):
    register("notanaligner", object)
""",
    )
    pm = PluginManager()
    with pytest.warns(PluginLoadWarning, match="module must be an Aligner subclass"):
        infos = {i.name: i for i in pm.plugins()}
    assert infos["badreg"].status == "failed"
    assert "notanaligner" not in pm.aligners


def test_load_plugins_env_restricts(add_plugin, monkeypatch: pytest.MonkeyPatch) -> None:
    add_plugin("broken", "raise RuntimeError('boom')\n")
    add_plugin("good", REGISTERING_PLUGIN)
    monkeypatch.setenv(plugins.LOAD_PLUGINS_ENV, "good")
    pm = PluginManager()
    status = {i.name: i.status for i in pm.plugins()}
    # plugins installed in the environment besides these (e.g. the example) are disabled too
    assert {k: status[k] for k in ("skelagnostic", "broken", "good")} == {
        "skelagnostic": "loaded",
        "broken": "disabled",
        "good": "loaded",
    }
    assert all(v == "disabled" for k, v in status.items() if k not in {"skelagnostic", "good"})
    monkeypatch.setenv(plugins.LOAD_PLUGINS_ENV, "")
    assert "mine" not in PluginManager().representations


def test_capabilities_are_enforced(example_plugin) -> None:
    model = plugins.load_aligner("example", hidden=8)
    assert model.supports("retarget") and not model.supports("phase")
    with pytest.raises(CapabilityError, match="does not support 'phase'"):
        model.require("phase")


def test_plugins_command_lists_broken_plugin(add_plugin, fake_site: Path) -> None:
    add_plugin("broken", "raise ImportError('no such thing')\n")
    env_path = [str(fake_site), str(REPO / "src")]
    out = subprocess.run(
        [sys.executable, "-m", "skelagnostic.cli", "plugins", "--json"],
        capture_output=True,
        text=True,
        check=True,
        env={"PYTHONPATH": ":".join(env_path), "PATH": "/usr/bin:/bin"},
    )
    rows = {row["name"]: row for row in json.loads(out.stdout)}
    assert rows["broken"]["status"] == "failed"
    assert rows["broken"]["version"] == "1.2.3"
    assert rows["broken"]["source"] == "fake-broken"
    assert rows["broken"]["error"] == "ImportError: no such thing"
    assert rows["skelagnostic"]["status"] == "loaded"


def test_plugin_without_hookimpl_is_reported(add_plugin) -> None:
    add_plugin("nohooks", "def register_aligners(register):\n    pass\n")
    with pytest.warns(
        PluginLoadWarning,
        match="register_aligners is not decorated with "
        r"@skelagnostic\.plugins\.hookimpl",
    ):
        pm = PluginManager()
    info = {i.name: i for i in pm.plugins()}["nohooks"]
    assert info.status == "failed" and "fake_plugin_nohooks" in info.error


def test_plugin_with_misspelt_undecorated_hook_is_reported(add_plugin) -> None:
    add_plugin("typo", "def register_aligner(register):\n    pass\n")
    with pytest.warns(
        PluginLoadWarning,
        match=r"implements no skelagnostic hook \(misspelt "
        r"hook\? register_aligner\)",
    ):
        pm = PluginManager()
    assert {i.name: i for i in pm.plugins()}["typo"].status == "failed"


def test_plugin_with_another_projects_marker_is_reported(add_plugin) -> None:
    add_plugin(
        "foreign",
        "import pluggy\nimpl = pluggy.HookimplMarker('other')\n"
        "@impl\ndef register_aligners(register):\n    pass\n",
    )
    with pytest.warns(PluginLoadWarning, match="another project's HookimplMarker"):
        PluginManager()


def test_fit_error_names_the_plugin_without_hookimpl(
    example_plugin: Path, add_plugin, fake_site: Path, tmp_path: Path
) -> None:
    add_plugin("mlp", "def register_aligners(register):\n    pass\n")
    out = subprocess.run(
        [sys.executable, "-m", "skelagnostic.cli", "fit", "model=mlp"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env={
            "PYTHONPATH": f"{fake_site}:{EXAMPLE_SRC}:{REPO / 'src'}",
            "PATH": "/usr/bin:/bin",
            plugins.LOAD_PLUGINS_ENV: "mlp,example",
            "OMP_NUM_THREADS": "1",
        },
    )
    assert out.returncode == 1
    line = out.stderr.strip().splitlines()[-1]
    assert "Could not find 'model/mlp'" in line
    assert "mlp (PluginError: plugin 'mlp': fake_plugin_mlp: register_aligners is not " in line


def _conf_plugin(site: Path, name: str, url: str, init: bool, write_dist) -> None:
    pkg = site / f"confplug_{name}"
    (pkg / "conf" / "experiment").mkdir(parents=True)
    (pkg / "__init__.py").write_text(
        "from skelagnostic.plugins import hookimpl\n\n@hookimpl\n"
        f"def register_config_paths(register):\n    register({url!r})\n"
    )
    if init:
        (pkg / "conf" / "__init__.py").write_text("")
    (pkg / "conf" / "experiment" / f"{name}_seed.yaml").write_text(
        "# @package _global_\nseed: 1234\n"
    )
    write_dist(site, f"confplug-{name}", "0.1.0", {name: f"confplug_{name}"})


@pytest.mark.parametrize("init", [True, False])
def test_conf_package_with_or_without_init_is_found(
    example_plugin: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, init: bool, dist_writer
) -> None:
    from skelagnostic.cli.app import compose

    name = "withinit" if init else "noinit"  # distinct modules: sys.modules keeps the first
    _conf_plugin(example_plugin, name, f"pkg://confplug_{name}.conf", init, dist_writer)
    monkeypatch.setenv(plugins.LOAD_PLUGINS_ENV, f"example,{name}")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        cfg = compose(["model=example", f"experiment={name}_seed", f"run_dir={tmp_path}"])
    assert cfg.seed == 1234
    # Hydra's pkg:// source wants an __init__.py and warns "... is not available" without one
    assert not [w for w in caught if "not available" in str(w.message)]


def test_missing_conf_package_is_named(example_plugin: Path, monkeypatch, dist_writer) -> None:
    _conf_plugin(example_plugin, "nope", "pkg://confplug_nope.configs", True, dist_writer)
    monkeypatch.setenv(plugins.LOAD_PLUGINS_ENV, "example,nope")
    with pytest.warns(
        PluginLoadWarning,
        match="config path 'pkg://confplug_nope.configs': "
        "'confplug_nope.configs' is not importable",
    ):
        infos = {i.name: i for i in plugins.get_plugin_manager().plugins()}
    assert infos["nope"].status == "failed"


def test_plugins_command_shows_description_version_and_contents(
    subprocess_env, tmp_path: Path
) -> None:
    def plugins_cli(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run(
            [sys.executable, "-m", "skelagnostic.cli", "plugins", *args],
            capture_output=True,
            text=True,
            cwd=tmp_path,
            env=subprocess_env,
        )

    text = plugins_cli().stdout
    assert "example 0.1.0 (skelagnostic-example-aligner) loaded" in text
    assert "Example third-party aligner: a per-joint GRU autoencoder" in text
    assert "aligners (model=): example" in text
    assert "experiments (experiment=): example_quick" in text
    assert "experiments (experiment=): smoke" in text  # the built-in plugin's
    assert "data presets (data=): bandai, bvh, cmu, lafan1, mann_dog, procedural" in text
    rows = {row["name"]: row for row in json.loads(plugins_cli("--json").stdout)}
    assert rows["example"]["description"].startswith("Example third-party aligner")
    assert "experiment:example_quick" in rows["example"]["provides"]


def test_plugins_name_shows_capabilities_and_defaults(example_plugin, capsys) -> None:
    from skelagnostic.cli.plugins import main

    assert main(["example"]) == 0
    out = capsys.readouterr().out
    assert "aligner example (plugin example 0.1.0, skelagnostic-example-aligner)" in out
    for line in (
        "retarget: yes",
        "interpolate: no",
        "transfer: no",
        "unseen topology: yes",
        "declared: decode, encode, quadruped, retarget, unseen_topology",
        "  hidden: 64",
        "  latent: 16",
        "  lr: 0.003",
    ):
        assert line in out
    assert main(["example", "--json"]) == 0
    details = json.loads(capsys.readouterr().out)
    assert details["config"] == {
        "hidden": 64,
        "latent": 16,
        "optimizer": {"_target_": "torch.optim.Adam", "_partial_": True, "lr": 3e-3},
        "scheduler": None,
    }
    assert details["capabilities"] == {
        "retarget": True,
        "interpolate": False,
        "transfer": False,
        "unseen_topology": True,
    }
    assert details["module"] == "skelagnostic_example.aligner.ExampleAligner"


def test_plugins_name_unknown_lists_the_known_ones(example_plugin, capsys) -> None:
    from skelagnostic.cli.plugins import main

    assert main(["nope"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(
        "skelagnostic plugins: 'nope' is neither an aligner nor a plugin; "
        "aligners: example; plugins: skelagnostic, example"
    )


def test_plugin_with_one_undecorated_hook_among_decorated_ones_is_reported(add_plugin) -> None:
    add_plugin(
        "half",
        "from skelagnostic.plugins import hookimpl\n\n"
        "@hookimpl\ndef register_datasets(register):\n    pass\n\n"
        "def register_config_paths(register):\n    register('pkg://x.conf')\n",
    )
    with pytest.warns(
        PluginLoadWarning, match="fake_plugin_half: register_config_paths is not decorated"
    ):
        pm = PluginManager()
    assert {i.name: i for i in pm.plugins()}["half"].status == "failed"
