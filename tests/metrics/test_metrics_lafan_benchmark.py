"""LaFAN1 benchmark protocol on the real subject-5 clip: LERP/SLERP and zero-velocity baselines.

Follows the benchmark's data preparation (``get_lafan1_set``/``benchmark_interpolation``):
65-frame test windows every 40 frames, 10 past frames, transitions of 5/15/30/45
frames, then the target frame; root XZ centred on the window mean and facing
unified at the last past frame; L2P statistics from training windows (50 frames
every 20) of one subject-1 clip, as only two of the training subjects' clips are
available. The values must land in the published order of magnitude (within a
factor 3; measured: L2Q 0.18/0.54/0.86/1.03, L2P 0.35/1.26/2.43/3.39, NPSS
0.0015/0.026/0.15/0.35).

The statistics come from ``multipleActions1_subject1`` (mixed actions) rather than
``walk4_subject1``: walking alone has a vertical standard deviation of ~2.5 cm at
the hips, against ~27 cm over mixed actions, and would inflate L2P about 6-fold.
"""

from __future__ import annotations

import pytest
import torch

import skelagnostic as sa
from skelagnostic.core import quaternion as Q
from skelagnostic.core.kinematics import forward_kinematics
from skelagnostic.metrics import L2P, L2Q, NPSS
from skelagnostic.metrics.functional import l2p, l2q, npss

N_PAST, N_FUTURE = 10, 10
# Published LaFAN1 values per transition length: (L2Q, L2P, NPSS).
INTERPOLATION = {
    5: (0.22, 0.37, 0.0023),
    15: (0.62, 1.25, 0.0391),
    30: (0.98, 2.32, 0.2013),
    45: (1.25, 3.45, 0.4493),
}
ZERO_VELOCITY = {5: (0.56, 1.52), 15: (1.10, 3.69), 30: (1.51, 6.60), 45: (1.81, 9.33)}


def sliding_windows(
    motion: sa.Motion, length: int, offset: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """Local rotations [W, L, J, 4] and root positions [W, L, 3] of the benchmark windows."""
    starts = torch.arange(0, motion.num_frames - length, offset)  # `while i + window < T`
    index = starts[:, None] + torch.arange(length)
    return motion.rotations.double()[index], motion.root_positions.double()[index]


def canonicalise(rot: torch.Tensor, root: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Centre the root XZ on the window mean, then turn the root's local +Y axis
    (projected on the ground) at the last past frame onto +X, as the benchmark does."""
    root = root.clone()
    root[..., [0, 2]] -= root[..., [0, 2]].mean(dim=1, keepdim=True)
    up = torch.tensor([0.0, 1.0, 0.0], dtype=rot.dtype)
    forward = Q.rotate(rot[:, N_PAST - 1, 0], up)
    turn = Q.inv(Q.heading_from_direction(forward, up=1, forward=0))[:, None]  # [W, 1, 4]
    rot = rot.clone()
    rot[:, :, 0] = Q.mul(turn, rot[:, :, 0])
    return rot, Q.rotate(turn, root)


def normalisation_stats(motion: sa.Motion) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-channel mean/std of the global positions of the training windows."""
    rot, root = canonicalise(*sliding_windows(motion, 50, 20))
    s = motion.skeleton
    _, pos = forward_kinematics(rot, root, s.offsets.double(), s.parents)
    flat = pos.reshape(-1, s.num_joints * 3)
    return flat.mean(dim=0), flat.std(dim=0, correction=0)


def baselines(rot, root, skeleton, n_trans):
    """Ground truth, SLERP/LERP and zero-velocity predictions of one transition length,
    as full windows (past + transition + future) plus the transition mask."""
    rot, root = rot[:, : N_PAST + n_trans + N_FUTURE], root[:, : N_PAST + n_trans + N_FUTURE]
    trans = slice(N_PAST, N_PAST + n_trans)
    start, end = N_PAST - 1, N_PAST + n_trans
    w = torch.arange(1, n_trans + 1, dtype=rot.dtype) / (n_trans + 1)
    interp_rot, interp_root = rot.clone(), root.clone()
    interp_rot[:, trans] = Q.slerp(rot[:, start, None], rot[:, end, None], w[None, :, None])
    interp_root[:, trans] = root[:, start, None] + w[None, :, None] * (
        root[:, end, None] - root[:, start, None]
    )
    zero_rot, zero_root = rot.clone(), root.clone()
    zero_rot[:, trans] = rot[:, start, None]
    zero_root[:, trans] = root[:, start, None]
    offsets, parents = skeleton.offsets.double(), skeleton.parents
    fk = {
        name: forward_kinematics(r, p, offsets, parents)
        for name, (r, p) in {
            "gt": (rot, root),
            "interp": (interp_rot, interp_root),
            "zerov": (zero_rot, zero_root),
        }.items()
    }
    mask = torch.zeros(rot.shape[:2], dtype=torch.bool)
    mask[:, trans] = True
    return fk, mask


@pytest.mark.data
@pytest.mark.slow
def test_lafan1_baselines_on_subject5(shared_data):
    lafan = shared_data / "human" / "lafan1"
    mean, std = normalisation_stats(sa.read_bvh(lafan / "multipleActions1_subject1.bvh"))
    test_motion = sa.read_bvh(lafan / "obstacles1_subject5.bvh")
    rot, root = canonicalise(*sliding_windows(test_motion, 65, 40))
    assert rot.shape[:2] == (134, 65)

    for n_trans, (pub_l2q, pub_l2p, pub_npss) in INTERPOLATION.items():
        fk, mask = baselines(rot, root, test_motion.skeleton, n_trans)
        (gt_q, gt_p), (in_q, in_p), (zv_q, zv_p) = fk["gt"], fk["interp"], fk["zerov"]
        values = {
            "l2q": l2q(in_q, gt_q, mask).item(),
            "l2p": l2p(in_p, gt_p, mean, std, mask).item(),
            "npss": npss(in_q, gt_q, mask=mask).item(),
        }
        for name, published in zip(values, (pub_l2q, pub_l2p, pub_npss), strict=True):
            ratio = values[name] / published
            assert 1 / 3 < ratio < 3, (n_trans, name, values[name], published)
        # the zero-velocity baseline is worse, in its published order of magnitude too
        zero_l2q, zero_l2p = l2q(zv_q, gt_q, mask).item(), l2p(zv_p, gt_p, mean, std, mask).item()
        assert zero_l2q > values["l2q"] and zero_l2p > values["l2p"]
        assert 1 / 3 < zero_l2q / ZERO_VELOCITY[n_trans][0] < 3
        assert 1 / 3 < zero_l2p / ZERO_VELOCITY[n_trans][1] < 3

        # masking full windows = slicing the transition (what the benchmark code does)
        tr = slice(N_PAST, N_PAST + n_trans)
        assert values["l2p"] == pytest.approx(l2p(in_p[:, tr], gt_p[:, tr], mean, std).item())
        assert values["npss"] == pytest.approx(
            npss(Q.continuity(in_q)[:, tr], Q.continuity(gt_q)[:, tr]).item()
        )

        # the classes, fed in two uneven batches, agree with the functions
        metrics = {"l2q": L2Q(), "l2p": L2P(mean, std), "npss": NPSS()}
        for part in (slice(0, 50), slice(50, None)):
            metrics["l2q"].update(in_q[part], gt_q[part], mask[part])
            metrics["l2p"].update(in_p[part], gt_p[part], mask[part])
            metrics["npss"].update(in_q[part], gt_q[part], mask[part])
        for name, metric in metrics.items():
            assert metric.compute().item() == pytest.approx(values[name], rel=1e-5)
