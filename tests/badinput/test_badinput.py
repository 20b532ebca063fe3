"""The bad-input corpus through the Python API and the ``skelagnostic`` CLI.

Every case must give one clear error line naming the culprit, a non-zero exit
code from the CLI, no traceback unless ``--debug``/``SKELAGNOSTIC_DEBUG=1``,
and no partial output: a failed run leaves no run directory behind (it only
held configs and logs) and the window cache holds only complete entries.
Each CLI error line must appear verbatim in docs/troubleshooting.md (paths
written as ``<corpus>`` and ``<tmp>``), so that page cannot drift.
"""

from __future__ import annotations

import errno
import json
import os
import stat
import subprocess
import sys
import warnings
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import torch

import skelagnostic as sa
from skelagnostic import cli
from skelagnostic.data import MotionDataModule, ProceduralSource, WindowCache
from skelagnostic.data.cache import CacheWarning
from skelagnostic.errors import BVHError, MotionError, SkelagnosticError
from skelagnostic.io.bvh import BVHWarning
from skelagnostic.metrics import MPJPE, BoneLengthConsistency

HERE = Path(__file__).resolve().parent
CORPUS = HERE / "corpus"
REPO = HERE.parents[1]
TROUBLESHOOTING = REPO / "docs" / "troubleshooting.md"
SMOKE = [
    "model=example",
    "experiment=smoke",
    "data.window=2",
    "data.stride=1",
    "model.hidden=8",
    "model.latent=4",
]

#: Malformed BVH file -> (1-based line, reason) of the BVHError.
MALFORMED = {
    "empty.bvh": (1, "the file is empty"),
    "binary_garbage.bvh": (
        1,
        "a BVH file starts with 'HIERARCHY', found 'PK\\x03\\x04\\x00\ufffd\ufffd'",
    ),
    "non_utf8_name.bvh": (
        19,
        "invalid UTF-8 at byte offset 364 (0xe9); BVH files are read as "
        "UTF-8, re-save this one in that encoding",
    ),
    "not_bvh_text.bvh": (1, "a BVH file starts with 'HIERARCHY', found '{\"not\":'"),
    "cut_in_hierarchy.bvh": (
        17,
        "unexpected end of the hierarchy, expected 'JOINT', 'End Site' or '}' in joint 'LeftUpLeg'",
    ),
    "unbalanced_braces.bvh": (
        28,
        "unexpected end of the hierarchy, expected 'JOINT', 'End Site' or '}' in joint 'Hips'",
    ),
    "duplicate_joint.bvh": (19, "duplicate joint name 'Spine'"),
    "unknown_channel.bvh": (9, "unknown channel 'Wrotation' on joint 'Spine'"),
    "no_motion_section.bvh": (29, "no MOTION section (truncated file?)"),
    "zero_frames.bvh": (31, "the file declares 0 frames; a motion needs at least one"),
    "zero_frame_time.bvh": (32, "Frame Time must be positive, got 0.0"),
    "tiny_frame_time.bvh": (
        32,
        "Frame Time 1e-320 is too small: the frame rate 1 / Frame Time is not a finite number",
    ),
    "inf_frame_time.bvh": (32, "Frame Time must be a finite number of seconds, got inf"),
    "nan_frame_time.bvh": (32, "Frame Time must be a finite number of seconds, got nan"),
    "truncated_frames.bvh": (35, "the file declares 5 frames but has 3 motion lines (truncated?)"),
    "short_row.bvh": (35, "motion line has 13 values, the hierarchy declares 15 channels"),
    "not_a_number.bvh": (34, "motion value 'x' is not a number"),
    "nan_frame.bvh": (34, "motion value 'nan' is not finite (NaN/inf)"),
    "inf_value.bvh": (34, "motion value 'inf' is not finite (NaN/inf)"),
}
HEIGHT_ZERO = {"single_joint.bvh": 1, "all_bones_zero.bvh": 4}
#: Variants of valid_small.bvh that read as the same motion.
READABLE = {
    "utf8_bom.bvh": "a UTF-8 byte order mark",
    "cr_only.bvh": "CR-only line ends",
    "cut_last_number.bvh": "no line end after the last (cut) value",
}


#: Set to a file path to collect the error lines there (to update the page) instead of checking.
COLLECT_ENV = "SKELAGNOSTIC_COLLECT_ERRORS"


