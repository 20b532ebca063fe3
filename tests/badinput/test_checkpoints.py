"""Bad checkpoints: one line naming the file and the cause, never unpickled code.

Every verb that loads a checkpoint (``fit|validate|test|predict ckpt_path=``,
``retarget|interpolate|transfer ckpt=``) goes through
:func:`skelagnostic.aligners.checkpoints.read_checkpoint`. The checkpoints every
built-in aligner writes (with skelagnostic's callbacks and the resumable data
loader) must stay loadable with ``torch.load(weights_only=True)``.
"""

from __future__ import annotations

import os
import random
import shutil
import sys
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
import torch
from hydra.core.config_store import ConfigStore
from test_badinput import CORPUS, REPO, SMOKE, documented

from skelagnostic import cli
from skelagnostic.aligners.checkpoints import (
    CheckpointError,
    CheckpointNotFoundError,
    load_checkpoint,
    read_checkpoint,
)
from skelagnostic.cli import app
from skelagnostic.plugins import LOAD_PLUGINS_ENV, PluginManager, get_plugin_manager, load_aligner

PLUGIN_SRC = [
    REPO / "plugins" / name / "src" for name in ("example-aligner", "humot", "pcmrl", "vqpae")
]
TRAIN_VERBS = ("fit", "validate", "test", "predict")
INFER_VERBS = ("retarget", "interpolate", "transfer")
#: The verb whose line troubleshooting.md quotes for each option (the others say the same).
DOC_VERB = {"ckpt_path": "validate", "ckpt": "retarget"}


