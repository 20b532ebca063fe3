"""Manifold overlap (WalkTheDog Table 2): usage, overlap, per-dataset shared share."""

from __future__ import annotations

import pytest
import torch

from skelagnostic.errors import MotionError
from skelagnostic.metrics import ManifoldOverlap
from skelagnostic.metrics.functional import manifold_overlap


def reference(codes: list[list[int]], num_codes: int) -> dict:
    """Plain-Python sets, straight from the definitions."""
    used = [set(c) for c in codes]
    shared = set.intersection(*used)
    return {
        "usage": len(set.union(*used)) / num_codes,
        "overlap": len(shared) / num_codes,
        "per_dataset": [sum(x in shared for x in c) / len(c) for c in codes],
    }


def test_hand_computed():
    out = manifold_overlap([torch.tensor([0, 0, 1, 2]), torch.tensor([1, 1, 2, 3])], num_codes=8)
    assert out == {"usage": 0.5, "overlap": 0.25, "per_dataset": [0.5, 0.75]}
    full = manifold_overlap([torch.tensor([0, 1]), torch.tensor([1, 0]), torch.tensor([0, 1])], 2)
    assert full == {"usage": 1.0, "overlap": 1.0, "per_dataset": [1.0, 1.0, 1.0]}
    disjoint = manifold_overlap([torch.tensor([0]), torch.tensor([1])], 4)
    assert disjoint == {"usage": 0.5, "overlap": 0.0, "per_dataset": [0.0, 0.0]}


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_against_sets(seed):
    gen = torch.Generator().manual_seed(seed)
    num_codes = 32
    codes = [
        torch.randint(0, num_codes, (n,), generator=gen) % limit
        for n, limit in ((500, 32), (300, 20), (50, 12))
    ]
    expected = reference([c.tolist() for c in codes], num_codes)
    out = manifold_overlap(codes, num_codes)
    assert out["usage"] == pytest.approx(expected["usage"])
    assert out["overlap"] == pytest.approx(expected["overlap"])
    assert out["per_dataset"] == pytest.approx(expected["per_dataset"])

    metric = ManifoldOverlap(num_codes, num_datasets=3)
    for i, c in enumerate(codes):  # one dataset per update, split in two batches
        metric.update(c[: len(c) // 2], dataset=i)
        metric.update(c[len(c) // 2 :], dataset=i)
    result = metric.compute()
    assert result["usage"].item() == pytest.approx(expected["usage"])
    assert result["overlap"].item() == pytest.approx(expected["overlap"])
    assert result["per_dataset"].tolist() == pytest.approx(expected["per_dataset"])

    both = ManifoldOverlap(num_codes, num_datasets=3)
    both.update(codes)  # all datasets in one call
    assert torch.equal(both.counts, metric.counts)


def test_unseen_dataset_gives_nan_in_the_class():
    metric = ManifoldOverlap(4, 2)
    batch_value = metric(torch.tensor([0, 1]), dataset=0)  # forward: only dataset 0 seen
    assert batch_value["overlap"].item() == 0.0
    assert torch.isnan(batch_value["per_dataset"][1])


def test_errors():
    with pytest.raises(MotionError, match=r"codes\[1\] holds codes in \[0, 9\]"):
        manifold_overlap([torch.tensor([0]), torch.tensor([0, 9])], 8)
    with pytest.raises(MotionError, match=r"codes\[0\] must be an integer tensor"):
        manifold_overlap([torch.tensor([0.0])], 8)
    with pytest.raises(MotionError, match=r"1-D"):
        manifold_overlap([torch.zeros(2, 2, dtype=torch.long)], 8)
    with pytest.raises(MotionError, match=r"codes\[1\] is empty"):
        manifold_overlap([torch.tensor([0]), torch.tensor([], dtype=torch.long)], 8)
    with pytest.raises(MotionError, match=r"num_codes must be a positive integer"):
        manifold_overlap([torch.tensor([0])], 0)
    with pytest.raises(MotionError, match=r"at least one dataset"):
        manifold_overlap([], 4)
    metric = ManifoldOverlap(4, 2)
    with pytest.raises(MotionError, match=r"dataset must be in \[0, 2\)"):
        metric.update(torch.tensor([0]), dataset=2)
    with pytest.raises(MotionError, match=r"needs its dataset index"):
        metric.update(torch.tensor([0]))
    with pytest.raises(MotionError, match=r"expected codes of 2 datasets, got 3"):
        metric.update([torch.tensor([0])] * 3)
    with pytest.raises(MotionError, match=r"only used with a single codes tensor"):
        metric.update([torch.tensor([0])] * 2, dataset=0)
    with pytest.raises(MotionError, match=r"num_datasets"):
        ManifoldOverlap(4, 0)
    assert metric.higher_is_better is True and metric.is_differentiable is False
