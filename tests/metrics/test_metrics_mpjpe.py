"""MPJPE (plain, root-relative, Procrustes, height-normalised): both interfaces."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import skelagnostic as sa
from skelagnostic.errors import MotionError, SkelagnosticError
from skelagnostic.metrics import MPJPE
from skelagnostic.metrics.functional import mpjpe


def umeyama_np(p: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Umeyama (1991) similarity transform of one pose p [J, 3] onto t, as in the paper."""
    mu_p, mu_t = p.mean(0), t.mean(0)
    var_p = ((p - mu_p) ** 2).sum(1).mean()
    sigma = (t - mu_t).T @ (p - mu_p) / len(p)
    u, d, vt = np.linalg.svd(sigma)
    s = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        s[2, 2] = -1
    r = u @ s @ vt
    c = np.trace(np.diag(d) @ s) / var_p
    return c * p @ r.T + (mu_t - c * r @ mu_p)


def reference(p: np.ndarray, t: np.ndarray, mode: str, height=None) -> float:
    if mode == "root":
        p, t = p - p[..., :1, :], t - t[..., :1, :]
    if mode == "procrustes":
        shape = p.shape
        flat_p, flat_t = p.reshape(-1, shape[-2], 3), t.reshape(-1, shape[-2], 3)
        p = np.stack([umeyama_np(a, b) for a, b in zip(flat_p, flat_t, strict=True)])
        p = p.reshape(shape)
    err = np.linalg.norm(p - t, axis=-1)
    if height is not None:
        err = err / height.reshape(*height.shape, *[1] * (err.ndim - height.ndim))
    return float(err.mean())


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("mode", ["plain", "root", "procrustes"])
def test_matches_numpy_reference_on_random_data(mode, dtype):
    gen = torch.Generator().manual_seed(0)
    target = torch.randn(3, 5, 7, 3, generator=gen, dtype=dtype)
    preds = target + 0.3 * torch.randn(3, 5, 7, 3, generator=gen, dtype=dtype)
    expected = reference(preds.double().numpy(), target.double().numpy(), mode)
    tol = 1e-5 if dtype == torch.float32 else 1e-10
    value = mpjpe(preds, target, mode=mode)
    assert value.dtype == dtype
    assert value.item() == pytest.approx(expected, rel=tol)

    metric = MPJPE(mode=mode)
    metric.update(preds[:1], target[:1])
    metric.update(preds[1:], target[1:])
    assert metric.compute().item() == pytest.approx(expected, rel=1e-5)


def test_height_normalisation_per_sequence():
    gen = torch.Generator().manual_seed(1)
    target = torch.randn(4, 6, 5, 3, generator=gen, dtype=torch.float64)
    preds = target + torch.randn(4, 6, 5, 3, generator=gen, dtype=torch.float64)
    height = torch.tensor([1.0, 1.5, 2.0, 0.5], dtype=torch.float64)
    expected = reference(preds.numpy(), target.numpy(), "plain", height.numpy())
    assert mpjpe(preds, target, height=height).item() == pytest.approx(expected)
    assert mpjpe(preds, target, height=2.0).item() == pytest.approx(
        mpjpe(preds, target).item() / 2.0
    )
    metric = MPJPE(normalize_by_height=True)
    metric.update(preds[:2], target[:2], height=height[:2])
    metric.update(preds[2:], target[2:], height=height[2:])
    assert metric.compute().item() == pytest.approx(expected)


def test_hand_computed_cases():
    target = torch.zeros(1, 2, 3)
    preds = torch.tensor([[[3.0, 4.0, 0.0], [0.0, 0.0, 1.0]]])
    assert mpjpe(preds, target).item() == pytest.approx(3.0)  # (5 + 1) / 2
    # root-relative: joint 1 relative to joint 0 is (-3, -4, 1) vs (0, 0, 0)
    assert mpjpe(preds, target, mode="root").item() == pytest.approx(26**0.5 / 2)
    assert mpjpe(preds, target, mode="root", root_index=1).item() == pytest.approx(26**0.5 / 2)


