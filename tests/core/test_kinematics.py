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
