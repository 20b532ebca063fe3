"""File axes: Z-up exports of Y-up clips read back into the canonical frame, detection, errors.

A Z-up export is made here by a change of basis of a real clip (every vector and
rotation axis rotated, as Blender's exporters do) and written with the BVH and
glTF writers; reading it back with ``up="z"`` (or ``"auto"``) must give the
original clip's global positions.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

import skelagnostic as sa
from skelagnostic.core import axes
from skelagnostic.core.axes import AxesError, from_canonical, to_canonical
from skelagnostic.io import read_motion, write_motion

#: Rotation of a Y-up, +Z-facing frame into a Z-up, +Y-facing one (y -> z, z -> y, x -> -x).
Z_UP_Y_FORWARD = torch.tensor([[-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])


def _rotated_by_hand(motion: sa.Motion, r: torch.Tensor) -> sa.Motion:
    """``motion`` with the change of basis ``r`` written out independently (via matrices)."""
    from skelagnostic.core import quaternion as Q

    r = r.double()
    sk = motion.skeleton
    skeleton = sa.Skeleton(
        sk.joint_names,
        sk.parents,
        sk.offsets @ r.T,
        end_sites={
            j: (torch.tensor(v, dtype=torch.float64) @ r.T).tolist()
            for j, v in sk.end_sites.items()
        },
        name=sk.name,
        channels=sk.channels,
        body_root=sk.body_root,
    )
    mats = r @ Q.to_matrix(motion.rotations) @ r.T
    trans = None if motion.translations is None else motion.translations @ r.T
    return sa.Motion(
        skeleton,
        Q.from_matrix(mats),
        motion.root_positions @ r.T,
        motion.fps,
        translations=trans,
        name=motion.name,
    )


def _height(motion: sa.Motion) -> float:
    return motion.skeleton.height()


def _assert_same_positions(a: sa.Motion, b: sa.Motion, tol: float = 1e-5) -> None:
    err = (a.global_positions() - b.global_positions()).abs().max()
    assert float(err) <= tol * _height(b), f"max position error {float(err):.3g}"


@pytest.fixture(scope="module")
def lafan(shared_data: Path) -> sa.Motion:
    return sa.read_bvh(shared_data / "human" / "lafan1" / "Lafan1_example.bvh")[:120]


@pytest.fixture(scope="module")
def cmu(shared_data: Path) -> sa.Motion:
    return sa.read_bvh(shared_data / "human" / "cmu" / "131_01.bvh")[:120]


@pytest.fixture(scope="module")
def dog(shared_data: Path) -> sa.Motion:
    return sa.read_bvh(shared_data / "dog" / "mann" / "D1_001_KAN01_001.bvh")[:120]


@pytest.mark.parametrize("suffix", [".bvh", ".glb"])
@pytest.mark.parametrize("clip", ["lafan", "dog"])
def test_z_up_export_reads_back_to_the_original(
    clip: str, suffix: str, request: pytest.FixtureRequest, tmp_path: Path
) -> None:
    original = request.getfixturevalue(clip)
    z_up = _rotated_by_hand(original, Z_UP_Y_FORWARD)
    # the export really is Z up: the spine is above the feet along +z
    assert axes.detect_up(z_up)[0] == "z"
    path = tmp_path / f"clip{suffix}"
    write_motion(z_up, path)  # the Z-up values, as they are
    raw = read_motion(path)
    assert float((raw.global_positions() - original.global_positions()).abs().max()) > 1.0
    for up in ("z", "auto"):
        back = read_motion(path, up=up, forward="y")
        assert back.skeleton.up_axis == "y"
        _assert_same_positions(back, original)
    # the template and the height do not change with the frame
    tol = 1e-5 * _height(original)
    torch.testing.assert_close(
        back.skeleton.template(), original.skeleton.template(), atol=tol, rtol=0
    )
    assert back.skeleton.body_groups == original.skeleton.body_groups


def test_forward_auto_from_the_rest_pose(cmu: sa.Motion, tmp_path: Path) -> None:
    """CMU's rest pose faces +Z: both axes detected give back the original clip."""
    path = tmp_path / "cmu_z.bvh"
    sa.write_bvh(_rotated_by_hand(cmu, Z_UP_Y_FORWARD), path)
    back, found = to_canonical(sa.read_bvh(path), up="auto", forward="auto")
    assert (found.up, found.forward) == ("z", "y")
    assert found.detected and "detected" in found.describe()
    _assert_same_positions(back, cmu)
    _assert_same_positions(sa.read_bvh(path, up="auto", forward="auto"), cmu)


