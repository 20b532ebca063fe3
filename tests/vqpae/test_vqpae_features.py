"""``data.features=authors``: parity with wtd_data.py (the exporter's layout), any rig, errors.

Tolerances: 1e-4 m/s on velocities and 1e-5 m on positions. ``read_bvh`` snaps
a file's frame rate to the integer (30 fps for a Frame Time of 0.033333),
``wtd_data.py`` uses ``1 / Frame Time`` (30.0003), so velocities (``x fps``) and
the filter's sampling rate differ by 1e-5 relative (measured: 3.9e-5 m/s on the
LaFAN1 clip's 4.2 m/s peak, 1.1e-6 m on positions). The filters' edges need no
exclusion: both sides run ``scipy.signal.filtfilt`` with its default padding.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from skelagnostic_vqpae.data import VqpaeDataModule
from skelagnostic_vqpae.features import authors_features, facing_joints
from tests.script_loader import REPO, load_script

from skelagnostic import Motion, Skeleton, read_bvh
from skelagnostic.data import ProceduralSource
from skelagnostic.errors import SkelagnosticError

FIXTURE = REPO / "tests/fixtures/walkthedog/features.npz"
WTD = REPO.parent / "shared/tools/wtd_data.py"
VEL_TOL, POS_TOL = 1e-4, 1e-5


def _ours(clip: Path, mirrored: bool) -> np.ndarray:
    """Our ``[T, 6J]`` columns in wtd_data.py's order (velocities, then positions)."""
    motion = read_bvh(clip).convert_units("m", from_="cm")
    vel, pos = authors_features(motion, mirrored=mirrored)
    return torch.cat([vel.flatten(1), pos.flatten(1)], 1).numpy()


def _check(ours: np.ndarray, theirs: np.ndarray, joints: int, columns: np.ndarray) -> None:
    vel = columns < 3 * joints
    np.testing.assert_allclose(ours[:, vel], theirs[:, vel], rtol=0, atol=VEL_TOL)
    np.testing.assert_allclose(ours[:, ~vel], theirs[:, ~vel], rtol=0, atol=POS_TOL)


@pytest.mark.parametrize("key", ["human", "dog"])
def test_features_equal_the_committed_wtd_data_columns(shared_data: Path, key: str) -> None:
    fixture = np.load(FIXTURE)
    clip = shared_data / str(fixture[f"{key}/clip"])
    frames, columns = fixture[f"{key}/frames"], fixture[f"{key}/columns"]
    joints = read_bvh(clip).num_joints
    assert 0 in frames and joints * 3 in columns  # both ends, velocities and positions
    for tag in ("standard", "mirrored"):
        ours = _ours(clip, tag == "mirrored")[np.ix_(frames, columns)]
        _check(ours, fixture[f"{key}/{tag}"], joints, columns)


