"""A run's life through the CLI: fit, then validate/test/predict from its checkpoint alone."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest
import torch
import yaml

from skelagnostic import cli
from skelagnostic.data import MotionDataModule
from skelagnostic.data.sources import ClipRef
from skelagnostic.errors import SkelagnosticError

TROUBLESHOOTING = Path(__file__).resolve().parents[2] / "docs" / "troubleshooting.md"
FIT = [
    "model=example",
    "experiment=smoke",
    "model.hidden=8",
    "model.latent=4",
    "data.seconds=2.0",
    "data.clips_per_gait=2",
    "data.window=16",
    "data.stride=8",
    "threads=1",
]


@pytest.fixture
def fitted(
    example_plugin: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> Path:
    """A finished smoke fit of the example aligner (non-default sizes); its run directory."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("SKELAGNOSTIC_CACHE", str(tmp_path / "cache"))
    assert cli.main(["fit", *FIT]) == 0, capsys.readouterr().err
    capsys.readouterr()
    (run,) = (tmp_path / "runs" / "example" / "fit").iterdir()
    return run


def later_run(tmp_path: Path, verb: str) -> Path:
    (run,) = (tmp_path / "runs" / "example" / verb).iterdir()
    return run


def test_fit_records_its_split_and_prints_a_summary(
    example_plugin: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("SKELAGNOSTIC_CACHE", str(tmp_path / "cache"))
    assert cli.main(["fit", *FIT]) == 0
    out, err = capsys.readouterr()
    (run,) = (tmp_path / "runs" / "example" / "fit").iterdir()
    split = json.loads((run / "split.json").read_text())
    assert split["counts"]["train"] > 0 and split["counts"]["val"] > 0
    assert set(split["clips"].values()) <= {"train", "val", "test"}
    assert "run directory" in out and str(run) in out
    assert str(run / "checkpoints" / "best.ckpt") in out
    assert str(run / "checkpoints" / "last.ckpt") in out and "val/loss" in out
    for noise in ("litlogger", "LeafSpec", "dirpath has changed", "ambiguous collection"):
        assert noise not in err + out


@pytest.mark.parametrize("verb", ["validate", "test", "predict"])
def test_later_verbs_need_only_the_checkpoint(
    verb: str, fitted: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    extra = ["data.test_fraction=0.3"] if verb == "test" else []
    code = cli.main([verb, f"ckpt_path={fitted / 'checkpoints' / 'last.ckpt'}", *extra])
    out, err = capsys.readouterr()
    assert code == 0, err
    config = yaml.safe_load((later_run(tmp_path, verb) / "config.yaml").read_text())
    assert config["model"]["hidden"] == 8 and config["data"]["window"] == 16  # the run's
    assert "evaluated checkpoint" in out


def test_a_checkpoint_deeper_in_the_checkpoints_folder_finds_its_run(
    fitted: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # a second ModelCheckpoint (e.g. every N steps) writing to checkpoints/periodic/
    periodic = fitted / "checkpoints" / "periodic"
    periodic.mkdir()
    (periodic / "step2.ckpt").write_bytes((fitted / "checkpoints" / "last.ckpt").read_bytes())
    assert cli.main(["validate", f"ckpt_path={periodic / 'step2.ckpt'}"]) == 0, (
        capsys.readouterr().err
    )
    config = yaml.safe_load((later_run(tmp_path, "validate") / "config.yaml").read_text())
    assert config["model"]["hidden"] == 8 and config["data"]["window"] == 16  # the run's
    # outside a run's checkpoints folder nothing is guessed
    loose = tmp_path / "elsewhere" / "deeper" / "model.ckpt"
    loose.parent.mkdir(parents=True)
    loose.write_bytes(b"")
    assert cli.runs.find_run_dir(loose) is None


def test_explicit_overrides_still_win(
    fitted: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert cli.main(["validate", f"ckpt_path={fitted}", "data.batch_size=3"]) == 0
    config = yaml.safe_load((later_run(tmp_path, "validate") / "config.yaml").read_text())
    assert config["data"]["batch_size"] == 3 and config["data"]["window"] == 16
    assert config["ckpt_path"] == str(fitted)  # a run directory stands for its best.ckpt
    assert str(fitted / "checkpoints" / "best.ckpt") in capsys.readouterr().out


def test_a_run_directory_stands_for_the_checkpoint_its_run_chose(
    fitted: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    last = fitted / "checkpoints" / "last.ckpt"
    best = fitted / "checkpoints" / "best.ckpt"
    # the command line chooses
    assert cli.main(["validate", f"ckpt_path={fitted}", "run_checkpoint=last"]) == 0
    (row,) = [line for line in capsys.readouterr().out.splitlines() if "evaluated" in line]
    assert str(last) in row
    # the run's checkpoints folder stands for the run too: its config and split are reused
    assert cli.runs.find_run_dir(fitted / "checkpoints") == fitted
    assert cli.main(["validate", f"ckpt_path={fitted / 'checkpoints'}"]) == 0
    assert str(best) in capsys.readouterr().out
    newest = max((tmp_path / "runs" / "example" / "validate").iterdir())
    reused = yaml.safe_load((newest / "config.yaml").read_text())
    assert reused["model"]["hidden"] == 8 and reused["data"]["window"] == 16
    # else the run's config (a preset whose last step is its model writes last)
    config = fitted / "config.yaml"
    saved = yaml.safe_load(config.read_text())
    assert saved["run_checkpoint"] is None  # the fit's own: best
    assert cli.runs.checkpoint_of(fitted) == best
    config.write_text(yaml.safe_dump({**saved, "run_checkpoint": "last"}))
    assert cli.runs.checkpoint_of(fitted) == last
    assert cli.runs.checkpoint_of(fitted / "checkpoints") == last
    assert cli.runs.checkpoint_of(fitted, "best") == best
    # a missing preferred file falls back to the other one
    moved = best.rename(tmp_path / "best.ckpt")
    assert cli.runs.checkpoint_of(fitted, "best") == last
    moved.rename(best)
    # a wrong value names where it came from
    config.write_text(config.read_text().replace("run_checkpoint: last", "run_checkpoint: top"))
    with pytest.raises(SkelagnosticError, match=r"config.yaml: run_checkpoint .*'top'"):
        cli.runs.checkpoint_of(fitted)
    assert cli.main(["validate", f"ckpt_path={fitted}", "run_checkpoint=first"]) == 1
    assert "run_checkpoint must be 'best' or 'last', got 'first'" in capsys.readouterr().err


def test_a_resumed_fit_continues_from_the_last_checkpoint() -> None:
    from omegaconf import OmegaConf

    from skelagnostic.cli.tasks import _preferred_checkpoint

    def chosen(**cfg: object) -> str | None:
        return _preferred_checkpoint(OmegaConf.create({"run_checkpoint": None, **cfg}))

    assert chosen(task="fit") == "last"
    assert chosen(task="evaluate") is None  # the run's own choice, else best
    assert chosen(task="fit", run_checkpoint="best") == "best"
    assert chosen(task="test", run_checkpoint="last") == "last"


def test_a_default_fit_has_a_test_split(fitted: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # issue 48, item 6: `test ckpt_path=<run>` after a default fit always failed
    split = json.loads((fitted / "split.json").read_text())
    assert split["counts"]["test"] > 0 and split["counts"]["val"] > 0
    tested = {k for k, v in split["clips"].items() if v == "test"}
    assert not tested & {k for k, v in split["clips"].items() if v != "test"}
    assert cli.main(["test", f"ckpt_path={fitted}"]) == 0, capsys.readouterr().err
    assert "test/loss" in capsys.readouterr().out


def test_test_on_a_run_without_a_test_split_says_what_to_do(
    example_plugin: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("SKELAGNOSTIC_CACHE", str(tmp_path / "cache"))
    assert cli.main(["fit", *FIT, "data.test_clips_per_gait=0"]) == 0, capsys.readouterr().err
    (run,) = (tmp_path / "runs" / "example" / "fit").iterdir()
    capsys.readouterr()
    # a test split asked for later used to be the run's validation clips: test == validate
    for extra in ([], ["data.test_fraction=0.2"]):
        assert cli.main(["test", f"ckpt_path={run / 'checkpoints' / 'best.ckpt'}", *extra]) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and f"the run {run} has no test split" in err[0]
        assert "use validate, or fit again with data.test_fraction=0.2" in err[0]
        assert err[0].replace(str(run), "<run>") in TROUBLESHOOTING.read_text()
    # without a run to keep, an empty test split says how to get one
    best = tmp_path / "loose.ckpt"
    best.write_bytes((run / "checkpoints" / "best.ckpt").read_bytes())
    args = ["test", *FIT, "data.test_clips_per_gait=0", f"ckpt_path={best}"]
    assert cli.main(args) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "the test split is empty" in err[0]
    assert err[0] in TROUBLESHOOTING.read_text()


def test_a_later_test_fraction_never_takes_training_or_validation_clips() -> None:
    clips = [ClipRef(f"clip{i}", f"k{i}") for i in range(10)]
    dm = MotionDataModule(val_fraction=0.2, test_fraction=0.0, split_seed=3)
    recorded = {c.id: part for part, members in dm.split_clips(clips).items() for c in members}
    new = [ClipRef(f"new{i}", f"n{i}") for i in range(5)]  # clips the run never saw
    for fraction in (0.1, 0.3, 0.6):
        later = MotionDataModule(val_fraction=0.2, test_fraction=fraction, split_seed=3)
        later.recorded_splits = recorded
        split = later.split_clips(clips)
        # every recorded clip keeps its split: no test clip (the validation clips chose
        # the checkpoint, so testing on them would repeat validate)
        assert {c.id: part for part, members in split.items() for c in members} == recorded
        assert not split["test"]
        # without the record, the same fraction would have tested on training clips
        fresh = MotionDataModule(val_fraction=0.2, test_fraction=fraction, split_seed=3)
        fresh_test = {c.id for c in fresh.split_clips(clips)["test"]}
        if fraction >= 0.3:
            assert fresh_test & {k for k, v in recorded.items() if v == "train"}
        # clips the run never saw can be test clips
        later = MotionDataModule(val_fraction=0.2, test_fraction=fraction, split_seed=3)
        later.recorded_splits = recorded
        tested = {c.id for c in later.split_clips([*clips, *new])["test"]}
        assert tested <= {c.id for c in new}


def test_max_steps_is_not_capped_by_max_epochs(
    example_plugin: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("SKELAGNOSTIC_CACHE", str(tmp_path / "cache"))
    # smoke: 2 epochs of at most 4 batches; 11 steps need a third epoch
    assert cli.main(["fit", *FIT, "trainer.max_steps=11"]) == 0
    (run,) = (tmp_path / "runs" / "example" / "fit").iterdir()
    state = torch.load(run / "checkpoints" / "last.ckpt", map_location="cpu", weights_only=False)
    assert state["global_step"] == 11
    with open(run / "csv" / "metrics.csv") as fh:
        logged = [row for row in csv.DictReader(fh) if row.get("train/loss")]
    assert len(logged) >= 5  # at least every other step on an 11-step run


def test_short_epochs_log_the_training_loss(
    example_plugin: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("SKELAGNOSTIC_CACHE", str(tmp_path / "cache"))
    assert cli.main(["fit", *FIT, "trainer.log_every_n_steps=50"]) == 0
    (run,) = (tmp_path / "runs" / "example" / "fit").iterdir()
    with open(run / "csv" / "metrics.csv") as fh:
        logged = [row for row in csv.DictReader(fh) if row.get("train/loss")]
    assert len(logged) >= 2  # 8 steps: one per epoch at least, not none


@pytest.mark.parametrize("content", ["model: [unclosed", "seed: 1\n"])
def test_a_broken_run_config_is_one_line(
    fitted: Path, content: str, capsys: pytest.CaptureFixture[str]
) -> None:
    (fitted / "config.yaml").write_text(content)
    assert cli.main(["validate", f"ckpt_path={fitted / 'checkpoints' / 'last.ckpt'}"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not the config.yaml of a skelagnostic run" in err[0], err