def test_procrustes_removes_similarity_transforms():
    gen = torch.Generator().manual_seed(2)
    target = torch.randn(10, 6, 3, generator=gen, dtype=torch.float64)
    rot = torch.linalg.qr(torch.randn(3, 3, generator=gen, dtype=torch.float64))[0]
    rot = rot * torch.sign(torch.linalg.det(rot))  # proper rotation
    preds = 2.5 * target @ rot.T + torch.tensor([1.0, -2.0, 0.5], dtype=torch.float64)
    assert mpjpe(preds, target, mode="procrustes").item() == pytest.approx(0.0, abs=1e-10)
    # a mirrored pose is not a proper rotation: the error stays
    mirrored = target * torch.tensor([-1.0, 1.0, 1.0], dtype=torch.float64)
    assert mpjpe(mirrored, target, mode="procrustes").item() > 0.1
    noisy = target + 0.2 * torch.randn(10, 6, 3, generator=gen, dtype=torch.float64)
    assert mpjpe(noisy, target, mode="procrustes") <= mpjpe(noisy, target)


@pytest.mark.data
def test_real_clip_against_reference(lafan_clip):
    motion = sa.read_bvh(lafan_clip)
    positions = motion.global_positions()[:120].double()
    target, preds = positions[:-5], positions[5:]  # a 5-frame lag as the "prediction"
    for mode in ("plain", "root", "procrustes"):
        expected = reference(preds.numpy(), target.numpy(), mode)
        assert mpjpe(preds, target, mode=mode).item() == pytest.approx(expected, rel=1e-9)
    height = motion.skeleton.height()
    assert mpjpe(preds, target, height=height).item() == pytest.approx(
        reference(preds.numpy(), target.numpy(), "plain") / height
    )


def test_gradients_flow():
    gen = torch.Generator().manual_seed(3)
    target = torch.randn(2, 4, 3, generator=gen, dtype=torch.float64)
    preds = (target + torch.randn(2, 4, 3, generator=gen, dtype=torch.float64)).requires_grad_()
    for mode in ("plain", "root", "procrustes"):
        assert torch.autograd.gradcheck(lambda p, m=mode: mpjpe(p, target, mode=m), (preds,))
    value = MPJPE()(preds, target)
    value.backward()
    assert preds.grad is not None


def test_errors_name_the_problem():
    good = torch.zeros(2, 4, 3)
    with pytest.raises(MotionError, match=r"joints differ: 4 vs 5"):
        mpjpe(good, torch.zeros(2, 5, 3))
    with pytest.raises(MotionError, match=r"preds contains NaN"):
        mpjpe(torch.full((2, 4, 3), float("nan")), good)
    with pytest.raises(MotionError, match=r"target contains infinite"):
        mpjpe(good, torch.full((2, 4, 3), float("inf")))
    with pytest.raises(MotionError, match=r"floating-point"):
        mpjpe(good.long(), good)
    with pytest.raises(MotionError, match=r"\[\.\.\., J, 3\]"):
        mpjpe(torch.zeros(2, 4), torch.zeros(2, 4))
    with pytest.raises(MotionError, match=r"mode must be one of"):
        mpjpe(good, good, mode="pa")
    with pytest.raises(MotionError, match=r"root_index"):
        mpjpe(good, good, mode="root", root_index=7)
    with pytest.raises(MotionError, match=r"height must be finite and > 0"):
        mpjpe(good, good, height=0.0)
    with pytest.raises(MotionError, match=r"height must be a number or a tensor"):
        mpjpe(good, good, height=torch.ones(3))
    with pytest.raises(SkelagnosticError, match=r"mode"):
        MPJPE(mode="bad")
    with pytest.raises(MotionError, match=r"needs a height"):
        MPJPE(normalize_by_height=True).update(good, good)
    with pytest.raises(MotionError, match=r"normalize_by_height=False"):
        MPJPE().update(good, good, height=1.0)


def test_metric_attributes_and_reset():
    metric = MPJPE()
    assert metric.higher_is_better is False
    assert metric.is_differentiable is True
    assert metric.full_state_update is False
    metric.update(torch.ones(2, 3), torch.zeros(2, 3))
    metric.reset()
    metric.update(torch.zeros(2, 3), torch.zeros(2, 3))
    assert metric.compute().item() == 0.0


@pytest.mark.parametrize("mode", ["plain", "root", "procrustes"])
def test_mixed_dtypes_are_promoted(mode):
    gen = torch.Generator().manual_seed(4)
    target = torch.randn(3, 5, 3, generator=gen, dtype=torch.float64)
    preds = (target + 0.1 * torch.randn(3, 5, 3, generator=gen, dtype=torch.float64)).float()
    value = mpjpe(preds, target, mode=mode)
    assert value.dtype == torch.float64
    assert value.item() == pytest.approx(mpjpe(preds.double(), target, mode=mode).item())