@pytest.mark.skipif(not WTD.is_file(), reason="../shared/tools/wtd_data.py not found")
@pytest.mark.parametrize("key", ["human", "dog"])
def test_features_equal_wtd_data_on_every_frame_and_channel(shared_data: Path, key: str) -> None:
    script = load_script("scripts/fixtures/walkthedog_features.py", "walkthedog_features")
    _, rel, topology = next(c for c in script.CLIPS if c[0] == key)
    theirs = script.wtd_columns(script.load_wtd(WTD), shared_data / rel, topology)
    for tag in ("standard", "mirrored"):
        ours = _ours(shared_data / rel, tag == "mirrored")
        assert ours.shape == theirs[tag].shape
        _check(ours, theirs[tag], ours.shape[1] // 6, np.arange(ours.shape[1]))


def _renamed(motion: Motion) -> Motion:
    """The motion on a rig named another way (``LeftUpLeg`` -> ``up_leg_l``)."""
    sk = motion.skeleton

    def rename(n: str) -> str:
        for side, suffix in (("Left", "_l"), ("Right", "_r")):
            if n.startswith(side):
                return (
                    "".join("_" + c.lower() if c.isupper() else c for c in n[len(side) :])[1:]
                    + suffix
                )
        return "body_" + n.lower()

    other = Skeleton([rename(n) for n in sk.joint_names], sk.parents, sk.offsets, name="renamed")
    return Motion(other, motion.rotations, motion.root_positions, motion.fps)


def test_features_do_not_depend_on_joint_names(lafan_clip: Path) -> None:
    motion = read_bvh(lafan_clip)[:200]
    renamed = _renamed(motion)
    assert renamed.skeleton.joint_names[1] == "up_leg_l"
    joints = facing_joints(renamed.skeleton)
    assert [renamed.skeleton.joint_names[joints[k]] for k in ("left_leg", "left_arm")] == [
        "up_leg_l",
        "shoulder_l",
    ]
    for mirrored in (False, True):
        for a, b in zip(
            authors_features(motion, mirrored), authors_features(renamed, mirrored), strict=True
        ):
            torch.testing.assert_close(a, b, rtol=0, atol=1e-9)


def test_a_quadruped_neck_without_its_name_is_found_where_the_front_legs_branch(
    shared_data: Path,
) -> None:
    motion = read_bvh(shared_data / "dog/mann/D1_010_KAN01_003.bvh")[:120]
    sk = motion.skeleton
    names = ["Withers" if "neck" in n.lower() else n for n in sk.joint_names]
    other = Skeleton(names, sk.parents, sk.offsets, name="no_neck_name")
    assert other.morphology == "quadruped" and "Neck" not in names
    assert facing_joints(other)["neck"] == facing_joints(sk)["neck"] == sk.index("Neck")
    renamed = Motion(other, motion.rotations, motion.root_positions, motion.fps)
    for a, b in zip(authors_features(motion), authors_features(renamed), strict=True):
        torch.testing.assert_close(a, b, rtol=0, atol=1e-9)


def test_a_rig_without_the_facing_joints_is_named_in_one_line() -> None:
    legs = Skeleton(
        ["Hips", "LeftUpLeg", "LeftLeg", "RightUpLeg", "RightLeg", "Spine"],
        [-1, 0, 1, 0, 3, 0],
        [[0, 90, 0], [10, 0, 0], [0, -40, 0], [-10, 0, 0], [0, -40, 0], [0, 10, 0]],
        name="legs_only",
    )
    with pytest.raises(SkelagnosticError, match=r"skeleton legs_only has no left_arm, right_arm"):
        facing_joints(legs)
    motion = Motion(legs, torch.tensor([1.0, 0, 0, 0]).repeat(20, 6, 1), torch.zeros(20, 3), 30)
    with pytest.raises(SkelagnosticError, match="legs_only") as err:
        authors_features(motion)
    assert "\n" not in str(err.value)


def test_data_module_mirrors_training_clips_and_keys_its_cache(tmp_path: Path) -> None:
    src = ProceduralSource(kinds=["biped22"], gaits=["walk"], clips_per_gait=3, seconds=2.0)
    kw = {"fps": 20, "batch_size": 4, "cache_dir": tmp_path, "val_fraction": 0.34}
    raw = VqpaeDataModule(src, **kw)
    dm = VqpaeDataModule(src, features="authors", **kw)
    assert raw.preprocessing() != dm.preprocessing()  # separate cache entries
    dm.prepare_data()
    dm.setup()
    name = dm.dataset_names[0]
    train, val = dm.clip_ids["train"][name], dm.clip_ids["val"][name]
    assert train[1::2] == [c + "/mirrored" for c in train[0::2]] and len(train) == 4
    assert not any(c.endswith("/mirrored") for c in val)
    ds = dm.datasets["train"][name]
    batch = ds.__getitems__(list(range(len(ds))))
    assert set(batch["clip"].tolist()) == {0, 1, 2, 3}
    frames = next(ds.frames())[0]  # the first clip, normalised with the fitted statistics
    motion = src.load(next(c for c in src.clips() if c.id == train[0])).resample(20)
    vel = authors_features(motion)[0].flatten(1).float()
    rep = dm.representations[name]
    expected = (vel - rep.mean.flatten()) / rep.std.flatten()
    torch.testing.assert_close(frames, expected, rtol=1e-4, atol=1e-4)
    with pytest.raises(SkelagnosticError, match=r"data\.features must be one of raw, authors"):
        VqpaeDataModule(src, features="exporter", **kw)


def test_a_model_trained_on_authors_features_encodes_motions_with_them(
    tmp_path: Path, helpers: dict
) -> None:
    from skelagnostic_vqpae.aligner import VqpaeAligner

    from skelagnostic import procedural

    src = ProceduralSource(kinds=["biped22"], gaits=["walk"], clips_per_gait=2, seconds=2.0)
    dm = VqpaeDataModule(src, fps=20, batch_size=4, cache_dir=tmp_path, features="authors")
    model = VqpaeAligner(num_codes=4, kernel_size=7, pose_mlp="none")
    helpers["trainer"](tmp_path, 2, validate=False).fit(model, datamodule=dm)
    spec = model.hparams["datasets"][dm.dataset_names[0]]
    assert spec["features"] == "authors"
    motion, _ = procedural.generate("biped22", "walk", seconds=2.0, fps=20, seed=5)
    windows, _ = model._windows(0, motion)
    char = model.characters[0]
    vel = authors_features(motion.to_metres())[0].flatten(1).float()
    expected = (vel - char.input_mean) / char.input_std
    torch.testing.assert_close(windows[:, :, windows.shape[-1] // 2], expected)
    encoder = next(g for g in model.export_graphs() if g.name.startswith("encoder_"))
    assert encoder.metadata["representation"].startswith("the WalkTheDog exporter's velocities")


def test_without_scipy_the_option_says_what_to_install(monkeypatch: pytest.MonkeyPatch) -> None:
    """scipy is not a dependency of the package: only data.features=authors needs it."""
    from skelagnostic_vqpae.features import lowpass

    monkeypatch.setitem(sys.modules, "scipy.signal", None)  # as if it were not installed
    with pytest.raises(SkelagnosticError, match=r"data\.features=authors needs scipy.*pip install"):
        lowpass(np.zeros((100, 3)), 60.0)
