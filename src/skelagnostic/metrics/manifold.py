"""Codebook usage and overlap across datasets (WalkTheDog manifold overlap)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch
from torch import Tensor
from torchmetrics import Metric

from skelagnostic.metrics._checks import check_positive_int, fail
from skelagnostic.metrics.functional.manifold import (
    _manifold_overlap_compute,
    _manifold_overlap_update,
)

__all__ = ["ManifoldOverlap"]


class ManifoldOverlap(Metric):
    """Share of codebook entries used by any / every dataset, and per-dataset shared share.

    See [`manifold_overlap`][skelagnostic.metrics.functional.manifold_overlap]. The state is a
    per-dataset code histogram ``[num_datasets, num_codes]`` summed across
    batches and DDP ranks, so the result is exact.

    `compute()` returns tensors: ``usage`` and ``overlap`` (scalars) and
    ``per_dataset`` (``[num_datasets]``). A dataset that has not been seen yet
    has no codes, so ``overlap`` is 0 and its ``per_dataset`` entry is NaN (this
    is also what ``forward`` reports for a batch holding one dataset only).

    Args:
        num_codes: Codebook size ``K``.
        num_datasets: Number of datasets (characters) sharing the codebook.
        **kwargs: Passed to `torchmetrics.Metric`.

    Examples:
        >>> import torch
        >>> metric = ManifoldOverlap(num_codes=4, num_datasets=2)
        >>> metric.update(torch.tensor([0, 1, 1]), dataset=0)     # e.g. the human batch
        >>> metric.update(torch.tensor([1, 2]), dataset=1)        # the dog batch
        >>> out = metric.compute()
        >>> float(out["usage"]), float(out["overlap"]), out["per_dataset"].tolist()
        (0.75, 0.25, [0.6666666865348816, 0.5])
    """

    is_differentiable = False
    higher_is_better = True
    full_state_update = False
    plot_lower_bound = 0.0
    plot_upper_bound = 1.0
    counts: Tensor

    def __init__(self, num_codes: int, num_datasets: int, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        check_positive_int("ManifoldOverlap", "num_codes", num_codes)
        check_positive_int("ManifoldOverlap", "num_datasets", num_datasets)
        self.num_codes = num_codes
        self.num_datasets = num_datasets
        self.add_state(
            "counts", torch.zeros(num_datasets, num_codes, dtype=torch.long), dist_reduce_fx="sum"
        )

    def update(self, codes: Tensor | Sequence[Tensor], dataset: int | None = None) -> None:
        """Count the code index of every frame.

        Args:
            codes: Either a 1-D integer tensor of one dataset's codes (then give
                ``dataset``), or one such tensor per dataset (then leave ``dataset`` out).
            dataset: Index of the dataset ``codes`` belongs to.
        """
        if not isinstance(codes, Tensor) and dataset is not None:
            raise fail("ManifoldOverlap", "dataset is only used with a single codes tensor")
        counts = _manifold_overlap_update(codes, self.num_codes, dataset, self.num_datasets)
        self.counts += counts.to(self.counts.device)

    def compute(self) -> dict[str, Tensor]:
        """``{"usage": Tensor, "overlap": Tensor, "per_dataset": Tensor [num_datasets]}``."""
        return _manifold_overlap_compute(self.counts)
