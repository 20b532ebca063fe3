import itertools

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from skelagnostic.core import quaternion as Q

ORDERS = ["".join(p) for p in itertools.permutations("XYZ")]


def _scipy_wxyz(rot: Rotation) -> np.ndarray:
    xyzw = rot.as_quat()
    return np.concatenate([xyzw[..., 3:], xyzw[..., :3]], axis=-1)


def _same_rotation(a, b, atol):
    dots = np.abs((np.asarray(a) * np.asarray(b)).sum(-1))
    assert np.all(np.abs(dots - 1) < atol), dots.min()


@pytest.mark.parametrize("order", ORDERS)
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_euler_to_quat_matches_scipy_intrinsic(order, dtype):
    rng = np.random.default_rng(0)
    angles = rng.uniform(-180, 180, size=(64, 3))
    q = Q.euler_to_quat(torch.tensor(angles, dtype=dtype), order)
    assert q.dtype == dtype and q.shape == (64, 4)
    ref = _scipy_wxyz(Rotation.from_euler(order, angles, degrees=True))
    _same_rotation(q.double().numpy(), ref, 1e-5 if dtype == torch.float32 else 1e-12)


@pytest.mark.parametrize("order", ORDERS)
def test_quat_to_euler_inverts(order):
    rng = np.random.default_rng(1)
    angles = torch.tensor(rng.uniform(-80, 80, size=(32, 3)))
    q = Q.euler_to_quat(angles, order)
    back = Q.quat_to_euler(q, order)
    _same_rotation(Q.euler_to_quat(back, order).numpy(), q.numpy(), 1e-12)


def test_mul_rotate_matrix_agree():
    rng = np.random.default_rng(2)
    a = Rotation.random(16, random_state=3)
    b = Rotation.random(16, random_state=4)
    qa, qb = torch.tensor(_scipy_wxyz(a)), torch.tensor(_scipy_wxyz(b))
    _same_rotation(Q.mul(qa, qb).numpy(), _scipy_wxyz(a * b), 1e-12)
    v = torch.tensor(rng.normal(size=(16, 3)))
    np.testing.assert_allclose(Q.rotate(qa, v).numpy(), a.apply(v.numpy()), atol=1e-12)
    np.testing.assert_allclose(Q.to_matrix(qa).numpy(), a.as_matrix(), atol=1e-12)
    _same_rotation(Q.from_matrix(torch.tensor(a.as_matrix())).numpy(), qa.numpy(), 1e-12)
    np.testing.assert_allclose(
        Q.mul(qa, Q.inv(qa)).numpy(), np.tile([1, 0, 0, 0], (16, 1)), atol=1e-12
    )


def test_rotate_broadcasts_over_batch_dims():
    q = Q.normalize(torch.randn(5, 1, 4, dtype=torch.float64))
    v = torch.randn(5, 7, 3, dtype=torch.float64)
    out = Q.rotate(q, v)
    ref = (Q.to_matrix(q) @ v.unsqueeze(-1)).squeeze(-1)
    torch.testing.assert_close(out, ref)


def test_rotate_mixes_precisions_in_the_wider_one():
    """Float32 rotations of bfloat16 vectors (autocast output), e.g. PC-MRL's root under bf16."""
    q = Q.normalize(torch.randn(5, 4, generator=torch.Generator().manual_seed(0)))
    v = torch.randn(5, 3, generator=torch.Generator().manual_seed(1)).to(torch.bfloat16)
    out = Q.rotate(q, v)
    assert out.dtype == torch.float32
    torch.testing.assert_close(out, Q.rotate(q, v.float()))
    assert Q.rotate(q.to(torch.bfloat16), v).dtype == torch.bfloat16


