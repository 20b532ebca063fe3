import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

import skelagnostic as sa
from skelagnostic.core import quaternion as Q
from skelagnostic.core.kinematics import depth_levels, forward_kinematics


def _naive_fk(rot_wxyz, root, offsets, parents, trans=None):
    """Joint-by-joint FK with scipy matrices: an independent transcription."""
    t_count, j_count = rot_wxyz.shape[:2]
    gpos = np.zeros((t_count, j_count, 3))
    gmat = np.zeros((t_count, j_count, 3, 3))
    xyzw = np.concatenate([rot_wxyz[..., 1:], rot_wxyz[..., :1]], -1)
    local = Rotation.from_quat(xyzw.reshape(-1, 4)).as_matrix().reshape(t_count, j_count, 3, 3)
    for j, p in enumerate(parents):
        if p < 0:
            gmat[:, j] = local[:, j]
            gpos[:, j] = root
            continue
        off = offsets[j] if trans is None else trans[:, j]
        gmat[:, j] = gmat[:, p] @ local[:, j]
        gpos[:, j] = gpos[:, p] + np.einsum(
            "tij,tj->ti", gmat[:, p], np.broadcast_to(off, (t_count, 3))
        )
    return gmat, gpos


PARENTS = [-1, 0, 1, 2, 0, 4, 0, 6, 7, 7]


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_fk_matches_naive_reference(dtype):
    gen = torch.Generator().manual_seed(0)
    rot = Q.normalize(torch.randn(12, len(PARENTS), 4, generator=gen, dtype=torch.float64))
    root = torch.randn(12, 3, generator=gen, dtype=torch.float64)
    offsets = torch.randn(len(PARENTS), 3, generator=gen, dtype=torch.float64)
    grot, gpos = forward_kinematics(rot.to(dtype), root.to(dtype), offsets, PARENTS)
    mats, ref = _naive_fk(rot.numpy(), root.numpy(), offsets.numpy(), PARENTS)
    tol = 1e-5 if dtype == torch.float32 else 1e-12
    np.testing.assert_allclose(gpos.double().numpy(), ref, atol=tol * 10)
    np.testing.assert_allclose(Q.to_matrix(grot.double()).numpy(), mats, atol=tol * 10)
    assert gpos.dtype == dtype


def test_fk_batch_dims_and_translations():
    gen = torch.Generator().manual_seed(1)
    rot = Q.normalize(torch.randn(3, 5, len(PARENTS), 4, generator=gen, dtype=torch.float64))
    root = torch.randn(3, 5, 3, generator=gen, dtype=torch.float64)
    offsets = torch.randn(len(PARENTS), 3, generator=gen, dtype=torch.float64)
    _, batched = forward_kinematics(rot, root, offsets, PARENTS)
    for b in range(3):
        _, single = forward_kinematics(rot[b], root[b], offsets, PARENTS)
        torch.testing.assert_close(batched[b], single)
    trans = offsets.expand(5, -1, -1).clone()
    trans[:, 2] += torch.randn(5, 3, generator=gen, dtype=torch.float64)
    _, with_t = forward_kinematics(rot[0], root[0], offsets, PARENTS, translations=trans)
    _, ref = _naive_fk(rot[0].numpy(), root[0].numpy(), offsets.numpy(), PARENTS, trans.numpy())
    np.testing.assert_allclose(with_t.numpy(), ref, atol=1e-12)


def test_fk_is_differentiable():
    rot = Q.normalize(torch.randn(2, len(PARENTS), 4, dtype=torch.float64)).requires_grad_()
    root = torch.zeros(2, 3, dtype=torch.float64)
    offsets = torch.randn(len(PARENTS), 3, dtype=torch.float64)
    assert torch.autograd.gradcheck(
        lambda r: forward_kinematics(r, root, offsets, PARENTS)[1], (rot,)
    )


