"""A static root that carries the trajectory (Bandai-Namco, MotionBuilder exports).

The procedural generator writes the same walk in the ordinary layout (the hips are
the root) and with a static ``joint_Root`` above the hips, whose OFFSET is where
the hips stood in the last frame. Everything derived from the rest geometry must
be the ordinary export's, and forward kinematics must stay exact.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

import skelagnostic as sa
from skelagnostic.core.units import infer_units
from skelagnostic.errors import SkeletonError

LAYOUTS = {
    "plain": {},
    "all6": {"channels": "all6"},
    "carrier": {"root_carrier": "static"},
    "carrier_all6": {"root_carrier": "static", "channels": "all6"},
}


def _walk(**layout: str) -> sa.Motion:
    return sa.procedural.generate("biped22", "walk", seconds=5.0, fps=30, seed=0, **layout)[0]


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The same 5 s walk written in every layout."""
    root = tmp_path_factory.mktemp("carrier")
    paths = {}
    for name, layout in LAYOUTS.items():
        paths[name] = root / f"{name}.bvh"
        sa.write_bvh(_walk(**layout), paths[name])
    return paths


def _body(motion: sa.Motion) -> slice:
    """The joints of the body (after the carrier, if any)."""
    return slice(motion.skeleton.body_root, None)


def test_generator_writes_the_carrier_layout(files: dict[str, Path]) -> None:
    text = files["carrier"].read_text()
    head = text.split("MOTION")[0].split()
    assert head[:3] == ["HIERARCHY", "ROOT", "joint_Root"]
    hips = head.index("Hips")
    assert head[hips + 2] == "OFFSET"
    hips_offset = [float(v) for v in head[hips + 3 : hips + 6]]
    last = _walk().root_positions[-1].tolist()
    assert hips_offset == pytest.approx(last, abs=1e-5)  # where the hips are in the last frame
    assert hips_offset[2] > 400.0  # 5 s of walking along +Z
    six = "CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation"
    assert text.count(six) == 2
    assert files["carrier_all6"].read_text().count(six) == 23
    assert files["all6"].read_text().count(six) == 22


@pytest.mark.parametrize("name", list(LAYOUTS))
def test_forward_kinematics_equals_the_ordinary_export(files: dict[str, Path], name: str) -> None:
    plain = sa.read_bvh(files["plain"])
    motion = sa.read_bvh(files[name])
    torch.testing.assert_close(
        motion.global_positions()[:, _body(motion)], plain.global_positions(), atol=1e-5, rtol=0
    )
    generated = _walk(**LAYOUTS[name])
    torch.testing.assert_close(
        generated.global_positions()[:, _body(generated)],
        _walk().global_positions(),
        atol=1e-9,
        rtol=0,
    )


@pytest.mark.parametrize("name", list(LAYOUTS))
def test_rest_geometry_is_the_ordinary_exports(files: dict[str, Path], name: str) -> None:
    plain = sa.read_bvh(files["plain"]).skeleton
    sk = sa.read_bvh(files[name]).skeleton
    body = sk.body_root
    assert body == (1 if "carrier" in name else 0)
    assert sk.carrier_joints() == list(range(body))
    assert sk.height() == pytest.approx(plain.height(), rel=1e-6)
    assert infer_units(sk) == infer_units(plain) == "cm"
    torch.testing.assert_close(sk.bone_lengths()[body:], plain.bone_lengths())
    assert float(sk.bone_lengths()[:body].abs().sum()) == 0.0
    rest = sk.rest_positions()
    torch.testing.assert_close(
        rest[body:] - rest[body], plain.rest_positions() - plain.rest_positions()[0]
    )
    template = sk.template()
    torch.testing.assert_close(template[body:] - template[body], plain.template())
    assert sk.body_groups[body:] == plain.body_groups


def test_unit_guess_before_the_rule_was_the_distance_walked(files: dict[str, Path]) -> None:
    """Without the rule (the file's OFFSETs as bones) the hips stand on a 5.7 m pole."""
    sk = sa.read_bvh(files["carrier"]).skeleton
    naive = sa.Skeleton(sk.joint_names, sk.parents, sk.offsets, morphology=sk.morphology)
    assert naive.body_root == 0
    assert float(naive.bone_lengths()[1]) > 500.0
    assert naive.height() > 3 * sk.height()  # the pole (5.8 m) follows the rest direction
    assert infer_units(naive) != "cm"


def test_translations_repeating_offsets_are_dropped(files: dict[str, Path]) -> None:
    assert sa.read_bvh(files["all6"]).translations is None
    carrier = sa.read_bvh(files["carrier_all6"])
    assert carrier.translations is not None  # the hips carry the trajectory
    assert sa.read_bvh(files["plain"]).translations is None


def test_animated_translations_do_not_change_bone_lengths(files: dict[str, Path]) -> None:
    """Six channels whose values differ from the OFFSETs: FK follows them, bones do not."""
    motion = sa.read_bvh(files["all6"])
    sk = motion.skeleton
    trans = sk.offsets.expand(motion.num_frames, -1, -1).clone()
    knee = sk.index("LeftLeg")
    trans[:, knee] *= 1.0 + 0.2 * torch.linspace(0, 1, motion.num_frames)[:, None]
    stretched = sa.Motion(sk, motion.rotations, motion.root_positions, motion.fps, trans)
    moved = stretched.global_positions() - motion.global_positions()
    assert float(moved[-1, knee].norm()) > 5.0
    assert float(sk.bone_lengths()[knee]) == pytest.approx(float(sk.offsets[knee].norm()))


