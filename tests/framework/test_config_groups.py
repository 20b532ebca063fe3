"""The top-level ``conf/`` tree: ``debug/`` presets, optional ``local/`` overrides, search paths."""

from __future__ import annotations

import warnings
from importlib import resources
from pathlib import Path

import pytest
from hydra.errors import ConfigCompositionException

from skelagnostic import cli
from skelagnostic.cli import app

REPO = Path(__file__).resolve().parents[2]
SMALL = [
    "experiment=smoke",
    "data.seconds=2.0",
    "data.clips_per_gait=1",
    "data.window=16",
    "data.stride=8",
    "model.hidden=16",
    "model.latent=4",
]


def test_the_config_package_is_the_top_level_conf_directory() -> None:
    assert not (REPO / "src" / "skelagnostic" / "conf").exists()
    conf = resources.files("skelagnostic.conf")
    assert conf.joinpath("config.yaml").is_file()
    where = Path(str(conf)).resolve()
    if where.is_relative_to(REPO.resolve()):  # editable install: the repository's conf/
        assert where == (REPO / "conf").resolve()
    names = sorted(p.name for p in conf.joinpath("debug").iterdir())
    assert names == ["fast_dev_run.yaml", "overfit.yaml", "profiler.yaml"]


@pytest.mark.parametrize(
    ("option", "expected"),
    [
        ("fast_dev_run", {"fast_dev_run": True}),
        ("overfit", {"overfit_batches": 1, "max_epochs": 100}),
        ("profiler", {"profiler": "simple", "max_epochs": 1, "limit_train_batches": 20}),
    ],
)
def test_debug_presets_set_the_trainer(example_plugin: Path, option: str, expected: dict) -> None:
    cfg = app.compose(["model=example", "run_dir=/tmp/x", f"debug={option}"])
    assert {k: cfg.trainer[k] for k in expected} == expected
    assert cfg.trainer.max_time is None and cfg.data.num_workers == 0


def test_debug_wins_over_the_experiment_and_loses_to_the_command_line(example_plugin: Path) -> None:
    cfg = app.compose(["experiment=example_quick", "debug=overfit", "run_dir=/tmp/x"])
    assert cfg.trainer.max_epochs == 100 and cfg.model.hidden == 32
    cfg = app.compose(
        ["experiment=example_quick", "debug=overfit", "trainer.max_epochs=2", "run_dir=/tmp/x"]
    )
    assert cfg.trainer.max_epochs == 2


def test_no_debug_preset_by_default(example_plugin: Path) -> None:
    cfg = app.compose(["model=example", "run_dir=/tmp/x"])
    assert cfg.trainer.overfit_batches == 0.0 and "fast_dev_run" not in cfg.trainer
    assert "profiler" not in cfg.trainer


