"""The LaFAN1 in-betweening benchmark metrics as functions: L2P, L2Q and NPSS.

The functional twins of :mod:`skelagnostic.metrics.lafan`.
"""

from __future__ import annotations

import torch
from torch import Tensor

from skelagnostic.metrics._checks import (
    check_choice,
    check_frame_mask,
    check_same_shape,
    check_tensor,
    fail,
    promote,
)
from skelagnostic.metrics.functional._utils import _mean_compute

__all__ = ["feature_npss", "l2p", "l2q", "npss"]

NPSS_POWERS = ("real", "abs")


# --------------------------------------------------------------------------- LaFAN1 metrics


def _frames(
    name: str, preds: Tensor, target: Tensor, last: int, layout: str
) -> tuple[Tensor, Tensor]:
    """Validate a ``[B, T, J, last]`` pair; return it in the common dtype."""
    check_tensor(name, "preds", preds, min_ndim=4, last_dim=last, layout=layout)
    check_tensor(name, "target", target, min_ndim=4, last_dim=last, layout=layout)
    if preds.ndim != 4:
        raise fail(name, f"preds must have shape {layout}, got {list(preds.shape)}")
    check_same_shape(name, preds, target, ("frames", "joints", "channels"))
    return promote(preds, target)


def _masked_frame_sum(name: str, per_frame: Tensor, mask: Tensor | None) -> tuple[Tensor, Tensor]:
    """Sum a ``[B, T]`` per-frame value over the frames selected by ``mask``."""
    if mask is None:
        return per_frame.sum(), torch.tensor(per_frame.numel(), device=per_frame.device)
    mask = check_frame_mask(name, mask, per_frame.shape).to(per_frame.device)
    return per_frame[mask].sum(), mask.sum()


def _flat_stats(name: str, arg: str, value: Tensor | float, channels: int, like: Tensor) -> Tensor:
    """Normalisation statistics as a ``[channels]`` vector (or a broadcast scalar)."""
    v = torch.as_tensor(value, dtype=like.dtype, device=like.device)
    if v.numel() not in (1, channels):
        raise fail(
            name,
            f"{arg} must have J*3 = {channels} values (e.g. shape [{channels}] or "
            f"[1, {channels}, 1] as the LaFAN1 code stores them), got shape {list(v.shape)}",
        )
    if not bool(torch.isfinite(v).all()):
        raise fail(name, f"{arg} contains NaN or infinite values")
    return v.reshape(-1)


def _l2p_update(
    preds: Tensor,
    target: Tensor,
    mean: Tensor | float,
    std: Tensor | float,
    mask: Tensor | None = None,
) -> tuple[Tensor, Tensor]:
    """Sum over counted frames of the normalised L2 distance, and the frame count."""
    name = "l2p"
    preds, target = _frames(name, preds, target, 3, "[B, T, J, 3]")
    batch, frames, joints, _ = preds.shape
    channels = joints * 3
    mean_v = _flat_stats(name, "mean", mean, channels, preds)
    std_v = _flat_stats(name, "std", std, channels, preds)
    if bool((std_v <= 0).any()):
        raise fail(name, "std must be > 0 in every channel")
    norm_p = (preds.reshape(batch, frames, channels) - mean_v) / std_v
    norm_t = (target.reshape(batch, frames, channels) - mean_v) / std_v
    per_frame = torch.linalg.vector_norm(norm_p - norm_t, dim=-1)  # [B, T]
    return _masked_frame_sum(name, per_frame, mask)


def _nonempty(name: str, count: Tensor) -> None:
    if int(count) == 0:
        raise fail(name, "mask selects no frame; nothing to average")