def documented(line: str, tmp_path: Path) -> None:
    """Assert that ``line`` (paths normalised) is quoted in docs/troubleshooting.md."""
    text = line.replace(str(CORPUS), "<corpus>").replace(str(tmp_path), "<tmp>")
    if os.environ.get(COLLECT_ENV):
        with open(os.environ[COLLECT_ENV], "a", encoding="utf-8") as fh:
            fh.write(text + "\n")
        return
    page = TROUBLESHOOTING.read_text(encoding="utf-8")
    assert text in page, f"not in docs/troubleshooting.md:\n{text}"


def error_line(capsys: pytest.CaptureFixture[str]) -> str:
    """The one error line of a CLI failure (no traceback, no Hydra job report)."""
    err = capsys.readouterr().err
    assert "Traceback" not in err and "Error executing job" not in err, err
    lines = [line for line in err.splitlines() if line.startswith("skelagnostic fit: ")]
    assert len(lines) == 1, err
    return lines[0]


def files(root: Path) -> list[str]:
    """Files below ``root`` (none if it does not exist), relative to it."""
    return sorted(str(p.relative_to(root)) for p in root.rglob("*") if p.is_file())


def assert_no_partial_output(tmp_path: Path) -> None:
    """No run directory; cache entries complete (array and metadata, no temporary files)."""
    assert files(tmp_path / "runs") == []
    cached = files(tmp_path / "cache")
    assert not [f for f in cached if f.endswith(".tmp")]
    assert {f.removesuffix(".npy") for f in cached if f.endswith(".npy")} == {
        f.removesuffix(".json") for f in cached if f.endswith(".json")
    }


def fit(tmp_path: Path, *args: str, cache: Path | None = None) -> int:
    cache = cache or tmp_path / "cache"
    return cli.main(
        ["fit", *SMOKE, *args, f"runs_dir={tmp_path / 'runs'}", f"data.cache_dir={cache}"]
    )


# ------------------------------------------------------------------ BVH, Python API
@pytest.mark.parametrize("name", sorted(MALFORMED))
def test_read_bvh_names_file_and_line(name: str) -> None:
    line, reason = MALFORMED[name]
    with pytest.raises(BVHError) as info:
        sa.read_bvh(CORPUS / name)
    assert (info.value.path, info.value.line, info.value.reason) == (CORPUS / name, line, reason)
    assert str(info.value) == f"{CORPUS / name}:{line}: {reason}"
    assert isinstance(info.value, SkelagnosticError) and isinstance(info.value, ValueError)


def test_corpus_is_complete() -> None:
    known = {*MALFORMED, *HEIGHT_ZERO, *READABLE, "valid_small.bvh", "zero_length_bone.bvh"}
    assert {p.name for p in CORPUS.iterdir()} == known


@pytest.mark.parametrize("name", sorted(READABLE))
def test_readable_variants(name: str) -> None:
    valid = sa.read_bvh(CORPUS / "valid_small.bvh")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        motion = sa.read_bvh(CORPUS / name)
    assert motion.skeleton == valid.skeleton and motion.num_frames == valid.num_frames
    assert np.array_equal(motion.root_positions.numpy(), valid.root_positions.numpy())
    messages = [str(w.message) for w in caught]
    if name == "cut_last_number.bvh":  # read, but the cut is reported with its line
        assert [w.category for w in caught] == [BVHWarning]
        assert messages == [
            f"{CORPUS / name}:35: the last motion line has no line end, so "
            "the file may be truncated (its last value read as '1.')"
        ]
    else:
        assert messages == []
        assert torch.equal(motion.rotations, valid.rotations)