@pytest.mark.parametrize("option", ["fast_dev_run", "overfit", "profiler"])
def test_debug_presets_run(example_plugin: Path, tmp_path: Path, option: str) -> None:
    extra = ["trainer.max_epochs=2"] if option == "overfit" else []
    cfg = app.compose(
        [
            "model=example",
            f"debug={option}",
            f"run_dir={tmp_path / 'run'}",
            f"data.cache_dir={tmp_path / 'cache'}",
            "threads=1",
            *SMALL,
            *extra,
        ]
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        metrics = app.run(cfg)
    assert "train/loss" in metrics


def _user_folder(root: Path, local: str | None) -> Path:
    folder = root / "my_conf"
    (folder / "experiment").mkdir(parents=True)
    (folder / "experiment" / "mine.yaml").write_text(
        "# @package _global_\ndefaults:\n  - override /model: example\nmodel:\n  hidden: 24\n"
    )
    if local is not None:
        (folder / "local").mkdir()
        (folder / "local" / "default.yaml").write_text(local)
    return folder


def test_a_user_config_folder_on_the_search_path(example_plugin: Path, tmp_path: Path) -> None:
    folder = _user_folder(tmp_path, None)
    cfg = app.compose([f"hydra.searchpath=[file://{folder}]", "experiment=mine", "run_dir=/tmp/x"])
    assert cfg.model.name == "example" and cfg.model.hidden == 24
    # the plugins' config paths stay on the search path next to the user's
    cfg = app.compose(
        [f"hydra.searchpath=[file://{folder}]", "experiment=example_quick", "run_dir=/tmp/x"]
    )
    assert cfg.model.hidden == 32


def test_a_model_variant_of_ones_own_extends_the_registered_aligner(
    example_plugin: Path, tmp_path: Path
) -> None:
    # docs/configuration.md: model/<new name>.yaml with ``defaults: [example, _self_]``
    (tmp_path / "model").mkdir()
    (tmp_path / "model" / "wide.yaml").write_text(
        "defaults:\n  - example\n  - _self_\nhidden: 40\n"
    )
    plain = app.compose(["model=example", "run_dir=/tmp/x"])
    cfg = app.compose([f"hydra.searchpath=[file://{tmp_path}]", "model=wide", "run_dir=/tmp/x"])
    assert cfg.model.hidden == 40 and cfg.model.latent == plain.model.latent
    # the registered aligner's name, default data and data options come along
    assert cfg.model.name == "example"
    assert cfg.data == plain.data


def test_a_file_named_like_a_registered_aligner_is_refused(
    example_plugin: Path, tmp_path: Path
) -> None:
    # the registered model/example carries the aligner's data and options in its defaults
    # list, so Hydra cannot merge a same-named file over it: the command names the file
    (tmp_path / "model").mkdir()
    (tmp_path / "model" / "example.yaml").write_text("hidden: 40\n")
    with pytest.raises(ConfigCompositionException, match="'model/example'"):
        app.compose([f"hydra.searchpath=[file://{tmp_path}]", "model=example", "run_dir=/x"])


def test_the_command_names_the_same_named_file_and_the_fix(
    example_plugin: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys
) -> None:
    (tmp_path / "model").mkdir()
    (tmp_path / "model" / "example.yaml").write_text("hidden: 40\n")
    monkeypatch.chdir(tmp_path)
    assert cli.main(["fit", "model=example", f"hydra.searchpath=[file://{tmp_path}]"]) == 1
    err = capsys.readouterr().err
    assert "model/example.yaml on the config search path is named like the registered" in err
    assert "'defaults: [example, _self_]'" in err and "Hydra 1.1" not in err
    assert not (tmp_path / "runs").exists()


def test_a_data_file_named_like_a_shipped_one_is_not_used(
    example_plugin: Path, tmp_path: Path
) -> None:
    (tmp_path / "data").mkdir()
    (tmp_path / "data" / "procedural.yaml").write_text("seconds: 123.0\n")
    search = f"hydra.searchpath=[file://{tmp_path}]"
    cfg = app.compose([search, "model=example", "data=procedural", "run_dir=/tmp/x"])
    assert cfg.data.seconds != 123.0


def test_local_default_is_applied_last_but_under_the_command_line(
    example_plugin: Path, tmp_path: Path
) -> None:
    local = "# @package _global_\nseed: 7\ntrainer:\n  max_epochs: 3\nthreads: 1\n"
    folder = _user_folder(tmp_path, local)
    search = f"hydra.searchpath=[file://{folder}]"
    cfg = app.compose([search, "experiment=mine", "run_dir=/tmp/x"])
    assert (cfg.seed, cfg.trainer.max_epochs, cfg.threads) == (7, 3, 1)
    cfg = app.compose([search, "experiment=mine", "seed=1", "run_dir=/tmp/x"])
    assert cfg.seed == 1
    cfg = app.compose([search, "experiment=mine", "~local", "run_dir=/tmp/x"])
    assert cfg.seed == 42  # ~local switches it off


def test_local_overrides_are_git_ignored() -> None:
    ignore = REPO / "conf" / "local" / ".gitignore"
    if not ignore.is_file():
        pytest.skip("not a source checkout")
    assert ignore.read_text().splitlines()[1:] == ["*", "!.gitignore"]


def test_a_config_package_without_config_yaml_is_named_with_the_fix(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from skelagnostic.cli.app import ConfigError, check_config_package

    check_config_package()  # the installed skelagnostic.conf has its config.yaml
    stale = tmp_path / "stale_pkg" / "conf"  # a namespace package: only __pycache__ left
    (stale / "__pycache__").mkdir(parents=True)
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(ConfigError, match=r"stale_pkg\.conf .*has no config\.yaml.*delete it"):
        check_config_package("stale_pkg.conf")