def l2p(
    preds: Tensor,
    target: Tensor,
    mean: Tensor | float,
    std: Tensor | float,
    mask: Tensor | None = None,
) -> Tensor:
    r"""L2P, the LaFAN1 benchmark's normalised global-position error.

    Each frame's global positions are flattened to ``J*3`` channels (joint-major:
    ``x0, y0, z0, x1, ...``), z-normalised with the per-channel ``mean``/``std`` of
    the *training* windows, and the L2 norm of the difference is averaged over
    the counted frames of every sequence:

    $$
    \mathrm{L2P} = \frac{1}{|F|}\sum_{(b,t)\in F}
    \Big\lVert \frac{\hat x_{b,t} - \mu}{\sigma} - \frac{x_{b,t} - \mu}{\sigma} \Big\rVert_2
    $$

    Args:
        preds: Predicted global positions ``[B, T, J, 3]``.
        target: Ground-truth global positions ``[B, T, J, 3]``.
        mean: Per-channel training mean with ``J*3`` values (any shape, e.g. ``[J*3]``,
            ``[J, 3]`` or LaFAN1's ``[1, J*3, 1]``), or a scalar.
        std: Per-channel training standard deviation, same layout, all ``> 0``.
        mask: Optional ``[B, T]`` boolean mask of the frames to count (the transition
            frames); all frames when ``None``.

    Returns:
        Scalar tensor.

    Raises:
        MotionError: On mismatched shapes, NaN/inf, bad statistics or an empty mask.

    Examples:
        >>> import torch
        >>> target = torch.zeros(1, 2, 2, 3)
        >>> preds = target.clone()
        >>> preds[0, 1, 0, 0] = 2.0
        >>> l2p(preds, target, mean=torch.zeros(6), std=torch.full((6,), 0.5))
        tensor(2.)
        >>> l2p(preds, target, 0.0, 1.0, mask=torch.tensor([[False, True]]))
        tensor(2.)
    """
    total, count = _l2p_update(preds, target, mean, std, mask)
    _nonempty("l2p", count)
    return _mean_compute(total, count)


def _continuous(q: Tensor) -> Tensor:
    """Remove quaternion sign flips along the time axis of ``[B, T, J, 4]``."""
    # Imported here: the quaternion module pulls in roma, which takes seconds to import,
    # and most users of the metrics never need it.
    from skelagnostic.core import quaternion as Q

    return Q.continuity(q, dim=-3)


def _l2q_update(
    preds: Tensor,
    target: Tensor,
    mask: Tensor | None = None,
    continuity: bool = True,
) -> tuple[Tensor, Tensor]:
    """Sum over counted frames of the quaternion L2 distance, and the frame count."""
    name = "l2q"
    preds, target = _frames(name, preds, target, 4, "[B, T, J, 4]")
    if continuity:
        preds, target = _continuous(preds), _continuous(target)
    per_frame = torch.linalg.vector_norm((preds - target).flatten(-2), dim=-1)  # [B, T]
    return _masked_frame_sum(name, per_frame, mask)


def l2q(
    preds: Tensor, target: Tensor, mask: Tensor | None = None, *, continuity: bool = True
) -> Tensor:
    r"""L2Q, the LaFAN1 benchmark's global-quaternion error.

    $$
    \mathrm{L2Q} = \frac{1}{|F|}\sum_{(b,t)\in F} \lVert \hat q_{b,t} - q_{b,t} \rVert_2
    $$

    with $q_{b,t}$ the $4J$ global quaternion values ``(w, x, y, z)`` of frame
    ``t`` of sequence ``b``. The benchmark reads its quaternions with sign
    discontinuities removed along time (``q`` and ``-q`` are the same rotation);
    with ``continuity=True`` (default) both inputs get the same treatment over
    their full length before the mask is applied, so a sign flip in the data does
    not count as an error. The overall sign of a sequence is *not* aligned with
    the target (neither does the benchmark).

    Args:
        preds: Predicted global quaternions ``[B, T, J, 4]``.
        target: Ground-truth global quaternions ``[B, T, J, 4]``.
        mask: Optional ``[B, T]`` boolean mask of the frames to count.
        continuity: Remove sign flips along time first.

    Returns:
        Scalar tensor.

    Raises:
        MotionError: On mismatched shapes, NaN/inf or an empty mask.

    Examples:
        >>> import torch
        >>> target = torch.tensor([1.0, 0.0, 0.0, 0.0]).expand(1, 3, 2, 4)
        >>> preds = target.clone()
        >>> preds[0, 2, 1] = torch.tensor([0.0, 1.0, 0.0, 0.0])
        >>> l2q(preds, target, mask=torch.tensor([[False, False, True]]))
        tensor(1.4142)
    """
    total, count = _l2q_update(preds, target, mask, continuity)
    _nonempty("l2q", count)
    return _mean_compute(total, count)


