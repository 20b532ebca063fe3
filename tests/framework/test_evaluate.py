"""skelagnostic evaluate: protocols registered by plugins, run on a run's held-out clips."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from skelagnostic import cli
from skelagnostic.data import MotionDataModule, ProceduralSource
from skelagnostic.evaluation import Evaluation, EvaluationError, held_out, mean_rows
from skelagnostic.plugins import LOAD_PLUGINS_ENV, get_plugin_manager

FIT = [
    "model=example",
    "experiment=smoke",
    "model.hidden=8",
    "model.latent=4",
    "data.seconds=2.0",
    "data.clips_per_gait=2",
    "data.window=16",
    "data.stride=8",
    "data.test_clips_per_gait=0",  # the test split, if any, from data.test_fraction
    "threads=1",
]

# Another aligner (same network, another name) with a protocol of its own.
OTHER = '''
from skelagnostic.plugins import hookimpl
from skelagnostic_example.aligner import ExampleAligner, ExampleDataModule


class Other(ExampleAligner):
    def __init__(self, hidden=8, latent=4, lr=3e-3, depth=1):
        super().__init__(hidden, latent, lr)


def nothing(aligner, held_out, out_dir):
    """A protocol of model=other."""
    raise AssertionError("never run in these tests")


@hookimpl
def register_aligners(register):
    register("other", Other, ExampleDataModule, config={"model": {"hidden": 8, "latent": 4}})


@hookimpl
def register_evaluations(register):
    register("other.nothing", nothing, model="other", default=True)
'''


def _fit(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], *extra: str
) -> Path:
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("SKELAGNOSTIC_CACHE", str(tmp_path / "cache"))
    assert cli.main(["fit", *FIT, *extra]) == 0, capsys.readouterr().err
    capsys.readouterr()
    (run,) = (tmp_path / "runs" / "example" / "fit").iterdir()
    return run


def _evaluation_dir(tmp_path: Path) -> Path:
    (run,) = (tmp_path / "runs" / "example" / "evaluate").iterdir()
    return run


def test_evaluate_writes_the_report_on_the_test_split_or_every_held_out_clip(
    example_plugin: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    fitted = _fit(tmp_path, monkeypatch, capsys, "data.test_fraction=0.3")
    assert cli.main(["evaluate", f"ckpt_path={fitted}"]) == 0, capsys.readouterr().err
    out = capsys.readouterr().out
    run = _evaluation_dir(tmp_path)
    report = json.loads((run / "evaluation.json").read_text())
    split = json.loads((fitted / "split.json").read_text())["clips"]
    assert report["protocol"] == "example.reconstruction"  # the model's default
    assert report["model"] == "example"
    assert report["checkpoint"] == str(fitted / "checkpoints" / "best.ckpt")
    assert report["data"]["split"] == "test" and report["data"]["source"] == "procedural"
    assert report["data"]["clips"] == sorted(k for k, v in split.items() if v == "test")
    assert report["data"]["config"]["window"] == 16  # the run's data config
    methods = ["model", "mean_pose", "mean_pose_on_trajectory"]
    assert report["methods"] == [*methods, "ground_truth"]  # its own skate: a reference
    skate = {"foot_skate_cm_s", "foot_skate_ratio"}
    assert set(report["metrics"]) == {"mpjpe_cm", "mpjpe_over_height", *skate}
    assert [r["clip"] for r in report["per_clip"]] == report["data"]["clips"]
    for method in report["methods"]:
        for metric in report["metrics"]:
            values = [r["values"][method].get(metric) for r in report["per_clip"]]
            values = [v for v in values if v is not None]  # a clip may have no planted step
            if method == "ground_truth" and metric not in skate:
                assert not values
            elif values:
                assert report["mean"][method][metric] == pytest.approx(sum(values) / len(values))
    # the root-trajectory baseline is exact on the root, so it beats the static mean pose
    assert (
        report["mean"]["mean_pose_on_trajectory"]["mpjpe_cm"]
        < report["mean"]["mean_pose"]["mpjpe_cm"]
    )
    assert report["plots"] == ["evaluation.png"] and (run / "evaluation.png").stat().st_size
    markdown = (run / "evaluation.md").read_text()
    assert "# Evaluation: example.reconstruction" in markdown and "test split" in markdown
    assert "| mpjpe_cm (" in markdown
    assert "example.reconstruction on the test split" in out and "mean_pose" in out
    assert (run / "config.yaml").is_file()
    # cleanup=footlock: the foot lock measured on the model's output of every clip
    shutil.rmtree(run)
    assert cli.main(["evaluate", f"ckpt_path={fitted}", "cleanup=footlock"]) == 0, (
        capsys.readouterr().err
    )
    capsys.readouterr()
    locked = json.loads((_evaluation_dir(tmp_path) / "evaluation.json").read_text())
    assert {"footlock_mpjpe_cm", "footlock_accel_max_locked"} <= set(locked["mean"]["model"])
    assert locked["mean"]["mean_pose"] == report["mean"]["mean_pose"]  # the rest unchanged
    assert any("cleanup=footlock" in note for note in locked["notes"])
    shutil.rmtree(_evaluation_dir(tmp_path))
    assert cli.main(["evaluate", f"ckpt_path={fitted}", "cleanup=fix"]) != 0
    assert "cleanup='fix': must be one of none, footlock" in capsys.readouterr().err
    # split=heldout: the same run's validation and test clips together
    shutil.rmtree(tmp_path / "runs" / "example" / "evaluate", ignore_errors=True)
    assert cli.main(["evaluate", f"ckpt_path={fitted}", "split=heldout"]) == 0, (
        capsys.readouterr().err
    )
    report = json.loads((_evaluation_dir(tmp_path) / "evaluation.json").read_text())
    assert report["data"]["split"] == "heldout"
    assert report["data"]["split_name"] == "validation and test splits"
    expected = [k for s in ("val", "test") for k, v in sorted(split.items()) if v == s]
    assert report["data"]["clips"] == expected and len(expected) > 2
    assert "validation and test splits" in capsys.readouterr().out
    # split=train: the run's training clips, never labelled as held out
    shutil.rmtree(_evaluation_dir(tmp_path))
    assert cli.main(["evaluate", f"ckpt_path={fitted}", "split=train"]) == 0, (
        capsys.readouterr().err
    )
    run = _evaluation_dir(tmp_path)
    report = json.loads((run / "evaluation.json").read_text())
    assert report["data"]["split"] == "train"
    assert report["data"]["split_name"] == (
        "training split (clips the model trained on, not held out)"
    )
    assert report["data"]["clips"] == sorted(k for k, v in split.items() if v == "train")
    assert report["notes"][0].startswith("evaluated on the run's training clips (split=train)")
    markdown = (run / "evaluation.md").read_text()
    assert "## Mean over training clips (not held out)" in markdown
    assert "Mean over held-out clips" not in markdown
    assert "on the training split (clips the model trained on, not held out)" in (
        capsys.readouterr().out.replace("\n", " ")
    )
    assert cli.main(["evaluate", f"ckpt_path={fitted}", "split=training"]) == 1
    assert "split='training': expected one of test, val, heldout, train" in (
        capsys.readouterr().err
    )


def test_evaluate_falls_back_to_the_validation_split(
    example_plugin: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    fitted = _fit(tmp_path, monkeypatch, capsys)
    assert cli.main(["evaluate", f"ckpt_path={fitted}", "protocol=example.reconstruction"]) == 0, (
        capsys.readouterr().err
    )
    report = json.loads((_evaluation_dir(tmp_path) / "evaluation.json").read_text())
    assert report["data"]["split"] == "val"
    assert "no test split" in report["data"]["split_name"]
    assert "validation split" in capsys.readouterr().out


def test_evaluate_errors_name_the_way_out(
    example_plugin: Path,
    add_plugin,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    fitted = _fit(tmp_path, monkeypatch, capsys)
    add_plugin("other", OTHER)
    monkeypatch.setenv(LOAD_PLUGINS_ENV, "example,other")
    get_plugin_manager.cache_clear()
    cases = {
        ("protocol=example.nope",): "unknown evaluation protocol 'example.nope'; protocols of "
        "model=example: example.reconstruction",
        ("protocol=other.nothing",): "protocol 'other.nothing' evaluates model=other, not "
        "model=example",
        ("model=other",): "is a checkpoint of model=example, this is model=other",
        ("+protocol_options.steps=3",): "protocol_options: protocol 'example.reconstruction' "
        "takes no option ['steps']; its options: none",
    }
    for extra, message in cases.items():
        assert cli.main(["evaluate", f"ckpt_path={fitted}", *extra]) == 1
        err = capsys.readouterr().err
        assert message in err, err
    assert cli.main(["evaluate", "model=example"]) == 1
    assert "evaluate: give ckpt_path=" in capsys.readouterr().err
    assert not (tmp_path / "runs" / "example" / "evaluate").exists() or not any(
        (tmp_path / "runs" / "example" / "evaluate").rglob("evaluation.json")
    )


def _procedural(tmp_path: Path, clips_per_gait: int, **options: float) -> MotionDataModule:
    """biped22 clips of 2 s in a data module (16-frame windows), split by ``options``."""
    source = ProceduralSource(kinds=("biped22",), clips_per_gait=clips_per_gait, seconds=2.0)
    return MotionDataModule(source, window=16, stride=8, cache_dir=tmp_path, **options)


def test_held_out_refuses_data_without_a_held_out_split(tmp_path: Path) -> None:
    dm = _procedural(tmp_path, 1, val_fraction=0.0)
    with pytest.raises(EvaluationError, match="neither a test nor a validation split"):
        held_out(dm)


def test_held_out_loads_the_validation_clips_at_the_data_fps(tmp_path: Path) -> None:
    dm = _procedural(tmp_path, 2, fps=20.0, val_fraction=0.3)
    held = held_out(dm)
    assert held.split == "val"
    assert held.names == sorted(k for k, v in dm.assigned_splits.items() if v == "val")
    assert all(c.fps == 20.0 for c in held.clips)


def test_held_out_split_chooses_test_val_or_both(tmp_path: Path) -> None:
    dm = _procedural(tmp_path, 4, val_fraction=0.25, test_fraction=0.25)
    held = {split: held_out(dm, split) for split in (None, "test", "val", "heldout")}
    by_split = {
        s: sorted(k for k, v in dm.assigned_splits.items() if v == s) for s in ("val", "test")
    }
    assert by_split["val"] and by_split["test"]
    assert held[None].split == "test" and held[None].names == by_split["test"]
    assert held["test"].names == by_split["test"] and held["test"].name == "test split"
    assert held["val"].names == by_split["val"] and held["val"].name == "validation split"
    assert held["heldout"].names == by_split["val"] + by_split["test"]
    assert held["heldout"].name == "validation and test splits"
    assert not set(held["heldout"].names) & {
        k for k, v in dm.assigned_splits.items() if v == "train"
    }
    train = held_out(dm, "train")  # the training clips, named as such
    assert train.names == sorted(k for k, v in dm.assigned_splits.items() if v == "train")
    assert train.is_training and not held["heldout"].is_training
    assert train.name == "training split (clips the model trained on, not held out)"
    with pytest.raises(EvaluationError, match=r"split='all': expected one of test, val, heldout"):
        held_out(dm, "all")
    no_test = _procedural(tmp_path, 2, val_fraction=0.3)
    with pytest.raises(EvaluationError, match="split=test: the data has no test split"):
        held_out(no_test, "test")
    assert held_out(no_test, "heldout").names == held_out(no_test).names


def test_mean_rows_skips_missing_and_nan_values() -> None:
    rows = [
        {"clip": "a", "values": {"model": {"x": 1.0, "y": float("nan")}}},
        {"clip": "b", "values": {"model": {"x": 3.0, "y": 2.0}, "base": {"x": 5.0}}},
    ]
    assert mean_rows(rows) == {"model": {"x": 2.0, "y": 2.0}, "base": {"x": 5.0}}
    assert Evaluation({"x": ""}, rows).methods == ["model", "base"]


def test_protocols_are_listed_with_their_plugin(example_plugin: Path) -> None:
    pm = get_plugin_manager()
    spec = pm.evaluations["example.reconstruction"]
    assert (spec.model, spec.default, spec.plugin) == ("example", True, "example")
    assert spec.description.startswith("Encode-decode pose error")
    info = {i.name: i for i in pm.plugins()}["example"]
    assert "evaluation:example.reconstruction" in info.provides
    assert "register_evaluations" in info.hooks


def test_help_lists_the_protocols(example_plugin: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["evaluate", "--help"]) == 0
    out = capsys.readouterr().out
    assert "Evaluation protocols (protocol=NAME; * = the model's default):" in out
    assert "* example.reconstruction" in out and "model=example" in out
    assert "ckpt_path" in out  # Hydra's help follows


def test_evaluation_json_names_file_clips_without_the_machines_folders(tmp_path: Path) -> None:
    """Clip ids that are absolute paths lose the folders above the data (portable JSON)."""
    import skelagnostic as sa
    from skelagnostic.evaluation import HeldOut, portable_names, write_evaluation

    root = tmp_path / "somewhere" / "sets"
    ids = [str(root / "lafan1" / "walk1_subject5.bvh"), str(root / "mann_dog" / "D1_004.bvh")]
    clips = []
    for clip_id in ids:
        clip = sa.procedural.generate("biped22", "walk", seconds=0.5, fps=30, seed=1)[0]
        clip.name = clip_id
        clips.append(clip)
    rows = [
        {"clip": clip_id, "values": {"model": {"mpjpe_cm": float(i)}}}
        for i, clip_id in enumerate([*ids, "window_3"])
    ]
    extra = {"bound": {"per_clip": {ids[0]: 1.0}, "clips": [ids[1], "window_3"]}, "n": 2}
    result = Evaluation({"mpjpe_cm": "an error"}, rows, extra=extra)
    report = write_evaluation(
        result,
        tmp_path / "out",
        protocol="p",
        model="m",
        description="",
        checkpoint="last.ckpt",
        data={"source": "bvh"},
        held=HeldOut("test", clips),
    )
    names = ["lafan1/walk1_subject5.bvh", "mann_dog/D1_004.bvh"]
    assert report["data"]["clips"] == names
    assert [r["clip"] for r in report["per_clip"]] == [*names, "window_3"]
    # clip ids inside extra (keys and values) too
    assert report["extra"] == {
        "bound": {"per_clip": {names[0]: 1.0}, "clips": [names[1], "window_3"]},
        "n": 2,
    }
    written = (tmp_path / "out" / "evaluation.json").read_text()
    assert str(tmp_path) not in written
    assert str(tmp_path) not in (tmp_path / "out" / "evaluation.md").read_text()
    # one folder keeps its name; a combined source's label stays in front
    one = portable_names([ids[0], f"human:{ids[0]}"])
    assert one == {ids[0]: names[0], f"human:{ids[0]}": f"human:{names[0]}"}
