"""Functional metrics: the same math as the :mod:`skelagnostic.metrics` classes, as plain functions.

Every metric ``x`` is split torchmetrics-style into a private ``_x_update``
(validates one batch and returns additive sufficient statistics, e.g. a sum and
a count) and ``_x_compute`` (turns accumulated statistics into the value). The
public function ``x(...)`` is ``_x_compute(*_x_update(...))``; the metric
classes keep the statistics as ``dist_reduce_fx="sum"`` states, which is why
they are exact under DDP.

Conventions: positions are ``[..., J, 3]`` in the data's units, quaternions are
``(w, x, y, z)``, ``preds`` is the model output and ``target`` the ground truth.
Bad input (wrong shapes or dtypes, NaN/inf, unknown options) raises
`MotionError` naming the argument.
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence

import torch
from torch import Tensor

from skelagnostic.metrics._checks import (
    check_bones,
    check_choice,
    check_frame_mask,
    check_indices,
    check_positive_int,
    check_same_frames,
    check_same_shape,
    check_tensor,
    fail,
    promote,
    reshape_per_item,
)

__all__ = [
    "bone_length_consistency",
    "end_effector_error",
    "l2p",
    "l2q",
    "manifold_overlap",
    "mpjpe",
    "npss",
    "temporal_knn_distance",
]

MPJPE_MODES = ("plain", "root", "procrustes")
NPSS_POWERS = ("real", "abs")
REDUCTIONS = ("mean", "sum")
# Largest number of pairwise distances the KNN metric materialises at once.
_KNN_CHUNK_ELEMENTS = 1 << 24


# --------------------------------------------------------------------------- MPJPE


def _procrustes_align(preds: Tensor, target: Tensor) -> Tensor:
    """Similarity-align every pose of ``preds`` to ``target`` (Umeyama, with scale).

    Both are ``[N, J, 3]``. Returns ``s * R @ preds + t`` per pose, with the
    rotation ``R`` forced proper (no reflection) and the scale ``s`` minimising
    the squared error.
    """
    mu_p = preds.mean(dim=-2, keepdim=True)
    mu_t = target.mean(dim=-2, keepdim=True)
    p0 = preds - mu_p
    t0 = target - mu_t
    cov = p0.transpose(-1, -2) @ t0  # [N, 3, 3] = sum_j p_j t_j^T
    u, s, vh = torch.linalg.svd(cov)
    v = vh.transpose(-1, -2)
    sign = torch.sign(torch.linalg.det(v @ u.transpose(-1, -2)))
    sign = torch.where(sign == 0, torch.ones_like(sign), sign)
    z = torch.ones_like(s)
    z[..., -1] = sign
    rot = v @ torch.diag_embed(z) @ u.transpose(-1, -2)  # maps preds onto target
    var_p = p0.square().sum(dim=(-1, -2))
    scale = (s * z).sum(dim=-1) / var_p.clamp_min(torch.finfo(preds.dtype).tiny)
    return scale[:, None, None] * (p0 @ rot.transpose(-1, -2)) + mu_t


def _mpjpe_update(
    preds: Tensor,
    target: Tensor,
    mode: str = "plain",
    root_index: int = 0,
    height: float | Tensor | None = None,
) -> tuple[Tensor, Tensor]:
    """Sum of per-joint position errors and the number of (pose, joint) pairs."""
    name = "mpjpe"
    check_choice(name, "mode", mode, MPJPE_MODES)
    check_tensor(name, "preds", preds, min_ndim=2, last_dim=3, layout="[..., J, 3]")
    check_tensor(name, "target", target, min_ndim=2, last_dim=3, layout="[..., J, 3]")
    check_same_shape(name, preds, target, ("joints", "xyz"))
    preds, target = promote(preds, target)
    num_joints = preds.shape[-2]
    if mode == "root":
        if not -num_joints <= root_index < num_joints:
            raise fail(name, f"root_index {root_index} is out of range for {num_joints} joints")
        preds = preds - preds[..., root_index : root_index + 1, :]
        target = target - target[..., root_index : root_index + 1, :]
    elif mode == "procrustes":
        flat_p = preds.reshape(-1, num_joints, 3)
        flat_t = target.reshape(-1, num_joints, 3)
        preds = _procrustes_align(flat_p, flat_t).reshape(preds.shape)
    errors = torch.linalg.vector_norm(preds - target, dim=-1)  # [..., J]
    if height is not None:
        errors = (
            errors / reshape_per_item(name, "height", height, errors.shape[:-1], errors)[..., None]
        )
    return errors.sum(), torch.tensor(errors.numel(), device=errors.device)


def _mean_compute(total: Tensor, count: Tensor) -> Tensor:
    """``total / count`` (NaN when nothing was counted)."""
    return total / count


def mpjpe(
    preds: Tensor,
    target: Tensor,
    *,
    mode: str = "plain",
    height: float | Tensor | None = None,
    root_index: int = 0,
) -> Tensor:
    r"""Mean per-joint position error.

    $$
    \mathrm{MPJPE} = \frac{1}{N J}\sum_{n,j} \lVert \hat p_{n,j} - p_{n,j} \rVert_2
    $$

    over every pose ``n`` (all leading dimensions) and joint ``j``, in the data's units.

    Args:
        preds: Predicted global joint positions ``[..., J, 3]``.
        target: Ground-truth global joint positions, same shape.
        mode: ``"plain"``; ``"root"`` subtracts joint ``root_index`` from every pose
            first (root-relative MPJPE); ``"procrustes"`` first aligns each predicted
            pose to its target with the optimal similarity transform (rotation,
            uniform scale, translation; PA-MPJPE).
        height: Optional skeleton height to normalise by (HuMoT reports
            MPJPE / height): a number, or a tensor whose shape is a prefix of the
            leading dimensions, e.g. ``[B]`` for ``[B, T, J, 3]`` inputs.
        root_index: Joint used as the origin in ``"root"`` mode.

    Returns:
        Scalar tensor.

    Raises:
        MotionError: On mismatched shapes, NaN/inf, non-positive heights or an unknown mode.

    Examples:
        >>> import torch
        >>> target = torch.zeros(2, 4, 3)
        >>> preds = target + torch.tensor([3.0, 4.0, 0.0])
        >>> mpjpe(preds, target)
        tensor(5.)
        >>> mpjpe(preds, target, mode="root")
        tensor(0.)
        >>> mpjpe(preds, target, height=torch.tensor([1.0, 2.0]))
        tensor(3.7500)
    """
    return _mean_compute(*_mpjpe_update(preds, target, mode, root_index, height))


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


# --------------------------------------------------------------------------- manifold overlap


def _manifold_overlap_update(
    codes: Sequence[Tensor] | Tensor,
    num_codes: int,
    dataset: int | None = None,
    num_datasets: int | None = None,
) -> Tensor:
    """Per-dataset code histogram ``[D, K]`` (int64) of one batch.

    ``codes`` is either a sequence of 1-D integer tensors, one per dataset, or a
    single 1-D tensor of dataset ``dataset``.
    """
    name = "manifold_overlap"
    check_positive_int(name, "num_codes", num_codes)
    if isinstance(codes, Tensor):
        if dataset is None or num_datasets is None:
            raise fail(name, "a single codes tensor needs its dataset index")
        if not 0 <= dataset < num_datasets:
            raise fail(name, f"dataset must be in [0, {num_datasets}), got {dataset}")
        per_dataset: list[Tensor | None] = [None] * num_datasets
        per_dataset[dataset] = codes
    else:
        per_dataset = list(codes)
        if num_datasets is not None and len(per_dataset) != num_datasets:
            raise fail(name, f"expected codes of {num_datasets} datasets, got {len(per_dataset)}")
        if not per_dataset:
            raise fail(name, "codes must hold at least one dataset")
    device = next((c.device for c in per_dataset if isinstance(c, Tensor)), None)
    counts = torch.zeros(len(per_dataset), num_codes, dtype=torch.long, device=device)
    for i, c in enumerate(per_dataset):
        if c is None:
            continue
        arg = f"codes[{i}]"
        if not isinstance(c, Tensor) or c.ndim != 1:
            raise fail(name, f"{arg} must be a 1-D tensor of code indices")
        if c.is_floating_point() or c.is_complex() or c.dtype == torch.bool:
            raise fail(name, f"{arg} must be an integer tensor, got dtype {c.dtype}")
        if c.numel() and (int(c.min()) < 0 or int(c.max()) >= num_codes):
            raise fail(
                name,
                f"{arg} holds codes in [{int(c.min())}, {int(c.max())}], "
                f"outside [0, num_codes={num_codes})",
            )
        counts[i] = torch.bincount(c.long().to(device), minlength=num_codes)
    return counts


def _manifold_overlap_compute(counts: Tensor) -> dict[str, Tensor]:
    """Usage, overlap and per-dataset shared share from a ``[D, K]`` histogram."""
    num_codes = counts.shape[1]
    used = counts > 0
    shared = used.all(dim=0)
    frames = counts.sum(dim=1)
    return {
        "usage": used.any(dim=0).sum() / num_codes,
        "overlap": shared.sum() / num_codes,
        "per_dataset": (counts * shared).sum(dim=1) / frames,
    }


def manifold_overlap(codes: Sequence[Tensor], num_codes: int) -> dict[str, float | list[float]]:
    r"""Codebook usage and overlap across datasets (WalkTheDog Table 2).

    Given, for every dataset ``i``, the codebook index of each of its frames,
    with $U_i$ the set of codes dataset $i$ uses and $K$ the codebook size:

    * ``usage`` = $|\bigcup_i U_i| / K$, share of codes used by any dataset;
    * ``overlap`` = $|\bigcap_i U_i| / K$, share of codes used by every dataset;
    * ``per_dataset[i]`` = share of dataset ``i``'s frames whose code is in
      $\bigcap_i U_i$ (the paper's "percentage of embeddings that lie on a
      shared connected component"; Table 2 prints it in percent).

    Args:
        codes: One 1-D integer tensor per dataset: the code index of every frame.
        num_codes: Codebook size ``K``.

    Returns:
        ``{"usage": float, "overlap": float, "per_dataset": list[float]}``, all in [0, 1].

    Raises:
        MotionError: On non-integer or out-of-range codes, or a dataset without frames.

    Examples:
        >>> import torch
        >>> human = torch.tensor([0, 0, 1, 2])
        >>> dog = torch.tensor([1, 1, 2, 3])
        >>> manifold_overlap([human, dog], num_codes=8)
        {'usage': 0.5, 'overlap': 0.25, 'per_dataset': [0.5, 0.75]}
    """
    counts = _manifold_overlap_update(codes, num_codes)
    empty = (counts.sum(dim=1) == 0).nonzero().flatten().tolist()
    if empty:
        raise fail("manifold_overlap", f"codes[{empty[0]}] is empty; every dataset needs frames")
    out = _manifold_overlap_compute(counts)
    return {
        "usage": float(out["usage"]),
        "overlap": float(out["overlap"]),
        "per_dataset": [float(v) for v in out["per_dataset"]],
    }


# --------------------------------------------------------------------------- bone lengths


def _bone_length_consistency_update(
    preds: Tensor,
    target: Tensor,
    bones: Sequence[tuple[int, int]],
    correction: int = 0,
) -> tuple[Tensor, Tensor]:
    """Sum over (sequence, bone) of the temporal variance of the length ratio, and the count."""
    name = "bone_length_consistency"
    parents, children = check_bones(name, bones)
    check_tensor(name, "preds", preds, min_ndim=3, last_dim=3, layout="[..., T, J, 3]")
    check_tensor(name, "target", target, min_ndim=3, last_dim=3, layout="[..., T, J, 3]")
    check_same_shape(name, preds, target, ("frames", "joints", "xyz"))
    preds, target = promote(preds, target)
    num_joints, frames = preds.shape[-2], preds.shape[-3]
    if max(max(parents), max(children)) >= num_joints:
        raise fail(name, f"bones refer to joints beyond the {num_joints} joints of preds")
    if correction not in (0, 1):
        raise fail(name, f"correction must be 0 (population) or 1 (sample), got {correction!r}")
    if frames <= correction:
        raise fail(name, f"the temporal variance needs more than {correction} frame(s)")

    def lengths(x: Tensor) -> Tensor:
        return torch.linalg.vector_norm(x[..., children, :] - x[..., parents, :], dim=-1)

    len_t = lengths(target)  # [..., T, nb]
    zero = (len_t == 0).flatten(0, -2).any(dim=0).nonzero().flatten().tolist()
    if zero:
        raise fail(name, f"target bone {tuple(bones[zero[0]])} has zero length in some frame")
    variance = torch.var(lengths(preds) / len_t, dim=-2, correction=correction)  # [..., nb]
    return variance.sum(), torch.tensor(variance.numel(), device=variance.device)


def bone_length_consistency(
    preds: Tensor,
    target: Tensor,
    bones: Sequence[tuple[int, int]],
    *,
    correction: int = 0,
) -> Tensor:
    r"""Temporal bone-length consistency (HuMoT Eq. 2).

    For every bone ``b`` of every sequence, the temporal variance of the
    predicted length divided by the ground-truth length, averaged over bones
    (and sequences):

    $$
    \mathrm{BLC} = \frac{1}{B}\sum_b
    \operatorname{Var}_t\Big(\frac{\hat\ell_b(t)}{\ell_b(t)}\Big)
    $$

    Args:
        preds: Predicted global positions ``[..., T, J, 3]`` (leading dims = sequences).
        target: Ground-truth global positions, same shape.
        bones: ``(parent, child)`` joint index pairs, e.g. ``skeleton.bones()``.
        correction: ``0`` population variance (default), ``1`` unbiased sample variance.

    Returns:
        Scalar tensor (0 for perfectly rigid bones, even if they are scaled).

    Raises:
        MotionError: On mismatched shapes, NaN/inf, bad bones or zero-length target bones.

    Examples:
        >>> import torch
        >>> target = torch.tensor([[0.0, 0, 0], [0, 1, 0]]).expand(4, 2, 3)
        >>> preds = target * torch.tensor([1.0, 1.0, 1.0, 3.0])[:, None, None]
        >>> bone_length_consistency(preds, target, [(0, 1)])
        tensor(0.7500)
    """
    return _mean_compute(*_bone_length_consistency_update(preds, target, bones, correction))


# --------------------------------------------------------------------------- point clouds


def _group_ids(
    name: str,
    preds_groups: Tensor | Sequence[Hashable] | None,
    target_groups: Tensor | Sequence[Hashable] | None,
    num_preds: int,
    num_target: int,
    device: torch.device,
) -> tuple[Tensor, Tensor]:
    """Body-group ids of the predicted and target points as two integer tensors."""
    if preds_groups is None and target_groups is None:
        return (
            torch.zeros(num_preds, dtype=torch.long, device=device),
            torch.zeros(num_target, dtype=torch.long, device=device),
        )
    if preds_groups is None or target_groups is None:
        raise fail(name, "give both preds_groups and target_groups, or neither")
    vocabulary: dict[Hashable, int] = {}
    out = []
    for arg, groups, count in (
        ("preds_groups", preds_groups, num_preds),
        ("target_groups", target_groups, num_target),
    ):
        if isinstance(groups, Tensor):
            if groups.is_floating_point() or groups.ndim != 1:
                raise fail(name, f"{arg} must be a 1-D integer tensor or a sequence of labels")
            labels: list[Hashable] = groups.tolist()
        else:
            labels = list(groups)
        if len(labels) != count:
            raise fail(name, f"{arg} has {len(labels)} labels for {count} points")
        out.append(
            torch.tensor(
                [vocabulary.setdefault(g, len(vocabulary)) for g in labels],
                dtype=torch.long,
                device=device,
            )
        )
    return out[0], out[1]


def _temporal_knn_update(
    preds: Tensor,
    target: Tensor,
    preds_groups: Tensor | Sequence[Hashable] | None = None,
    target_groups: Tensor | Sequence[Hashable] | None = None,
    k: int = 8,
    reduction: str = "mean",
) -> tuple[Tensor, Tensor]:
    """Sum of the per-sequence KNN distances, and the number of sequences."""
    name = "temporal_knn_distance"
    check_positive_int(name, "k", k)
    check_choice(name, "reduction", reduction, REDUCTIONS)
    check_tensor(name, "preds", preds, min_ndim=3, last_dim=3, layout="[..., T, N, 3]")
    check_tensor(name, "target", target, min_ndim=3, last_dim=3, layout="[..., T, M, 3]")
    check_same_frames(name, preds, target)
    frames, num_p, num_t = preds.shape[-3], preds.shape[-2], target.shape[-2]
    g_p, g_t = _group_ids(name, preds_groups, target_groups, num_p, num_t, preds.device)
    for group in g_t.unique().tolist():
        available = int((g_p == group).sum())
        if available < k:
            raise fail(
                name,
                f"body group {group} has {available} predicted points, fewer than k={k}",
            )
    preds, target = promote(preds, target)
    p = preds.reshape(-1, frames, num_p, 3)
    t = target.reshape(-1, frames, num_t, 3)
    chunk = max(1, _KNN_CHUNK_ELEMENTS // max(1, p.shape[0] * num_p * num_t))
    delta = p.new_zeros(p.shape[0], num_t, num_p)
    for start in range(0, frames, chunk):
        delta = delta + torch.cdist(
            t[:, start : start + chunk],
            p[:, start : start + chunk],
            compute_mode="donot_use_mm_for_euclid_dist",
        ).sum(dim=1)
    delta = delta.masked_fill(g_t[:, None] != g_p[None, :], float("inf"))
    per_sequence = delta.topk(k, dim=-1, largest=False).values.sum(dim=(-1, -2))
    if reduction == "mean":
        per_sequence = per_sequence / (num_t * k * frames)
    return per_sequence.sum(), torch.tensor(per_sequence.numel(), device=preds.device)


def temporal_knn_distance(
    preds: Tensor,
    target: Tensor,
    *,
    preds_groups: Tensor | Sequence[Hashable] | None = None,
    target_groups: Tensor | Sequence[Hashable] | None = None,
    k: int = 8,
    reduction: str = "mean",
) -> Tensor:
    r"""Temporally consistent KNN point-cloud distance (PC-MRL Eq. 5, Table 2).

    The distance between two point trajectories is the sum over frames of their
    per-frame L2 distance, infinite across body groups:
    $\delta(u_A, u_B) = \sum_t \lVert p_{u_A,t} - p_{u_B,t} \rVert_2$.
    For every reference point ``u_A`` (``target``, the source motion's cloud)
    the ``k`` nearest predicted points ``u_B`` (``preds``, the reconstructed
    motion's cloud) are found by ``delta`` and their distances summed:

    $$
    L_{KNN} = \sum_{u_A}\sum_{u_B \in N_k(u_A)} \delta(u_A, u_B)
    $$

    ``reduction="sum"`` returns this sum (Eq. 5, the training loss);
    ``reduction="mean"`` (default) divides it by ``M * k * T``, the mean
    per-frame distance to a neighbour, which is the scale of the paper's Table 2
    (there in metres and multiplied by 100). Several sequences are averaged.

    Args:
        preds: Predicted point trajectories ``[..., T, N, 3]``.
        target: Reference point trajectories ``[..., T, M, 3]`` (same leading dims and T).
        preds_groups: Body group of every predicted point (``N`` ints or labels such
            as ``"left_arm"``); ``None`` with ``target_groups=None`` means one group.
        target_groups: Body group of every reference point (``M`` entries).
        k: Number of neighbours (8 in the paper).
        reduction: ``"mean"`` or ``"sum"`` (see above).

    Returns:
        Scalar tensor.

    Raises:
        MotionError: On mismatched shapes, NaN/inf, or a body group with fewer than
            ``k`` predicted points.

    Examples:
        >>> import torch
        >>> target = torch.zeros(3, 2, 3)               # 3 frames, 2 points at the origin
        >>> preds = torch.zeros(3, 2, 3)
        >>> preds[:, 1, 0] = 2.0                        # second predicted point 2 units away
        >>> temporal_knn_distance(preds, target, k=1)   # nearest is always the first
        tensor(0.)
        >>> temporal_knn_distance(preds, target, k=2)   # (0 + 2) per frame and point / 2
        tensor(1.)
        >>> temporal_knn_distance(preds, target, k=2, reduction="sum")
        tensor(12.)
    """
    return _mean_compute(
        *_temporal_knn_update(preds, target, preds_groups, target_groups, k, reduction)
    )


# --------------------------------------------------------------------------- end effectors


def _end_effector_update(
    preds: Tensor,
    target: Tensor,
    preds_indices: Sequence[int] | None = None,
    target_indices: Sequence[int] | None = None,
    reduction: str = "sum",
) -> tuple[Tensor, Tensor]:
    """Sum of the per-sequence end-effector errors, and the number of sequences."""
    name = "end_effector_error"
    check_choice(name, "reduction", reduction, REDUCTIONS)
    check_tensor(name, "preds", preds, min_ndim=3, last_dim=3, layout="[..., T, J, 3]")
    check_tensor(name, "target", target, min_ndim=3, last_dim=3, layout="[..., T, J, 3]")
    check_same_frames(name, preds, target)
    preds, target = promote(preds, target)
    idx_p = check_indices(name, "preds_indices", preds_indices)
    idx_t = check_indices(name, "target_indices", target_indices)
    for arg, idx, x in (("preds_indices", idx_p, preds), ("target_indices", idx_t, target)):
        if idx is not None and not all(-x.shape[-2] <= i < x.shape[-2] for i in idx):
            raise fail(name, f"{arg} {idx} out of range for {x.shape[-2]} joints")
    if idx_p is not None:
        preds = preds[..., idx_p, :]
    if idx_t is not None:
        target = target[..., idx_t, :]
    if preds.shape[-2] != target.shape[-2]:
        raise fail(
            name,
            f"{preds.shape[-2]} predicted vs {target.shape[-2]} target end effectors; "
            "give matching preds_indices and target_indices",
        )
    per_pair = torch.linalg.vector_norm(preds - target, dim=-1).mean(dim=-2)  # [..., E]
    per_sequence = per_pair.sum(dim=-1) if reduction == "sum" else per_pair.mean(dim=-1)
    return per_sequence.sum(), torch.tensor(per_sequence.numel(), device=preds.device)


def end_effector_error(
    preds: Tensor,
    target: Tensor,
    *,
    preds_indices: Sequence[int] | None = None,
    target_indices: Sequence[int] | None = None,
    reduction: str = "sum",
) -> Tensor:
    r"""End-effector error between matched joints of two skeletons (PC-MRL Eq. 6).

    $$
    L_{end} = \sum_{(a, b) \in E} \frac{1}{T}\sum_t \lVert \hat p_{b,t} - p_{a,t} \rVert_2
    $$

    over matched end-effector pairs ``E`` (hands, feet, head; see
    ``Skeleton.end_effectors()``), averaged over sequences. ``reduction="sum"``
    (default) sums over pairs as in Eq. 6; ``"mean"`` averages over pairs.

    Args:
        preds: Predicted global positions ``[..., T, J_B, 3]`` (e.g. the retargeted skeleton).
        target: Reference global positions ``[..., T, J_A, 3]``.
        preds_indices: End-effector joints of ``preds``; all joints when ``None``.
        target_indices: The matching joints of ``target``, same order and length.
        reduction: ``"sum"`` or ``"mean"`` over pairs.

    Returns:
        Scalar tensor.

    Raises:
        MotionError: On mismatched shapes, NaN/inf or unmatched index lists.

    Examples:
        >>> import torch
        >>> target = torch.zeros(2, 5, 3)               # 2 frames, 5 joints
        >>> preds = torch.zeros(2, 3, 3)                # 2 frames, 3 joints
        >>> preds[1, 2, 1] = 4.0                        # joint 2 is off by 4 in frame 1
        >>> end_effector_error(preds, target, preds_indices=[1, 2], target_indices=[3, 4])
        tensor(2.)
    """
    return _mean_compute(
        *_end_effector_update(preds, target, preds_indices, target_indices, reduction)
    )