# ------------------------------------------------------------------------ BVH, CLI
@pytest.mark.parametrize("name", sorted(MALFORMED))
def test_cli_malformed_bvh(
    site: Path, tmp_path: Path, name: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert fit(tmp_path, "data=bvh", f"data.paths=[{CORPUS / name}]") == 1
    line, reason = MALFORMED[name]
    err = error_line(capsys)
    assert err == f"skelagnostic fit: error: {CORPUS / name}:{line}: {reason}"
    assert_no_partial_output(tmp_path)
    assert files(tmp_path / "cache") == []  # a clip that fails to load is not cached
    documented(err, tmp_path)


@pytest.mark.parametrize("name", sorted(HEIGHT_ZERO))
def test_cli_rejects_skeletons_of_height_zero(
    site: Path, tmp_path: Path, name: str, capsys: pytest.CaptureFixture[str]
) -> None:
    motion = sa.read_bvh(CORPUS / name)  # the core accepts them ...
    assert motion.skeleton.height() == 0
    assert fit(tmp_path, "data=bvh", f"data.paths=[{CORPUS / name}]") == 1  # ... training not
    err = error_line(capsys)
    assert err == (
        f"skelagnostic fit: error: data: clip '{CORPUS / name}' has a skeleton of "
        f"height 0 ({HEIGHT_ZERO[name]} joint(s), no bone of non-zero length); "
        "features are normalised by the skeleton height"
    )
    assert_no_partial_output(tmp_path)
    documented(err, tmp_path)


def test_zero_length_bone_is_accepted_for_training_but_not_by_bone_metrics(
    site: Path, tmp_path: Path
) -> None:
    motion = sa.read_bvh(CORPUS / "zero_length_bone.bvh")
    assert motion.skeleton.offsets.norm(dim=-1).tolist() == [0.0, 10.0, 5.0, 0.0]
    assert fit(tmp_path, "data=bvh", f"data.paths=[{CORPUS / 'zero_length_bone.bvh'}]") == 0
    (run,) = (tmp_path / "runs" / "example" / "fit").iterdir()
    assert (run / "checkpoints" / "last.ckpt").is_file()
    positions = motion.global_positions()
    with pytest.raises(MotionError, match=r"target bone \(2, 3\) has zero length"):
        BoneLengthConsistency(motion.skeleton.bones())(positions, positions)
    assert float(MPJPE()(positions, positions)) == 0.0  # positions metrics do not care


# -------------------------------------------------------------------- mismatches
def test_mismatched_skeleton_and_motion() -> None:
    small = sa.read_bvh(CORPUS / "valid_small.bvh")
    other = sa.procedural.generate(kind="biped22", gait="walk", seconds=0.2, fps=30)[0]
    page = TROUBLESHOOTING.read_text(encoding="utf-8")
    with pytest.raises(MotionError, match=r"shape \[T, 22, 4\].*got \[3, 4, 4\]") as info:
        sa.Motion(other.skeleton, small.rotations, small.root_positions, small.fps)
    assert f"MotionError: {info.value}" in page
    with pytest.raises(MotionError, match=r"joints differ: 4 vs 22") as info:
        MPJPE()(small.global_positions(), other.global_positions()[:3])
    assert f"MotionError: {info.value}" in page


# --------------------------------------------------------------------- data dirs
@pytest.mark.parametrize(
    ("case", "args", "message"),
    [
        (
            "empty dir",
            ["data=bvh", "data.paths=[{tmp}/empty]"],
            "data.paths: no file matches '**/*.bvh' in ['{tmp}/empty']",
        ),
        (
            "missing dir",
            ["data=bvh", "data.paths=[{tmp}/missing]"],
            "data.paths: '{tmp}/missing' does not exist",
        ),
        (
            "clips too short",
            ["data=bvh", f"data.paths=[{CORPUS / 'valid_small.bvh'}]", "data.window=100"],
            "data: no clip is at least data.window=100 frames long at 30 fps",
        ),
    ],
)
def test_cli_data_dirs(
    site: Path,
    tmp_path: Path,
    case: str,
    args: list[str],
    message: str,
    capsys: pytest.CaptureFixture[str],
) -> None:
    (tmp_path / "empty").mkdir()
    assert fit(tmp_path, *(a.format(tmp=tmp_path) for a in args)) == 1
    err = error_line(capsys)
    assert err == f"skelagnostic fit: error: {message.format(tmp=tmp_path)}"
    assert_no_partial_output(tmp_path)
    documented(err, tmp_path)


# ------------------------------------------------------------------- config keys
@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["model.hiden=8"],
            "Could not override 'model.hiden'. To append to your config use "
            "+model.hiden=8 (Key 'hiden' is not in struct)",
        ),
        (
            ["+model.hiden=8"],
            "model.hiden is not an option of model=example; accepted: hidden, latent, optimizer, "
            "scheduler",
        ),
        (
            ["model.hidden=big"],
            "model.hidden='big' has the wrong type for model=example (expected int)",
        ),
        (
            ["trainer.max_epochs=ten"],
            "trainer.max_epochs='ten' has the wrong type for "
            "lightning.Trainer (expected Optional[int])",
        ),
        (["+trainer.epochs=3"], "trainer.epochs is not an option of lightning.Trainer; accepted: "),
        (
            ["+data.windw=8"],
            "data.windw is not an option of data.source='procedural' nor of "
            "ExampleDataModule; accepted: ",
        ),
        (
            ["callbacks=nope"],
            "In 'config': Could not find 'callbacks/nope' Available options in "
            "'callbacks': default ema none render resumable",
        ),
        (
            ["+callbacks.model_checkpoint.every=1"],
            "callbacks.model_checkpoint.every=1: TypeError: "
            "ModelCheckpoint.__init__() got an unexpected keyword argument 'every'",
        ),
        (["ckpt_path={tmp}/none.ckpt"], "ckpt_path: no checkpoint file '{tmp}/none.ckpt'"),
        (["data.window=0"], "data.window must be > 0, got 0"),
        (
            ["data.num_workers=-1"],
            "data.num_workers must be >= 0 (0: load in the main process), got -1",
        ),
        (
            ["summary=sometimes"],
            "summary='sometimes': must be one of auto, full, quick, none",
        ),
    ],
)
def test_cli_wrong_config(
    site: Path, tmp_path: Path, args: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert fit(tmp_path, *(a.format(tmp=tmp_path) for a in args)) == 1
    err = error_line(capsys)
    assert err.startswith(f"skelagnostic fit: error: {message.format(tmp=tmp_path)}")
    assert_no_partial_output(tmp_path)
    documented(err.split("; accepted: ")[0], tmp_path)


def test_wrong_summary_is_refused_before_the_data_is_read(
    site: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch
) -> None:
    import skelagnostic.cli.tasks as tasks

    def never(*args: object, **kwargs: object) -> None:
        raise AssertionError("the data module was built before summary= was checked")

    monkeypatch.setattr(tasks, "build_datamodule", never)
    assert fit(tmp_path, "summary=full-ish") == 1
    assert "summary='full-ish': must be one of auto, full, quick, none" in error_line(capsys)


def test_failed_run_keeps_a_directory_holding_other_files(
    site: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run_dir = tmp_path / "existing"
    run_dir.mkdir()
    (run_dir / "notes.txt").write_text("mine")
    assert (
        cli.main(
            [
                "fit",
                *SMOKE,
                "data.window=0",
                f"hydra.run.dir={run_dir}",
                f"data.cache_dir={tmp_path / 'cache'}",
            ]
        )
        == 1
    )
    assert error_line(capsys) == (  # refused before anything is written (a run's own dir)
        f"skelagnostic fit: error: hydra.run.dir={str(run_dir)!r} is not empty (it holds "
        "notes.txt); a run directory belongs to one run: name a new or empty directory, or "
        "leave hydra.run.dir out (each run then gets a new one)"
    )
    assert [p.name for p in run_dir.iterdir()] == ["notes.txt"]
    assert (run_dir / "notes.txt").read_text() == "mine"


# ------------------------------------------------------------------------- cache
def test_damaged_cache_entries_are_rebuilt(tmp_path: Path) -> None:
    source = ProceduralSource(kinds=["biped17"], gaits=["walk"], clips_per_gait=1, seconds=1)
    dm = MotionDataModule(source, window=8, stride=4, cache_dir=tmp_path)
    dm.prepare_data()
    cache = WindowCache(tmp_path)
    (array,) = (tmp_path / "windows").rglob("*.npy")
    key, meta = array.stem, array.with_suffix(".json")
    good = np.load(array)
    damages = {
        "unparsable metadata": lambda: meta.write_text("{not json"),
        "truncated array": lambda: array.write_bytes(array.read_bytes()[:-100]),
        "array of another shape": lambda: np.save(array, good[:1]),
        "metadata without starts": lambda: meta.write_text(json.dumps({"clip": "x"})),
    }
    for what, damage in damages.items():
        damage()
        with pytest.warns(CacheWarning, match=f"damaged cache entry {array}"):
            assert cache.get(key) is None, what
        dm.prepare_data()  # rebuilds the entry
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            entry = cache.get(key)
        assert entry is not None and np.array_equal(entry.open(), good), what


def test_cli_unwritable_cache_dir(
    site: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    blocker = tmp_path / "cache_is_a_file"
    blocker.write_text("")
    assert fit(tmp_path, cache=blocker) == 1
    err = error_line(capsys)
    assert err.startswith(
        f"skelagnostic fit: error: data.cache_dir: cannot write the window "
        f"cache in '{blocker}/windows/"
    )
    assert err.endswith(
        "(Not a directory); set data.cache_dir or $SKELAGNOSTIC_CACHE to a writable directory"
    )
    assert files(tmp_path / "runs") == []
    documented(err.split(f"'{blocker}")[0], tmp_path)


# ------------------------------------------------------------------------ plugins
def test_cli_names_the_broken_plugin(
    broken_plugin: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert cli.main(["fit", "model=broken", f"runs_dir={tmp_path / 'runs'}"]) == 1
    err = error_line(capsys)
    assert err == (
        "skelagnostic fit: error: In 'config': Could not find 'model/broken' "
        "Available options in 'model': example [plugins that failed to load: broken "
        "(RuntimeError: boom)]"
    )
    documented(err, tmp_path)


# --------------------------------------------------------------------- subprocess
@pytest.mark.slow
def test_exit_code_and_traceback_only_when_asked(site: Path, tmp_path: Path) -> None:
    env = {
        **os.environ,
        "SKELAGNOSTIC_LOAD_PLUGINS": "example",
        "PYTHONPATH": os.pathsep.join(
            [str(site), str(REPO / "plugins" / "example-aligner" / "src"), str(REPO / "src")]
        ),
    }
    env.pop("SKELAGNOSTIC_DEBUG", None)
    nan = CORPUS / "nan_frame.bvh"
    cmd = [
        sys.executable,
        "-m",
        "skelagnostic.cli",
        "fit",
        "model=example",
        "data=bvh",
        f"data.paths=[{nan}]",
        f"runs_dir={tmp_path / 'runs'}",
        f"data.cache_dir={tmp_path / 'cache'}",
    ]
    quiet = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=120)
    assert quiet.returncode == 1
    errors = [line for line in quiet.stderr.splitlines() if "error" in line.lower()]
    assert errors == [
        f"skelagnostic fit: error: {nan}:34: motion value 'nan' is not finite (NaN/inf)"
    ]
    assert "Traceback" not in quiet.stderr
    loud = subprocess.run(
        cmd, env={**env, "SKELAGNOSTIC_DEBUG": "1"}, capture_output=True, text=True, timeout=120
    )
    assert loud.returncode != 0 and "Traceback (most recent call last)" in loud.stderr
    assert files(tmp_path / "runs") == []


# ------------------------------------------------------------------- permissions
@pytest.fixture
def umask_022() -> Iterator[None]:
    old = os.umask(0o022)
    yield
    os.umask(old)


def modes(root: Path) -> dict[str, int]:
    """Permission bits of every file and directory below ``root``."""
    return {str(p.relative_to(root)): stat.S_IMODE(p.stat().st_mode) for p in root.rglob("*")}


def test_cache_files_get_the_permissions_the_umask_allows(tmp_path: Path, umask_022: None) -> None:
    cache = WindowCache(tmp_path)
    entry = cache.put("ab" + "0" * 62, np.zeros((2, 4, 3, 2)), {"starts": [0, 4]})
    written = modes(tmp_path)
    assert written[str(entry.array.relative_to(tmp_path))] == 0o644
    assert set(written.values()) == {0o755, 0o644}


def test_full_disk_while_writing_the_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def no_space(fd: int) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "fsync", no_space)
    with pytest.raises(SkelagnosticError) as info:
        WindowCache(tmp_path).put("ab" + "0" * 62, np.zeros((2, 4, 3, 2)), {"starts": [0, 4]})
    assert str(info.value) == (
        f"data.cache_dir: cannot write the window cache in '{tmp_path}/windows/ab' (No space "
        "left on device); set data.cache_dir or $SKELAGNOSTIC_CACHE to a writable directory"
    )
    assert files(tmp_path) == []  # no temporary file, no half entry


def test_cli_fit_outputs_get_the_permissions_the_umask_allows(
    site: Path, tmp_path: Path, umask_022: None
) -> None:
    assert fit(tmp_path) == 0
    written = {**modes(tmp_path / "runs"), **modes(tmp_path / "cache")}
    assert any(name.endswith(".npy") for name in written)
    assert any(name.endswith(".ckpt") for name in written)
    wrong = {name: oct(mode) for name, mode in written.items() if mode not in {0o644, 0o755}}
    assert wrong == {}


def test_cli_demo_on_a_full_disk(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    target = out / "bvh" / "biped22_walk_0.bvh"
    target.parent.mkdir(parents=True)
    target.write_text("the old file")

    def no_space(fd: int) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "fsync", no_space)
    assert cli.main(["demo", f"out={out}", "seconds=0.2", "gif=false"]) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if line.startswith("skelagnostic demo: ")]
    assert lines == [f"skelagnostic demo: error: {target}: cannot write: No space left on device"]
    assert target.read_text() == "the old file"
    assert not [f for f in files(out) if f.endswith(".tmp")]
    documented(lines[0], tmp_path)