def test_slerp_endpoints_midpoint_and_short_arc():
    a = Q.euler_to_quat(torch.tensor([[0.0, 0.0, 0.0]], dtype=torch.float64), "ZYX")
    b = Q.euler_to_quat(torch.tensor([[90.0, 0.0, 0.0]], dtype=torch.float64), "ZYX")
    torch.testing.assert_close(Q.slerp(a, b, 0.0), a)
    torch.testing.assert_close(Q.slerp(a, b, 1.0), b)
    mid = Q.slerp(a, b, 0.5)
    ref = Q.euler_to_quat(torch.tensor([[45.0, 0.0, 0.0]], dtype=torch.float64), "ZYX")
    _same_rotation(mid.numpy(), ref.numpy(), 1e-12)
    # -b is the same rotation: slerp must take the short arc and give the same midpoint
    _same_rotation(Q.slerp(a, -b, 0.5).numpy(), ref.numpy(), 1e-12)
    # identical inputs do not produce NaN
    assert torch.isfinite(Q.slerp(a, a, 0.3)).all()


def test_continuity_removes_sign_flips():
    q = Q.euler_to_quat(
        torch.linspace(0, 720, 50, dtype=torch.float64)[:, None, None].expand(50, 2, 3).clone(),
        "XYZ",
    )
    flipped = q.clone()
    flipped[10:20] *= -1
    flipped[30:, 1] *= -1
    fixed = Q.continuity(flipped, dim=0)
    dots = (fixed[1:] * fixed[:-1]).sum(-1)
    assert (dots > 0).all()
    _same_rotation(fixed.numpy(), q.numpy(), 1e-12)
    with pytest.raises(ValueError):
        Q.continuity(q, dim=-1)


def test_bad_euler_order():
    with pytest.raises(ValueError, match="permutation"):
        Q.euler_to_quat(torch.zeros(1, 3), "XXY")


def test_heading_from_direction():
    d = torch.tensor([[1.0, 5.0, 0.0], [0.0, 0.0, 2.0], [-1.0, 0.0, 0.0]], dtype=torch.float64)
    h = Q.heading_from_direction(d)
    fwd = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64).expand(3, 3)
    out = Q.rotate(h, fwd)
    ref = torch.nn.functional.normalize(
        d * torch.tensor([1.0, 0.0, 1.0], dtype=torch.float64), dim=-1
    )
    torch.testing.assert_close(out, ref)


def test_best_rotation_matches_scipy_align_vectors():
    rng = np.random.default_rng(3)
    source = rng.normal(size=(5, 6, 3))
    truth = Rotation.random(5, random_state=4)
    noisy = np.stack([truth[i].apply(source[i]) for i in range(5)]) + 0.1 * rng.normal(
        size=source.shape
    )
    weights = rng.uniform(0.5, 2.0, size=(5, 6))
    q = Q.best_rotation(torch.tensor(source), torch.tensor(noisy), torch.tensor(weights))
    assert q.shape == (5, 4) and bool((q[:, 0] >= 0).all())
    for i in range(5):
        ref, _ = Rotation.align_vectors(noisy[i], source[i], weights=weights[i])
        _same_rotation(q[i].numpy(), _scipy_wxyz(ref), 1e-9)
    # a mirrored target still gives a rotation (det +1), the best one
    mirrored = source[0] * np.array([1.0, 1.0, -1.0])
    q = Q.best_rotation(torch.tensor(source[0]), torch.tensor(mirrored))
    ref, _ = Rotation.align_vectors(mirrored, source[0])
    _same_rotation(q.numpy(), _scipy_wxyz(ref), 1e-9)


def test_rotation_between_is_the_shortest_arc():
    rng = np.random.default_rng(5)
    u, v = rng.normal(size=(2, 16, 3))
    q = Q.rotation_between(torch.tensor(u), torch.tensor(3.0 * v)).numpy()
    unit = v / np.linalg.norm(v, axis=-1, keepdims=True)
    rotated = Q.rotate(torch.tensor(q), torch.tensor(u)).numpy()
    np.testing.assert_allclose(
        rotated, unit * np.linalg.norm(u, axis=-1, keepdims=True), atol=1e-12
    )
    # the axis is perpendicular to both and the angle is the angle between them
    angle = np.arccos(np.clip((u * unit).sum(-1) / np.linalg.norm(u, axis=-1), -1, 1))
    np.testing.assert_allclose(2 * np.arccos(np.clip(q[:, 0], -1, 1)), angle, atol=1e-7)
    np.testing.assert_allclose((q[:, 1:] * u).sum(-1), 0.0, atol=1e-12)
