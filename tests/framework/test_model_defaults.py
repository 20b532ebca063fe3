"""One source of truth for aligner defaults: ``conf/<name>.yaml``'s model == constructor defaults.

Every registered aligner (the built-ins and the example third-party plugin) reads its
defaults from the YAML file its plugin ships; the constructor's signature defaults must be
the same values, so that ``load_aligner(name)``, ``skelagnostic fit model=<name>`` and
``Class()`` build the same network.
"""

from __future__ import annotations

import importlib
import inspect
import sys
from collections.abc import Iterator, Mapping
from importlib.resources import files
from pathlib import Path
from typing import Any

import pytest
import torch
from omegaconf import OmegaConf

import skelagnostic.plugins as plugins_api
from skelagnostic.cli import app
from skelagnostic.plugins import PluginError, PluginManager, read_aligner_config, target_of

REPO = Path(__file__).resolve().parents[2]
PLUGINS = {  # entry-point name -> (source directory, plugin module)
    "humot": ("humot", "skelagnostic_humot.plugin"),
    "pcmrl": ("pcmrl", "skelagnostic_pcmrl.plugin"),
    "vqpae": ("vqpae", "skelagnostic_vqpae.plugin"),
    "example": ("example-aligner", "skelagnostic_example.plugin"),
}
ALIGNERS = ["example", "humot", "pcmrl", "pcmrl_interp", "vqpae"]


@pytest.fixture(scope="module")
def pm() -> Iterator[PluginManager]:
    """A plugin manager with the built-in plugins and the example plugin, from the sources."""
    added = [str(REPO / "plugins" / folder / "src") for folder, _ in PLUGINS.values()]
    sys.path[:0] = added
    try:
        manager = PluginManager(load_entrypoints=False)
        for name, (_, module) in PLUGINS.items():
            manager.register(importlib.import_module(module), name)
        yield manager
    finally:
        for path in added:
            sys.path.remove(path)


def _plain(hparams: Any) -> dict[str, Any]:
    return {k: list(v) if isinstance(v, tuple) else v for k, v in dict(hparams).items()}


def _signature_defaults(cls: type) -> dict[str, Any]:
    params = inspect.signature(cls.__init__).parameters.values()
    out = {}
    for p in params:
        if p.name == "self" or p.kind not in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY):
            continue
        assert p.default is not p.empty, f"{cls.__qualname__}({p.name}) has no default"
        out[p.name] = _yaml_like(p.default)
    return out


def _yaml_like(value: Any) -> Any:
    """``value`` as YAML holds it: mappings (``MappingProxyType`` too) as dicts, tuples as lists."""
    if isinstance(value, Mapping):
        return {k: _yaml_like(v) for k, v in value.items()}
    if isinstance(value, tuple):
        return [_yaml_like(v) for v in value]
    return value


def test_every_builtin_and_the_example_are_registered(pm: PluginManager) -> None:
    assert set(ALIGNERS) <= set(pm.aligners)


@pytest.mark.parametrize("name", ALIGNERS)
def test_config_defaults_equal_signature_defaults(pm: PluginManager, name: str) -> None:
    spec = pm.aligner(name)
    assert dict(spec.config) == _signature_defaults(spec.module)


@pytest.mark.parametrize("name", ALIGNERS)
def test_the_yaml_file_is_the_registered_config(pm: PluginManager, name: str) -> None:
    spec = pm.aligner(name)
    package = f"{spec.module.__module__.split('.')[0]}.conf"
    config = read_aligner_config(files(package) / f"{name}.yaml")["model"]
    assert config.pop("_target_") == target_of(spec.module)
    assert config == dict(spec.config)


@pytest.mark.parametrize("name", ALIGNERS)
def test_hydra_composes_the_same_defaults(pm: PluginManager, name: str, tmp_path: Path) -> None:
    cfg = app.compose([f"model={name}", f"run_dir={tmp_path}"], plugin_manager=pm)
    model = OmegaConf.to_container(cfg.model, resolve=True)
    assert model.pop("name") == name
    assert model.pop("_target_") == target_of(pm.aligner(name).module)
    assert model == dict(pm.aligner(name).config)


