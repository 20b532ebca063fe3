"""Every metric class under DDP: 2 gloo processes on CPU vs one process.

Each rank updates with its own (uneven) shard of the batches; ``compute()``
synchronises the ``dist_reduce_fx="sum"`` states, so both ranks must return
exactly what one process gets from all the batches.
"""

from __future__ import annotations

import datetime
from pathlib import Path

import pytest
import torch
import torch.distributed as dist
import torch.multiprocessing as mp
from torchmetrics.utilities.data import dim_zero_sum

from skelagnostic.metrics import (
    L2P,
    L2Q,
    MPJPE,
    NPSS,
    BoneLengthConsistency,
    EndEffectorError,
    FootSkate,
    FootSkateRatio,
    ManifoldOverlap,
    TemporalKNNDistance,
)

WORLD_SIZE = 2


def _quats(gen: torch.Generator, b: int, t: int, j: int) -> torch.Tensor:
    drift = 0.1 * torch.randn(b, t, j, 4, generator=gen, dtype=torch.float64).cumsum(1)
    return torch.nn.functional.normalize(drift + torch.randn(b, 1, j, 4, generator=gen), dim=-1)


def cases() -> dict[str, tuple]:
    """name -> (metric factory, list of (args, kwargs) batches); deterministic."""
    gen = torch.Generator().manual_seed(1234)

    def pos(b: int, t: int = 6, j: int = 5) -> torch.Tensor:
        return torch.randn(b, t, j, 3, generator=gen, dtype=torch.float64)

    def pair(b: int, t: int = 6, j: int = 5) -> tuple[torch.Tensor, torch.Tensor]:
        target = pos(b, t, j)
        return target + 0.2 * pos(b, t, j), target

    def qpair(b: int, t: int = 12) -> tuple[torch.Tensor, torch.Tensor]:
        target = _quats(gen, b, t, 3)
        return torch.nn.functional.normalize(target + 0.2 * _quats(gen, b, t, 3), dim=-1), target

    sizes = (3, 1, 2)  # three batches of different sizes: rank 0 gets two, rank 1 one
    mask = torch.zeros(3, 12, dtype=torch.bool)
    mask[:, 4:9] = True
    mask[1, 9] = True
    out: dict[str, tuple] = {}
    for mode in ("plain", "root", "procrustes"):
        out[f"mpjpe_{mode}"] = (
            lambda mode=mode: MPJPE(mode=mode),
            [(pair(b), {}) for b in sizes],
        )
    out["mpjpe_height"] = (
        lambda: MPJPE(normalize_by_height=True),
        [(pair(b), {"height": 1.0 + torch.rand(b, generator=gen)}) for b in sizes],
    )
    stats = (torch.randn(15, generator=gen), 1.0 + torch.rand(15, generator=gen))
    out["l2p"] = (lambda: L2P(*stats), [(pair(b), {"mask": mask[:b, :6]}) for b in sizes])
    out["l2q"] = (L2Q, [(qpair(b), {"mask": mask[:b]}) for b in sizes])
    out["npss_real"] = (NPSS, [(qpair(b), {}) for b in sizes])
    out["npss_abs_masked"] = (
        lambda: NPSS(power="abs"),
        [(qpair(b), {"mask": mask[:b]}) for b in sizes],
    )
    out["manifold"] = (
        lambda: ManifoldOverlap(num_codes=16, num_datasets=2),
        [
            ((torch.randint(0, 16, (40,), generator=gen) % (16 - 6 * d),), {"dataset": d})
            for d in (0, 1, 1)
        ],
    )
    bones = [(0, 1), (1, 2), (1, 3), (3, 4)]
    out["bone_length"] = (lambda: BoneLengthConsistency(bones), [(pair(b), {}) for b in sizes])
    out["end_effector"] = (
        lambda: EndEffectorError([4, 2], [2, 4]),
        [(pair(b), {}) for b in sizes],
    )

    def planted(b: int) -> torch.Tensor:
        return torch.rand(b, 6, 5, generator=gen) < 0.6

    out["foot_skate"] = (
        lambda: FootSkate(fps=30.0, feet=[1, 3]),
        [((pos(b), planted(b)[..., :2]), {}) for b in sizes],
    )
    out["foot_skate_ratio"] = (
        lambda: FootSkateRatio(fps=30.0, threshold=30.0, up_axis="z"),
        [((pos(b), planted(b)), {}) for b in sizes],
    )
    groups = [i % 3 for i in range(12)]
    out["temporal_knn"] = (
        lambda: TemporalKNNDistance(k=2),
        [((*pair(b, 4, 12),), {"preds_groups": groups, "target_groups": groups}) for b in sizes],
    )
    return out


def _as_python(value: torch.Tensor | dict[str, torch.Tensor]) -> list[float]:
    if isinstance(value, dict):  # ManifoldOverlap
        return [value["usage"].item(), value["overlap"].item(), *value["per_dataset"].tolist()]
    return [value.item()]


def run(rank: int | None) -> dict[str, object]:
    """Update with this rank's shard (every batch when ``rank`` is None) and compute."""
    results = {}
    for name, (factory, batches) in cases().items():
        metric = factory()
        for i, (args, kwargs) in enumerate(batches):
            if rank is None or i % WORLD_SIZE == rank:
                metric.update(*args, **kwargs)
        results[name] = _as_python(metric.compute())
    return results


def _worker(rank: int, init_file: str, out_dir: str) -> None:
    torch.set_num_threads(1)
    dist.init_process_group(
        "gloo",
        init_method=f"file://{init_file}",
        rank=rank,
        world_size=WORLD_SIZE,
        timeout=datetime.timedelta(seconds=60),
    )
    try:
        torch.save(run(rank), Path(out_dir) / f"rank{rank}.pt")
    finally:
        dist.destroy_process_group()


@pytest.mark.skipif(not dist.is_available(), reason="torch.distributed is not available")
def test_two_gloo_processes_match_one_process(tmp_path):
    single = run(None)  # also imports everything the workers need before the fork
    # fork (not spawn): the workers inherit the imported modules and start in milliseconds
    mp.start_processes(
        _worker,
        args=(str(tmp_path / "init"), str(tmp_path)),
        nprocs=WORLD_SIZE,
        join=True,
        start_method="fork",
    )
    for rank in range(WORLD_SIZE):
        ddp = torch.load(tmp_path / f"rank{rank}.pt")
        assert ddp.keys() == single.keys()
        for name, expected in single.items():
            assert ddp[name] == pytest.approx(expected, rel=1e-6), (name, rank)
    # the shards really are partial: rank 1 alone would give other values
    assert run(1)["npss_real"] != pytest.approx(single["npss_real"], rel=1e-6)


def test_every_state_is_sum_reduced():
    for factory, _ in cases().values():
        metric = factory()
        assert metric._reductions, type(metric).__name__
        assert all(fn is dim_zero_sum for fn in metric._reductions.values())
        assert metric.full_state_update is False
        assert isinstance(metric.higher_is_better, bool)
        assert isinstance(metric.is_differentiable, bool)