def _contiguous_runs(name: str, x: Tensor, mask: Tensor) -> list[Tensor]:
    """Split ``[B, T, D]`` into groups of equal-length masked runs, ``[b_i, L_i, D]`` each."""
    counts = mask.sum(dim=1)
    if bool((counts == 0).any()):
        row = int((counts == 0).nonzero()[0])
        raise fail(name, f"mask selects no frame in sequence {row}")
    frames = torch.arange(mask.shape[1], device=mask.device)
    first = torch.where(mask, frames, mask.shape[1]).amin(dim=1)
    last = torch.where(mask, frames, -1).amax(dim=1)
    if bool((last - first + 1 != counts).any()):
        raise fail(name, "mask must select one contiguous run of frames per sequence")
    runs = []
    for length in counts.unique().tolist():
        rows = (counts == length).nonzero().squeeze(1)
        index = first[rows, None] + torch.arange(length, device=mask.device)
        runs.append(x[rows[:, None], index])
    return runs


def _npss_sums(preds: Tensor, target: Tensor, power: str) -> tuple[Tensor, Tensor]:
    """Weighted-EMD sum and weight sum of ``[B, T, D]`` inputs (FFT along ``T``)."""
    spec_p = torch.fft.fft(preds, dim=1)
    spec_t = torch.fft.fft(target, dim=1)
    if power == "real":
        pow_p, pow_t = spec_p.real.square(), spec_t.real.square()
    else:
        pow_p, pow_t = spec_p.abs().square(), spec_t.abs().square()
    total_p = pow_p.sum(dim=1, keepdim=True)
    total_t = pow_t.sum(dim=1, keepdim=True)
    tiny = torch.finfo(total_t.dtype).tiny
    # A channel with zero total power has an all-zero spectrum: its normalised spectrum is 0.
    cdf_p = torch.cumsum(pow_p / total_p.clamp_min(tiny), dim=1)
    cdf_t = torch.cumsum(pow_t / total_t.clamp_min(tiny), dim=1)
    emd = (cdf_p - cdf_t).abs().sum(dim=1)  # [B, D]
    weight = total_t.squeeze(1)
    return (emd * weight).sum(), weight.sum()


def _npss_update(
    preds: Tensor,
    target: Tensor,
    power: str = "real",
    mask: Tensor | None = None,
    continuity: bool = True,
) -> tuple[Tensor, Tensor]:
    """Power-weighted EMD sum and ground-truth power sum (the two NPSS states)."""
    name = "npss"
    check_choice(name, "power", power, NPSS_POWERS)
    preds, target = _frames(name, preds, target, 4, "[B, T, J, 4]")
    if continuity:
        preds, target = _continuous(preds), _continuous(target)
    preds, target = preds.flatten(2), target.flatten(2)
    if mask is None:
        return _npss_sums(preds, target, power)
    mask = check_frame_mask(name, mask, preds.shape[:2]).to(preds.device)
    pairs = zip(
        _contiguous_runs(name, preds, mask), _contiguous_runs(name, target, mask), strict=True
    )
    emd, weight = zip(*(_npss_sums(p, t, power) for p, t in pairs), strict=True)
    return torch.stack(emd).sum(), torch.stack(weight).sum()