@pytest.mark.parametrize("name", ["carrier", "carrier_all6"])
def test_heading_and_velocities_follow_the_body_root(files: dict[str, Path], name: str) -> None:
    plain = sa.read_bvh(files["plain"])
    motion = sa.read_bvh(files[name])
    torch.testing.assert_close(motion.facing(), plain.facing(), atol=1e-6, rtol=0)
    torch.testing.assert_close(
        motion.root_local_velocities()[:, 1:], plain.root_local_velocities(), atol=1e-4, rtol=0
    )


@pytest.mark.parametrize("name", ["carrier", "carrier_all6"])
def test_root_relative_positions_follow_the_body_root(files: dict[str, Path], name: str) -> None:
    from skelagnostic.representations import GlobalPositions

    plain = GlobalPositions(frame="root").encode(sa.read_bvh(files["plain"]))
    carrier = GlobalPositions(frame="root").encode(sa.read_bvh(files[name]))
    torch.testing.assert_close(carrier[:, 1:], plain, atol=1e-5, rtol=0)


@pytest.mark.parametrize("name", ["carrier", "carrier_all6"])
def test_reroot_at_the_body_root_gives_the_ordinary_motion(
    files: dict[str, Path], name: str
) -> None:
    plain = sa.read_bvh(files["plain"])
    motion = sa.read_bvh(files[name])
    body = sa.reroot(motion, motion.skeleton.body_root)
    assert body.skeleton.joint_names == plain.skeleton.joint_names
    assert body.skeleton.body_root == 0 and body.translations is None
    torch.testing.assert_close(body.skeleton.offsets[1:], plain.skeleton.offsets[1:])
    torch.testing.assert_close(body.global_positions(), plain.global_positions(), atol=1e-5, rtol=0)
    torch.testing.assert_close(body.root_positions, plain.root_positions, atol=1e-5, rtol=0)
    sub = motion.skeleton.rooted_at("Hips")
    assert sub.joint_names == plain.skeleton.joint_names and sub.body_root == 0


def test_write_read_keeps_the_carrier(files: dict[str, Path], tmp_path: Path) -> None:
    motion = sa.read_bvh(files["carrier"])
    out = tmp_path / "again.bvh"
    sa.write_bvh(motion, out)
    back = sa.read_bvh(out)
    assert back.skeleton.body_root == 1
    assert back.skeleton.offsets.tolist() == motion.skeleton.offsets.tolist()
    torch.testing.assert_close(
        back.global_positions(), motion.global_positions(), atol=1e-5, rtol=0
    )


def test_moving_root_or_several_children_is_no_carrier(tmp_path: Path) -> None:
    motion = _walk(root_carrier="static")
    sk = motion.skeleton
    # the root moves: an ordinary file whose root happens to have one child
    moved = sa.Motion(
        sa.Skeleton(sk.joint_names, sk.parents, sk.offsets, channels=sk.channels),
        motion.rotations,
        torch.linspace(0, 1, motion.num_frames)[:, None].expand(-1, 3),
        motion.fps,
        motion.translations,
    )
    sa.write_bvh(moved, tmp_path / "moving.bvh")
    assert sa.read_bvh(tmp_path / "moving.bvh").skeleton.body_root == 0
    # the hips have no position channels: their OFFSET is a bone
    channels = [list(c) for c in sk.channels]
    channels[1] = channels[1][3:]
    still = sa.Motion(
        sa.Skeleton(sk.joint_names, sk.parents, sk.offsets, channels=channels),
        motion.rotations,
        motion.root_positions,
        motion.fps,
    )
    sa.write_bvh(still, tmp_path / "still.bvh")
    assert sa.read_bvh(tmp_path / "still.bvh").skeleton.body_root == 0


def test_body_root_survives_serialisation_and_edits() -> None:
    sk = _walk(root_carrier="static").skeleton
    assert sa.Skeleton.from_dict(sk.to_dict()).body_root == 1
    assert sk.scaled(0.01).body_root == 1
    assert sk.scaled(0.01).height() == pytest.approx(sk.height() * 0.01)
    assert sk.subset(["joint_Root", "Hips", "Spine", "Head"]).body_root == 1
    assert sk.subset(["joint_Root", "Spine", "Head"]).body_root == 0
    with pytest.raises(SkeletonError, match="body_root: unknown joint 'Pelvis'"):
        sa.Skeleton(sk.joint_names, sk.parents, sk.offsets, body_root="Pelvis")


def test_generator_rejects_unknown_layouts() -> None:
    with pytest.raises(sa.SkelagnosticError, match="root_carrier must be one of"):
        sa.procedural.generate("biped22", "walk", 1.0, root_carrier="moving")
    with pytest.raises(sa.SkelagnosticError, match="channels must be one of"):
        sa.procedural.generate("biped22", "walk", 1.0, channels="all9")