def test_lafan_rest_pose_faces_minus_x(lafan: sa.Motion) -> None:
    """LaFAN1's rest pose is not a T-pose facing +Z: auto gives what it faces, -X."""
    assert axes.detect_forward(lafan, "y")[0] == "-x"


@pytest.mark.parametrize(
    ("up", "forward"), [("z", None), ("z", "y"), ("-z", "x"), ("x", "-z"), ("-y", "z")]
)
def test_writers_convert_back(
    lafan: sa.Motion, up: str, forward: str | None, tmp_path: Path
) -> None:
    for suffix in (".bvh", ".gltf"):
        path = tmp_path / f"out{suffix}"
        write_motion(lafan, path, up=up, forward=forward)
        _assert_same_positions(read_motion(path, up=up, forward=forward), lafan)
    # the written file is in the asked frame: its own up points along `up`
    raw = sa.read_bvh(tmp_path / "out.bvh")
    assert axes.detect_up(raw)[0] == up


def test_blender_default_is_z_up_minus_y_forward(lafan: sa.Motion) -> None:
    z_up = from_canonical(lafan, up="z")
    r = axes.axes_matrix("z", "-y")
    assert axes.default_forward("z") == "-y"
    torch.testing.assert_close(
        z_up.global_positions(), lafan.global_positions() @ r.to(torch.float64)
    )


def test_gltf_records_its_axes(lafan: sa.Motion, tmp_path: Path) -> None:
    """A glTF file written with axes is read back into the canonical frame without arguments."""
    path = tmp_path / "z.glb"
    sa.write_gltf(lafan, path, up="z", forward="x")
    _assert_same_positions(sa.read_gltf(path), lafan)


def test_canonical_reads_are_untouched(lafan: sa.Motion) -> None:
    same, found = to_canonical(lafan)
    assert same is lafan and (found.up, found.forward) == ("y", "z") and not found.detected


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"up": "w"}, "up='w' is not an axis"),
        ({"forward": "up"}, "forward='up' is not an axis"),
        ({"up": "z", "forward": "-z"}, "lie on the same axis"),
        ({"up": "y", "forward": "y"}, "lie on the same axis"),
    ],
)
def test_bad_values_name_the_argument(
    lafan: sa.Motion, kwargs: dict[str, str], message: str, tmp_path: Path
) -> None:
    path = tmp_path / "a.bvh"
    sa.write_bvh(lafan, path)
    with pytest.raises(AxesError, match=message) as info:
        sa.read_bvh(path, **kwargs)
    assert str(path) in str(info.value)
    with pytest.raises(AxesError, match=message):
        sa.write_bvh(lafan, tmp_path / "b.bvh", **kwargs)
    assert not (tmp_path / "b.bvh").exists()
    with pytest.raises(AxesError, match="auto"):
        sa.write_gltf(lafan, tmp_path / "c.glb", up="auto")


def test_ambiguous_detection_explains(lafan: sa.Motion) -> None:
    """A body lying diagonally has no clear up: the error shows the direction and the fix."""
    c, s = 0.5**0.5, 0.5**0.5
    diagonal = torch.tensor([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]], dtype=torch.float64)
    tilted = _rotated_by_hand(lafan, diagonal)
    with pytest.raises(
        AxesError, match=r"up='auto': ambiguous: .* degrees from the nearest axis .* pass up="
    ):
        to_canonical(tilted, up="auto")
    rootless = sa.Skeleton(["a", "b"], [-1, 0], [[0.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    still = sa.Motion(rootless, torch.tensor([[[1.0, 0, 0, 0]] * 2]), torch.zeros(1, 3), 30)
    with pytest.raises(AxesError, match="no leg end joints"):
        axes.detect_up(still)
    with pytest.raises(AxesError, match=r"forward='auto': .* no left/right"):
        axes.detect_forward(still, "y")


def test_parse_axis_accepts_signs_and_case() -> None:
    assert [axes.parse_axis(v, "up") for v in ("+X", " -y", "z")] == ["x", "-y", "z"]
    assert axes.parse_axis("AUTO", "up", auto=True) == "auto"
    with pytest.raises(AxesError, match=r"data\.up=3"):
        axes.parse_axis(3, "data.up")