def npss(
    preds: Tensor,
    target: Tensor,
    power: str = "real",
    *,
    mask: Tensor | None = None,
    continuity: bool = True,
) -> Tensor:
    r"""NPSS, normalised power spectrum similarity (LaFAN1 ``fast_npss``).

    Global quaternions are flattened to $D = 4J$ channels. Per sequence $b$
    and channel $d$: the power spectrum along time $P_{b,d}(f)$ (full FFT
    over the $T$ frames), normalised to sum 1, its cumulative sum $C_{b,d}$,
    and the earth mover's distance
    $\mathrm{EMD}_{b,d} = \sum_f |\hat C_{b,d}(f) - C_{b,d}(f)|$. The result is
    the average of all EMDs weighted by the ground-truth total power
    $W_{b,d} = \sum_f P_{b,d}(f)$:

    $$
    \mathrm{NPSS} = \frac{\sum_{b,d} W_{b,d}\,\mathrm{EMD}_{b,d}}{\sum_{b,d} W_{b,d}}
    $$

    ``power="real"`` (default) reproduces the benchmark code, which squares the
    *real part* of the FFT; ``power="abs"`` uses the squared magnitude (CITL,
    PC-MRL). A channel with zero total power gets a zero normalised spectrum
    (the benchmark code would return NaN).

    Args:
        preds: Predicted global quaternions ``[B, T, J, 4]``.
        target: Ground-truth global quaternions ``[B, T, J, 4]``.
        power: ``"real"`` or ``"abs"``.
        mask: Optional ``[B, T]`` mask selecting one contiguous run of frames per
            sequence (e.g. the transition); runs may differ in length.
        continuity: Remove quaternion sign flips along time first (see
            [`l2q`][skelagnostic.metrics.functional.l2q]).

    Returns:
        Scalar tensor.

    Raises:
        MotionError: On mismatched shapes, NaN/inf, a non-contiguous or empty mask row.

    Examples:
        >>> import torch
        >>> t = torch.arange(8.0)
        >>> target = torch.stack([torch.cos(t), torch.sin(t), 0 * t, 0 * t], -1)[None, :, None]
        >>> npss(target, target)
        tensor(0.)
        >>> preds = target.roll(1, dims=1)
        >>> round(float(npss(preds, target, "abs")), 6)
        0.0
    """
    total, weight = _npss_update(preds, target, power, mask, continuity)
    return _mean_compute(total, weight)


def feature_npss(preds: Tensor, target: Tensor, power: str = "real") -> Tensor:
    r"""NPSS of any per-frame features ``[B, T, D]``: the formula of :func:`npss` per channel.

    :func:`npss` takes global quaternions; CITL and PC-MRL's Table 1 compute the
    same power-weighted earth mover's distance on the positions and rotations of a
    window side by side (``torch.cat([positions, rotations], -1).flatten(2)``).
    Here every one of the $D$ channels is taken as it is: no quaternion sign
    continuity, no mask.

    Args:
        preds: Predicted features ``[B, T, D]``.
        target: Ground-truth features ``[B, T, D]``.
        power: ``"real"`` (the benchmark code's squared real part of the FFT) or
            ``"abs"`` (the squared magnitude, CITL and PC-MRL).

    Returns:
        Scalar tensor (NaN when the target has no power at all).

    Raises:
        MotionError: On mismatched shapes, a wrong number of dimensions, NaN/inf
            values or an unknown ``power``.

    Examples:
        >>> import torch
        >>> t = torch.arange(8.0)
        >>> target = torch.stack([torch.cos(t), t], -1)[None]
        >>> feature_npss(target, target)
        tensor(0.)
    """
    name = "feature_npss"
    check_choice(name, "power", power, NPSS_POWERS)
    layout = "[B, T, D]"
    check_tensor(name, "preds", preds, min_ndim=3, layout=layout)
    check_tensor(name, "target", target, min_ndim=3, layout=layout)
    if preds.ndim != 3:
        raise fail(name, f"preds must have shape {layout}, got {list(preds.shape)}")
    check_same_shape(name, preds, target, ("frames", "channels"))
    preds, target = promote(preds, target)
    return _mean_compute(*_npss_sums(preds, target, power))