@pytest.mark.parametrize("name", ALIGNERS)
def test_load_aligner_builds_the_class_default_network(
    pm: PluginManager, name: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(plugins_api, "get_plugin_manager", lambda: pm)
    loaded = plugins_api.load_aligner(name)
    plain = pm.aligner(name).module()
    assert type(loaded) is type(plain)
    shapes = {k: tuple(v.shape) for k, v in loaded.state_dict().items()}
    assert shapes == {k: tuple(v.shape) for k, v in plain.state_dict().items()}
    # YAML has lists where a signature has tuples (HuMoT's betas): equal as sequences
    assert _plain(loaded.hparams) == _plain(plain.hparams)
    assert all(isinstance(v, torch.Tensor) for v in loaded.state_dict().values())


def test_missing_model_file_names_the_file() -> None:
    with pytest.raises(PluginError, match=r"conf/nope\.yaml: cannot be read"):
        read_aligner_config(files("skelagnostic.conf") / "nope.yaml")


def test_model_file_without_target_is_refused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    package = tmp_path / "cfgless_plugin_conf"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "mine.yaml").write_text("model:\n  hidden: 3\n")
    (package / "list.yaml").write_text("- 1\n- 2\n")
    (package / "flat.yaml").write_text("hidden: 3\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    conf = files("cfgless_plugin_conf")
    with pytest.raises(PluginError, match=r"conf/mine\.yaml: 'model' needs '_target_'"):
        read_aligner_config(conf / "mine.yaml")
    with pytest.raises(PluginError, match=r"list\.yaml: expected a mapping"):
        read_aligner_config(conf / "list.yaml")
    with pytest.raises(PluginError, match=r"unknown section\(s\) 'hidden'.*go under 'model'"):
        read_aligner_config(conf / "flat.yaml")


def test_a_target_naming_another_class_is_refused(pm: PluginManager) -> None:
    humot = pm.aligner("humot").module

    class Plugin:
        @plugins_api.hookimpl
        def register_aligners(self, register: Any) -> None:
            register(
                "wrong", humot, config={"model": {"_target_": "skelagnostic.aligners.Aligner"}}
            )

    other = PluginManager(load_entrypoints=False)
    other.register(Plugin(), "wrong")
    with pytest.warns(plugins_api.PluginLoadWarning, match="does not name the registered module"):
        assert "wrong" not in other.aligners


def test_a_plugin_whose_config_file_is_missing_is_reported_and_skipped(
    pm: PluginManager, tmp_path: Path
) -> None:
    humot = pm.aligner("humot").module

    class Plugin:
        @plugins_api.hookimpl
        def register_aligners(self, register: Any) -> None:
            register("gone", humot, config=tmp_path / "gone.yaml")

    other = PluginManager(load_entrypoints=False)
    other.register(Plugin(), "gone")
    with pytest.warns(plugins_api.PluginLoadWarning, match=r"gone\.yaml: cannot be read"):
        assert "gone" not in other.aligners
    assert other.plugins()[-1].status == "failed"


def test_no_model_yaml_sets_trainer_keys() -> None:
    # A model's defaults never set the trainer (issue 48, item 4): limits live in experiments.
    paths = sorted(REPO.glob("plugins/*/src/*/conf/*.yaml"))
    assert len(paths) >= len(ALIGNERS)
    for path in paths:
        text = path.read_text()
        assert "@package" not in text, f"{path}: a model section must stay in the model package"
        config = OmegaConf.load(path)
        assert "trainer" not in config.model, f"{path} sets trainer keys"
        assert "trainer_options" not in config, f"{path} sets trainer keys"


@pytest.mark.parametrize("name", ALIGNERS)
def test_a_model_alone_sets_no_trainer_limit(pm: PluginManager, name: str, tmp_path: Path) -> None:
    # `fit model=humot trainer.max_steps=20` stopped after 4 steps on the model's max_time.
    assert not dict(pm.aligner(name).trainer_options), f"{name}: trainer_options"
    trainer = app.compose([f"model={name}", f"run_dir={tmp_path}"], plugin_manager=pm).trainer
    default = OmegaConf.load(REPO / "conf" / "trainer" / "default.yaml")
    assert OmegaConf.to_container(trainer) == OmegaConf.to_container(default)


def test_plugin_experiments_are_named_after_their_method(pm: PluginManager) -> None:
    experiments = {
        info.name: [p.split(":", 1)[1] for p in info.provides if p.startswith("experiment:")]
        for info in pm.plugins()
    }
    assert experiments["skelagnostic"] == ["smoke"]  # the framework's own, for any model
    shipped = {name: names for name, names in experiments.items() if name != "skelagnostic"}
    assert all(shipped[name] for name in PLUGINS)
    wrong = [
        (plugin, n)
        for plugin, names in shipped.items()
        for n in names
        if not n.startswith(f"{plugin}_")
    ]
    assert wrong == []


def test_a_checkpoint_keeps_its_own_hyperparameters(
    pm: PluginManager, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A checkpoint trained with the former CPU defaults of PC-MRL still loads as trained."""
    import lightning as L

    monkeypatch.setattr(plugins_api, "get_plugin_manager", lambda: pm)
    optimizer = {"_target_": "torch.optim.AdamW", "_partial_": True, "lr": 1e-3, "weight_decay": 0}
    old = {"dim": 16, "temporal_dim": 128, "optimizer": optimizer, "target": "biped31"}
    trained = pm.aligner("pcmrl").module(**old)
    path = tmp_path / "old.ckpt"
    checkpoint = {
        "state_dict": trained.state_dict(),
        "hyper_parameters": dict(trained.hparams),
        "pytorch-lightning_version": L.__version__,
    }
    trained.on_save_checkpoint(checkpoint)  # what Lightning adds (PC-MRL: the target skeleton)
    torch.save(checkpoint, path)
    loaded = plugins_api.load_aligner("pcmrl", checkpoint=path)
    hp = loaded.hparams
    assert (hp.dim, hp.temporal_dim, hp.optimizer["lr"]) == (16, 128, 1e-3)
    for key, value in trained.state_dict().items():
        assert torch.equal(loaded.state_dict()[key], value)