class Payload:
    """Pickles as a call to ``os.system``: what a malicious checkpoint carries."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self) -> tuple[object, tuple[str]]:
        return os.system, (f"touch {self.marker}",)


@contextmanager
def config_store_restored() -> Iterator[None]:
    """Forget the ``model/`` and ``data/`` configs registered inside (the store is global)."""
    repo = ConfigStore.instance().repo
    saved = {group: dict(repo[group]) for group in ("model", "data") if group in repo}
    try:
        yield
    finally:
        for group in ("model", "data"):
            if group in saved:
                repo[group].clear()
                repo[group].update(saved[group])
            else:
                repo.pop(group, None)


@pytest.fixture(scope="module")
def plugin_paths() -> None:
    for src in PLUGIN_SRC:
        if str(src) not in sys.path:
            sys.path.insert(0, str(src))


@pytest.fixture(scope="module")
def all_aligners(plugin_paths: None) -> Iterator[PluginManager]:
    """A plugin manager with the example aligner and the three built-in methods."""
    import skelagnostic_example.plugin as example
    import skelagnostic_humot.plugin as humot
    import skelagnostic_pcmrl.plugin as pcmrl
    import skelagnostic_vqpae.plugin as vqpae

    pm = PluginManager(load_entrypoints=False)
    for name, plugin in (
        ("example", example),
        ("humot", humot),
        ("pcmrl", pcmrl),
        ("vqpae", vqpae),
    ):
        pm.register(plugin, name)
    with config_store_restored():
        yield pm


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory, all_aligners: PluginManager) -> Path:
    """``last.ckpt`` of the example aligner (hidden=8) after a smoke run."""
    root = tmp_path_factory.mktemp("trained")
    app.run(
        app.compose(
            [
                *SMOKE,
                f"run_dir={root / 'run'}",
                f"data.cache_dir={root / 'cache'}",
                "trainer.max_epochs=1",
            ],
            plugin_manager=all_aligners,
        ),
        plugin_manager=all_aligners,
    )
    return root / "run" / "checkpoints" / "last.ckpt"


@pytest.fixture
def with_humot(site: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """The example plugin (fake distribution) and HuMoT (the package's entry point)."""
    monkeypatch.setenv(LOAD_PLUGINS_ENV, "example,humot")
    get_plugin_manager.cache_clear()
    with config_store_restored():
        yield


def bad_checkpoint(kind: str, good: Path, tmp_path: Path) -> Path:
    """A checkpoint file of ``kind`` in ``tmp_path`` (made from the good ``last.ckpt``)."""
    path = tmp_path / f"{kind}.ckpt"
    data = good.read_bytes()
    if kind == "empty":
        path.write_bytes(b"")
    elif kind == "truncated":
        path.write_bytes(data[: len(data) // 2])
    elif kind == "random":
        path.write_bytes(random.Random(0).randbytes(4096))
    elif kind == "payload":
        checkpoint = torch.load(good, map_location="cpu", weights_only=True)
        checkpoint["hyper_parameters"]["note"] = Payload(tmp_path / "pwned")
        torch.save(checkpoint, path)
    elif kind == "weights":  # the weights of hidden=8 under hyperparameters saying 16
        checkpoint = torch.load(good, map_location="cpu", weights_only=True)
        checkpoint["hyper_parameters"]["hidden"] = 16
        torch.save(checkpoint, path)
    elif kind == "nonfinite":  # a diverged run's weights: one value of one layer is inf
        checkpoint = torch.load(good, map_location="cpu", weights_only=True)
        checkpoint["state_dict"]["temporal.weight_hh_l0"][3, 1] = float("inf")
        torch.save(checkpoint, path)
    elif kind != "missing":
        shutil.copy(good, path)
    return path


def command(verb: str, kind: str, ckpt: Path, tmp_path: Path) -> list[str]:
    """The command line of ``verb`` loading ``ckpt`` (``kind`` picks the model options)."""
    model = ["model=humot"] if kind == "other_model" else SMOKE
    if kind == "architecture":
        model = [*SMOKE[:-2], "model.hidden=16", "model.latent=4"]
    if verb in TRAIN_VERBS:
        return [
            verb,
            *model,
            f"ckpt_path={ckpt}",
            f"runs_dir={tmp_path / 'runs'}",
            f"data.cache_dir={tmp_path / 'cache'}",
        ]
    clip = str(CORPUS / "valid_small.bvh")
    inputs = {"retarget": [clip, clip], "interpolate": [clip, "every=2"], "transfer": [clip, clip]}[
        verb
    ]
    named = ["model=humot"] if kind == "other_model" else ["model=example"]
    return [verb, *inputs, f"ckpt={ckpt}", *named, f"out={tmp_path / 'out.bvh'}"]


#: kind of checkpoint -> what the line says after "<option>: ".
CASES = {
    "missing": "no checkpoint file '{ckpt}'",
    "empty": "'{ckpt}' is empty, not a checkpoint",
    "truncated": "'{ckpt}' is not a readable checkpoint (truncated or corrupt)",
    "random": "'{ckpt}' is not a readable checkpoint (truncated or corrupt)",
    "payload": "'{ckpt}' holds a Python object (posix.system) that a safe load refuses; "
    "skelagnostic loads checkpoints with torch.load(weights_only=True), which allows "
    "tensors and plain data only",
    "other_model": "'{ckpt}' is a checkpoint of model=example, this is model=humot",
    "nonfinite": "'{ckpt}' holds non-finite weights (temporal.weight_hh_l0 has NaN or infinite "
    "values): the run that wrote it diverged; use an earlier checkpoint of that run, or train "
    "again (e.g. with a lower learning rate)",
}


@pytest.mark.parametrize(
    ("kind", "verb"),
    # a missing ckpt_path= file was already one line (test_badinput.py::test_cli_wrong_config)
    [
        (kind, verb)
        for kind in sorted(CASES)
        for verb in (*TRAIN_VERBS, *INFER_VERBS)
        if not (kind == "missing" and verb in TRAIN_VERBS)
    ],
)
def test_bad_checkpoint_is_one_line(
    with_humot: None,
    trained: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    kind: str,
    verb: str,
) -> None:
    ckpt = bad_checkpoint(kind, trained, tmp_path)
    code = cli.main(command(verb, kind, ckpt, tmp_path))
    err = capsys.readouterr().err
    assert "Traceback" not in err and "Error executing job" not in err, err
    option = "ckpt_path" if verb in TRAIN_VERBS else "ckpt"
    line = f"skelagnostic {verb}: error: {option}: {CASES[kind].format(ckpt=ckpt)}"
    assert code != 0 and line in err.splitlines(), err
    assert not (tmp_path / "pwned").exists() and not (tmp_path / "out.bvh").exists()
    assert not list((tmp_path / "runs").rglob("*.*"))
    documented(line.replace(f"skelagnostic {verb}:", f"skelagnostic {DOC_VERB[option]}:"), tmp_path)


@pytest.mark.parametrize("verb", TRAIN_VERBS)
def test_different_architecture_names_the_hyperparameters(
    site: Path, trained: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], verb: str
) -> None:
    ckpt = bad_checkpoint("copy", trained, tmp_path)
    assert cli.main(command(verb, "architecture", ckpt, tmp_path)) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    line = (
        f"skelagnostic {verb}: error: ckpt_path: '{ckpt}' is of a different architecture: "
        "model.hidden=8 in the checkpoint, 16 here"
    )
    assert line in err.splitlines(), err
    documented(line.replace(f"skelagnostic {verb}:", "skelagnostic validate:"), tmp_path)


@pytest.mark.parametrize("verb", INFER_VERBS)
def test_weights_that_do_not_fit_their_hyperparameters(
    site: Path, trained: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], verb: str
) -> None:
    ckpt = bad_checkpoint("weights", trained, tmp_path)
    assert cli.main(command(verb, "weights", ckpt, tmp_path)) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    line = (
        f"skelagnostic {verb}: error: ckpt: '{ckpt}' is of a different architecture: its "
        "weights do not fit (14 of another shape)"
    )
    assert err.splitlines() == [line]
    documented(line.replace(f"skelagnostic {verb}:", "skelagnostic retarget:"), tmp_path)


def test_payload_never_runs_even_when_torch_is_told_to_unpickle(
    site: Path,
    trained: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """``weights_only=True`` is explicit, so torch's opt-out variable cannot re-enable pickle."""
    monkeypatch.setenv("TORCH_FORCE_NO_WEIGHTS_ONLY_LOAD", "1")
    ckpt = bad_checkpoint("payload", trained, tmp_path)
    for verb in ("validate", "fit", "retarget"):
        assert cli.main(command(verb, "payload", ckpt, tmp_path)) != 0
        assert "holds a Python object (posix.system)" in capsys.readouterr().err
    with pytest.raises(CheckpointError, match=r"posix\.system"):
        load_aligner("example", ckpt)
    assert not (tmp_path / "pwned").exists()


def test_read_checkpoint_api(trained: Path, tmp_path: Path, all_aligners: PluginManager) -> None:
    with pytest.raises(FileNotFoundError, match=r"nope\.ckpt"):  # also a CheckpointError
        read_checkpoint(tmp_path / "nope.ckpt")
    with pytest.raises(CheckpointNotFoundError) as info:
        read_checkpoint(tmp_path / "nope.ckpt", option="--ckpt")
    assert str(info.value) == f"--ckpt: no checkpoint file '{tmp_path / 'nope.ckpt'}'"
    assert info.value.path == tmp_path / "nope.ckpt" and info.value.option == "--ckpt"
    torch.save({"weights": torch.zeros(2)}, tmp_path / "plain.pt")
    with pytest.raises(CheckpointError, match="not a Lightning checkpoint"):
        read_checkpoint(tmp_path / "plain.pt")
    humot = all_aligners.aligner("humot").module
    with pytest.raises(CheckpointError, match="checkpoint of model=example, this is model=humot"):
        load_checkpoint(humot, trained, aligners=all_aligners.aligner_classes())
    # without the registered aligners the writer cannot be named, but it is still refused
    with pytest.raises(CheckpointError, match="not a checkpoint of model=HumotAligner"):
        load_checkpoint(humot, trained)
    assert read_checkpoint(trained, "humot")["state_dict"]  # a name alone cannot be checked


#: Tiny training runs of every built-in aligner, with checkpoints every step.
FITS = {
    "example": [*SMOKE, "callbacks=[ema,resumable]", "callbacks.resume.every_n_train_steps=1"],
    "humot": [
        "model=humot",
        "experiment=humot_quick",
        "model.dim=32",
        "model.latent=16",
        "model.blocks=1",
        "model.heads=4",
        "data.seconds=2.0",
        "callbacks=resumable",
        "callbacks.resume.every_n_train_steps=1",
    ],
    "pcmrl": [
        "model=pcmrl",
        "data.kinds=[biped22]",
        "data.gaits=[walk]",
        "data.clips_per_gait=2",
        "data.seconds=1.5",
        "data.window=12",
        "data.stride=12",
        "data.batch_size=2",
        "data.val_fraction=0.5",
        "model.dim=8",
        "model.stages=2",
        "model.point_heads=2",
        "model.temporal_dim=16",
        "model.temporal_layers=1",
        "model.temporal_heads=2",
        "model.num_source_points=64",
        "model.num_target_points=128",
        "callbacks=resumable",
        "callbacks.resume.every_n_train_steps=1",
    ],
    "pcmrl_interp": [
        "model=pcmrl_interp",
        "model.dim=16",
        "model.heads=2",
        "model.layers=1",
        "data.samples_per_epoch=8",
        "data.batch_size=4",
        "callbacks=[ema,resumable]",
        "callbacks.resume.every_n_train_steps=1",
    ],
    "vqpae": [
        "model=vqpae",
        "experiment=smoke",
        "model.num_codes=8",
        "model.kernel_size=7",
        "data.seconds=2.0",
        "callbacks=[ema,resumable]",
        "callbacks.resume.every_n_train_steps=1",
    ],
}


@pytest.mark.parametrize("name", sorted(FITS))
def test_every_aligner_checkpoint_loads_with_weights_only(
    all_aligners: PluginManager, tmp_path: Path, name: str
) -> None:
    def common(steps: int, run_dir: Path) -> list[str]:
        return [
            "threads=1",
            "logger=none",
            "trainer.max_epochs=3",
            f"trainer.max_steps={steps}",
            "trainer.limit_train_batches=2",
            "trainer.limit_val_batches=1",
            "trainer.enable_model_summary=false",
            f"data.cache_dir={tmp_path / 'cache'}",
            f"run_dir={run_dir}",
        ]

    cfg = app.compose([*FITS[name], *common(2, tmp_path / "run")], plugin_manager=all_aligners)
    ckpt = tmp_path / "run" / "checkpoints" / "last.ckpt"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        app.run(cfg, plugin_manager=all_aligners)
        # the whole file (loops, callbacks, data module, hyperparameters) under the safe loader
        checkpoint = read_checkpoint(ckpt, name, aligners=all_aligners.aligner_classes())
        assert checkpoint["global_step"] == 2
        model = load_checkpoint(
            all_aligners.aligner(name).module, ckpt, aligners=all_aligners.aligner_classes()
        )
        assert set(model.state_dict()) == set(checkpoint["state_dict"])
        # resuming (weights_only=True) restores the loops, callbacks and data loader position
        resumed = app.compose(
            [*FITS[name], *common(3, tmp_path / "resumed"), f"ckpt_path={ckpt}"],
            plugin_manager=all_aligners,
        )
        app.run(resumed, plugin_manager=all_aligners)
    after = read_checkpoint(
        tmp_path / "resumed" / "checkpoints" / "last.ckpt",
        name,
        aligners=all_aligners.aligner_classes(),
    )
    assert after["global_step"] == 3