def test_fk_gradient_reaches_offsets():
    rot = Q.normalize(torch.randn(2, len(PARENTS), 4, dtype=torch.float64))
    root = torch.zeros(2, 3, dtype=torch.float64)
    offsets = torch.randn(len(PARENTS), 3, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(
        lambda o: forward_kinematics(rot, root, o, PARENTS)[1], (offsets,)
    )


def test_depth_levels_and_errors():
    assert depth_levels(PARENTS) == [[0], [1, 4, 6], [2, 5, 7], [3, 8, 9]]
    with pytest.raises(sa.MotionError, match="joints"):
        forward_kinematics(
            torch.zeros(1, 3, 4), torch.zeros(1, 3), torch.zeros(4, 3), [-1, 0, 1, 2]
        )


# --------------------------------------------------------------- local/global maps, FK from global


def _check_maps_against_forward_kinematics(motion: sa.Motion) -> None:
    from skelagnostic.core.kinematics import fk_from_global, global_from_local, local_from_global

    sk = motion.skeleton
    grot_ref, gpos_ref = forward_kinematics(
        motion.rotations, motion.root_positions, sk.offsets, sk.parents
    )
    grot = global_from_local(motion.rotations, sk.parents)
    torch.testing.assert_close(grot, grot_ref, atol=1e-5, rtol=0)
    gpos = fk_from_global(grot, motion.root_positions, sk.offsets, sk.parents)
    scale = float(gpos_ref.abs().max())
    torch.testing.assert_close(gpos, gpos_ref, atol=1e-5 * scale, rtol=0)
    torch.testing.assert_close(
        local_from_global(grot_ref, sk.parents), motion.rotations, atol=1e-5, rtol=0
    )


@pytest.mark.parametrize(("kind", "gait"), [("biped22", "walk"), ("quadruped", "trot")])
def test_geometry_maps_match_forward_kinematics_on_procedural_motion(kind, gait):
    from skelagnostic import procedural

    _check_maps_against_forward_kinematics(procedural.generate(kind, gait, seconds=1.0)[0])


@pytest.mark.parametrize("pattern", ["human/lafan1/*.bvh", "human/cmu/**/*.bvh", "dog/**/*.bvh"])
def test_geometry_maps_match_forward_kinematics_on_real_clips(shared_data, pattern):
    paths = sorted(shared_data.glob(pattern))
    if not paths:
        pytest.skip(f"no clip matches {pattern} in {shared_data}")
    _check_maps_against_forward_kinematics(sa.read_bvh(paths[0])[:60])


def test_local_from_global_against_scipy_matrices():
    from skelagnostic.core.kinematics import local_from_global

    gen = torch.Generator().manual_seed(3)
    grot = Q.normalize(torch.randn(4, len(PARENTS), 4, generator=gen, dtype=torch.float64))
    local = local_from_global(grot, PARENTS)
    mats = Q.to_matrix(grot).numpy()
    for j, p in enumerate(PARENTS):
        want = mats[:, j] if p < 0 else np.swapaxes(mats[:, p], -1, -2) @ mats[:, j]
        np.testing.assert_allclose(Q.to_matrix(local[:, j]).numpy(), want, atol=1e-12)


def test_fk_from_global_per_batch_offsets_and_gradients():
    from skelagnostic.core.kinematics import fk_from_global, global_from_local

    gen = torch.Generator().manual_seed(4)
    local = Q.normalize(torch.randn(2, 5, len(PARENTS), 4, generator=gen, dtype=torch.float64))
    root = torch.randn(2, 5, 3, generator=gen, dtype=torch.float64)
    offsets = torch.randn(2, len(PARENTS), 3, generator=gen, dtype=torch.float64)
    grot = global_from_local(local, PARENTS).requires_grad_(True)
    pos = fk_from_global(grot, root, offsets, PARENTS)
    for b in range(2):
        _, ref = forward_kinematics(local[b], root[b], offsets[b], PARENTS)
        torch.testing.assert_close(pos[b], ref)
    pos.square().sum().backward()
    assert grot.grad is not None and grot.grad.abs().sum() > 0


@pytest.mark.parametrize(
    "call",
    [
        lambda k: k.local_from_global(torch.zeros(2, 3, 4), [-1, 0]),
        lambda k: k.global_from_local(torch.zeros(2, 3, 4), [0, 0, 1]),
        lambda k: k.fk_from_global(
            torch.zeros(2, 3, 4), torch.zeros(2, 3), torch.zeros(2, 3), [-1, 0, 1]
        ),
    ],
)
def test_geometry_maps_reject_bad_hierarchies(call):
    from skelagnostic.core import kinematics

    with pytest.raises(sa.MotionError):
        call(kinematics)


def test_global_rotations_from_directions_swing_kabsch_and_unknown_bones():
    from skelagnostic.core.kinematics import global_rotations_from_directions

    # root with two children (a, c), a -> b a chain, c -> d a chain
    parents = [-1, 0, 1, 0, 3]
    offsets = torch.tensor(
        [[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 1, 0]], dtype=torch.float64
    )
    turn = Rotation.from_euler("xyz", [0.3, -0.7, 1.1])
    dirs = np.zeros((5, 3))
    dirs[[1, 3]] = turn.apply(offsets[[1, 3]].numpy())  # the root's bones: a rigid turn
    dirs[2] = [0.0, 0.0, 2.0]
    dirs[4] = [1.0, 1.0, 0.0]
    glob = global_rotations_from_directions(
        torch.tensor(dirs), offsets, parents, [True] * 4 + [False]
    )
    g = glob.numpy()
    # Kabsch at the root recovers the rigid turn
    xyzw = turn.as_quat()
    assert abs(abs((g[0] * np.r_[xyzw[3:], xyzw[:3]]).sum()) - 1.0) < 1e-9
    # a has one bone (to b): it points along dirs[2]
    np.testing.assert_allclose(Q.rotate(glob[1], offsets[2]).numpy(), [0.0, 0.0, 1.0], atol=1e-9)
    # b is a leaf, d's bone is unknown: b keeps a's global rotation, c the root's, d c's
    for joint, parent in ((2, 1), (3, 0), (4, 3)):
        np.testing.assert_allclose(g[joint], g[parent], atol=1e-12)
    with pytest.raises(sa.MotionError, match="known has 2 entries"):
        global_rotations_from_directions(torch.tensor(dirs), offsets, parents, [True, False])
