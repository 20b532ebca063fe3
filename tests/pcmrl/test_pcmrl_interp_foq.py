"""FOQ (PC-MRL Sec. 3.3) as the interpolation model uses it: round trip and roll invariance."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch
from skelagnostic_pcmrl.interp.keyframes import window_features
from skelagnostic_pcmrl.interp.rpa import bone_tails

from skelagnostic import Motion, Skeleton, procedural, read_bvh
from skelagnostic.core import quaternion as Q
from skelagnostic.core.kinematics import local_from_global
from skelagnostic.representations import FirstFrameOffsetQuaternions


def _walk() -> Motion:
    motion, _ = procedural.generate("biped31", "walk", seconds=1.0, fps=30, seed=3)
    return motion.double()


def _same_rotation(a: torch.Tensor, b: torch.Tensor, atol: float = 1e-9) -> bool:
    """Equal as rotations (q and -q)."""
    dot = (a * b).sum(-1).abs()
    return bool(torch.allclose(dot, torch.ones_like(dot), atol=atol))


def test_foq_round_trip_real_clip(shared_data: Path) -> None:
    clip = read_bvh(shared_data / "human" / "xia_cmu" / "angry_13_000.bvh").double()[:40]
    rep = FirstFrameOffsetQuaternions()
    feats = rep.encode(clip)
    # frame 0 is the identity for every joint
    assert torch.allclose(feats[0, :, :4], torch.tensor([1.0, 0, 0, 0], dtype=feats.dtype))
    back = rep.decode(feats, clip.skeleton, clip.fps, reference=clip)
    assert torch.allclose(back.global_positions(), clip.global_positions(), atol=1e-8)
    assert _same_rotation(back.global_rotations(), clip.global_rotations())
    # any known frame works as the reference: q_0 = FOQ_t^-1 * q_t
    q_t = clip.global_rotations()[25]
    q0 = Q.mul(Q.inv(feats[25, :, :4]), q_t)
    again = rep.decode(feats, clip.skeleton, clip.fps, reference=q0)
    assert torch.allclose(again.global_positions(), clip.global_positions(), atol=1e-8)


def test_model_features_are_the_library_foq() -> None:
    motion = _walk()
    grot = motion.global_rotations()
    keys = torch.zeros(1, motion.num_frames, dtype=torch.bool)
    keys[0, ::5] = True
    tails = bone_tails(motion.skeleton).tails[None]
    f = window_features(
        grot[None],
        motion.root_positions[None],
        motion.skeleton.offsets[None],
        tails,
        keys,
        motion.skeleton.parents,
    )
    lib = FirstFrameOffsetQuaternions().encode(motion)
    assert torch.allclose(f["foq"][0], lib[..., :4], atol=1e-9)
    assert torch.allclose(f["positions"][0], motion.global_positions(), atol=1e-9)
    # FOQ * q0 gives back the global rotations, and local rotations through FK the motion
    assert _same_rotation(f["global"][0], grot)
    local = local_from_global(f["global"][0], motion.skeleton.parents)
    rebuilt = Motion(motion.skeleton, local, motion.root_positions, motion.fps)
    assert torch.allclose(rebuilt.global_positions(), motion.global_positions(), atol=1e-9)
    # non-key frames carry no information: zero features and a zero key flag
    assert torch.all(f["inputs"][0, ~keys[0]] == 0)
    assert torch.all(f["inputs"][0, keys[0], -1] == 1)


def _rolled(motion: Motion, joint: int, angle: float) -> Motion:
    """The same animation with bone ``joint`` rolled about its own rest axis by ``angle``.

    The joint's frame turns by ``r`` (axis = its rest tail); its children's offsets and
    local rotations are counter-rotated so every global position stays the same.
    """
    sk = motion.skeleton
    tail = bone_tails(sk).tails[joint]
    axis = tail / tail.norm()
    r = torch.cat(
        [torch.tensor([math.cos(angle / 2)], dtype=axis.dtype), math.sin(angle / 2) * axis]
    )
    offsets = sk.offsets.clone()
    rot = motion.rotations.clone()
    rot[:, joint] = Q.mul(rot[:, joint], r)
    for c in sk.children(joint):
        offsets[c] = Q.rotate(Q.inv(r), offsets[c])
        rot[:, c] = Q.mul(Q.inv(r).expand_as(rot[:, c]), rot[:, c])
    new_sk = Skeleton(sk.joint_names, sk.parents, offsets, end_sites=sk.end_sites)
    return Motion(new_sk, rot, motion.root_positions, motion.fps)


@pytest.mark.parametrize("joint_name", ["LeftLeg", "Spine1", "RightArm"])
def test_foq_is_roll_invariant(joint_name: str) -> None:
    motion = _walk()
    j = motion.skeleton.index(joint_name)
    rolled = _rolled(motion, j, angle=1.1)
    # the rest-pose roll changes nothing visible but the bone's absolute rotation ...
    assert torch.allclose(rolled.global_positions(), motion.global_positions(), atol=1e-9)
    assert not _same_rotation(
        rolled.global_rotations()[:, j], motion.global_rotations()[:, j], atol=1e-3
    )
    # ... and FOQ does not see it (paper: (q_t r)(q_0 r)^-1 = q_t q_0^-1)
    rep = FirstFrameOffsetQuaternions()
    assert torch.allclose(rep.encode(rolled), rep.encode(motion), atol=1e-9)
    # so do the model's inputs: the rest direction rotated by q_0 is the same world vector
    grot0, grot1 = motion.global_rotations(), rolled.global_rotations()
    keys = torch.ones(1, motion.num_frames, dtype=torch.bool)
    f0 = window_features(
        grot0[None],
        motion.root_positions[None],
        motion.skeleton.offsets[None],
        bone_tails(motion.skeleton).tails[None],
        keys,
        motion.skeleton.parents,
    )
    f1 = window_features(
        grot1[None],
        rolled.root_positions[None],
        rolled.skeleton.offsets[None],
        bone_tails(rolled.skeleton).tails[None],
        keys,
        rolled.skeleton.parents,
    )
    assert torch.allclose(f0["inputs"], f1["inputs"], atol=1e-9)


def test_foq_is_not_invariant_to_a_time_varying_roll() -> None:
    """The invariance is to a *constant* roll only (a real twist animation is kept)."""
    motion = _walk()
    j = motion.skeleton.index("LeftLeg")
    axis = bone_tails(motion.skeleton).tails[j]
    axis = axis / axis.norm()
    angles = torch.linspace(0.0, 1.0, motion.num_frames, dtype=axis.dtype)
    r = torch.cat([torch.cos(angles / 2)[:, None], torch.sin(angles / 2)[:, None] * axis], -1)
    rot = motion.rotations.clone()
    rot[:, j] = Q.mul(rot[:, j], r)
    twisted = Motion(motion.skeleton, rot, motion.root_positions, motion.fps)
    rep = FirstFrameOffsetQuaternions()
    diff = (rep.encode(twisted)[1:, j, :4] - rep.encode(motion)[1:, j, :4]).abs().max()
    assert diff > 1e-2
