"""Codebook usage and overlap across datasets as a function (WalkTheDog manifold overlap).

The functional twin of :mod:`skelagnostic.metrics.manifold`.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from skelagnostic.metrics._checks import (
    check_positive_int,
    fail,
)

__all__ = ["manifold_overlap"]


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
