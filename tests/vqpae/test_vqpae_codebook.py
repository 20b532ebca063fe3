"""The shared codebook: quantisation, the re-initialisation rule by hand, and DDP agreement."""

from __future__ import annotations

import datetime
import math
from pathlib import Path

import pytest
import torch
import torch.distributed as dist
import torch.multiprocessing as mp
from skelagnostic_vqpae.codebook import (
    SharedCodebook,
    reinit_alpha,
    reinit_probabilities,
    reinit_update,
)

from skelagnostic.errors import SkelagnosticError

GAMMA, EPS = 0.99, 1e-3


def _book(weight: list[list[float]], datasets: int = 1, **kwargs: object) -> SharedCodebook:
    book = SharedCodebook(len(weight), len(weight[0]), datasets, **kwargs)  # type: ignore[arg-type]
    book.weight.data = torch.tensor(weight)
    return book


class TestQuantize:
    def test_init_is_uniform_in_one_over_k(self) -> None:
        book = SharedCodebook(16, 20, 2)
        assert float(book.weight.detach().abs().max()) <= 1 / 16
        assert float(book.weight.detach().std()) > 0.25 / 16

    def test_nearest_entry_and_loss(self) -> None:
        book = _book([[0.0, 0.0], [1.0, 0.0], [0.0, 2.0]], beta=0.25)
        raw = torch.tensor([[0.9, 0.1], [0.1, 1.6], [-0.2, 0.1]])
        amp, codes, loss = book.quantize(raw)
        assert codes.tolist() == [1, 2, 0]
        sq = (book.weight.detach()[codes] - raw).square().mean()
        assert math.isclose(float(loss.detach()), 1.25 * float(sq), rel_tol=1e-6)
        assert torch.allclose(amp, book.weight.detach()[codes])

    def test_rejects_wrong_width_and_dataset(self) -> None:
        book = SharedCodebook(4, 6, 2)
        with pytest.raises(SkelagnosticError, match="end in 6"):
            book.quantize(torch.zeros(3, 5))
        with pytest.raises(SkelagnosticError, match="dataset"):
            book.quantize(torch.zeros(3, 6), dataset=2)

    @pytest.mark.parametrize("kwargs", [{"num_codes": 0}, {"dim": -1}, {"decay": 1.0}])
    def test_rejects_bad_arguments(self, kwargs: dict[str, float]) -> None:
        args = {"num_codes": 4, "dim": 2, **kwargs}
        with pytest.raises(SkelagnosticError, match=next(iter(kwargs))):
            SharedCodebook(**args)  # type: ignore[arg-type]


class TestReinitRule:
    def test_alpha(self) -> None:
        usage = torch.tensor([0.0, 1e-4, 0.01])
        want = [math.exp(-u * 32 * 10 / (1 - GAMMA) - EPS) for u in usage.tolist()]
        assert reinit_alpha(usage, 32, GAMMA, EPS).tolist() == pytest.approx(want, rel=1e-6)

    def test_probabilities_follow_exp_minus_distance(self) -> None:
        book = torch.tensor([[0.0, 0.0], [3.0, 4.0]])
        raw = torch.tensor([[0.0, 0.0], [0.0, 1.0], [3.0, 0.0]])
        probs = reinit_probabilities(book, raw)
        d = torch.tensor([[0.0, 1.0, 3.0], [5.0, math.sqrt(18), 4.0]])
        assert torch.allclose(probs, torch.softmax(-d, 1), atol=1e-6)
        sq = reinit_probabilities(book, raw, squared_distance=True)
        assert torch.allclose(sq, torch.softmax(-d.square(), 1), atol=1e-6)

    def test_one_dataset_by_hand(self) -> None:
        book = _book([[0.0, 0.0], [1.0, 1.0], [5.0, 5.0]])
        raw = torch.tensor([[0.2, 0.1], [-0.1, 0.0], [0.1, 0.1], [0.9, 1.2]])
        book.train()
        _, codes, _ = book.quantize(raw, dataset=0)
        assert codes.tolist() == [0, 0, 0, 1]
        old = book.weight.detach().clone()
        # the draw: with a fixed generator, replay it by hand
        probs = torch.cdist(old.double(), raw.double()).neg().softmax(1)
        pick = torch.multinomial(probs, 1, generator=torch.Generator().manual_seed(0)).view(-1)
        assert book.reinitialize()
        usage = (1 - GAMMA) * torch.tensor([3 / 4, 1 / 4, 0.0])
        assert torch.allclose(book.usage[0], usage)
        alpha = torch.exp(-usage * 3 * 10 / (1 - GAMMA) - EPS)[:, None]
        want = (1 - alpha) * old + alpha * raw[pick]
        assert torch.allclose(book.weight.detach(), want, atol=1e-6)
        # the unused entry moved almost all the way to a raw amplitude, the used ones stayed
        assert float((book.weight.detach()[2] - raw[pick[2]]).norm()) < 0.01
        assert torch.allclose(book.weight.detach()[:2], old[:2], atol=1e-3)

    def test_two_datasets_average_their_updates_and_ema_accumulates(self) -> None:
        book = _book([[0.0], [10.0]], datasets=2)
        book.usage[1] = torch.tensor([0.2, 0.0])
        book.train()
        book.quantize(torch.tensor([[1.0]]), dataset=0)  # one raw amplitude: Z is certain
        book.quantize(torch.tensor([[9.0]]), dataset=1)
        old = book.weight.detach().clone()
        assert book.reinitialize()
        n0 = (1 - GAMMA) * torch.tensor([1.0, 0.0])
        n1 = GAMMA * torch.tensor([0.2, 0.0]) + (1 - GAMMA) * torch.tensor([0.0, 1.0])
        assert torch.allclose(book.usage, torch.stack([n0, n1]))
        a0 = torch.exp(-n0 * 2 * 10 / (1 - GAMMA) - EPS)[:, None]
        a1 = torch.exp(-n1 * 2 * 10 / (1 - GAMMA) - EPS)[:, None]
        want = 0.5 * (((1 - a0) * old + a0 * 1.0) + ((1 - a1) * old + a1 * 9.0))
        assert torch.allclose(book.weight.detach(), want, atol=1e-6)

    def test_reinit_update_matches_the_module(self) -> None:
        torch.manual_seed(0)
        raws = [torch.randn(5, 3), torch.randn(7, 3)]
        usages = [torch.rand(4) * 0.01, torch.zeros(4)]
        weight = torch.randn(4, 3)
        a = reinit_update(weight, usages, raws, torch.Generator().manual_seed(5))
        b = reinit_update(weight, usages, raws, torch.Generator().manual_seed(5))
        assert torch.equal(a, b)
        assert a.shape == (4, 3)

    def test_disabled_switch_leaves_the_codebook_alone(self) -> None:
        book = _book([[0.0, 0.0], [5.0, 5.0]], reinit=False)
        book.train()
        book.quantize(torch.randn(4, 2), dataset=0)
        old = book.weight.detach().clone()
        assert not book.reinitialize()
        assert torch.equal(book.weight.detach(), old)
        assert float(book.usage.abs().sum()) == 0.0

    def test_eval_mode_keeps_nothing(self) -> None:
        book = _book([[0.0, 0.0], [5.0, 5.0]])
        book.eval()
        book.quantize(torch.randn(4, 2), dataset=0)
        assert not book.reinitialize()


# ----------------------------------------------------------------------------- DDP
WORLD = 2


def _shards() -> list[torch.Tensor]:
    gen = torch.Generator().manual_seed(11)
    return [torch.randn(5, 4, generator=gen) * 0.5, torch.randn(3, 4, generator=gen) + 2.0]


def _fresh() -> SharedCodebook:
    torch.manual_seed(3)
    book = SharedCodebook(6, 4, 1, seed=7)
    book.train()
    return book


def _step(book: SharedCodebook, raw: torch.Tensor) -> torch.Tensor:
    book.quantize(raw, dataset=0)
    book.reinitialize()
    return book.weight.detach().clone()


def _worker(rank: int, init_file: str, out_dir: str) -> None:
    torch.set_num_threads(1)
    dist.init_process_group(
        "gloo",
        init_method=f"file://{init_file}",
        rank=rank,
        world_size=WORLD,
        timeout=datetime.timedelta(seconds=60),
    )
    try:
        book = _fresh()
        weights = [_step(book, _shards()[rank]), _step(book, _shards()[1 - rank] * 0.3)]
        torch.save(
            {"weights": weights, "usage": book.usage.clone()}, Path(out_dir) / f"rank{rank}.pt"
        )
    finally:
        dist.destroy_process_group()


@pytest.mark.skipif(not dist.is_available(), reason="torch.distributed is not available")
def test_ddp_ranks_apply_the_same_update_as_one_process(tmp_path: Path) -> None:
    shards = _shards()
    single = _fresh()
    # one process seeing every rank's amplitudes, in rank order
    want = [
        _step(single, torch.cat(shards)),
        _step(single, torch.cat([shards[1] * 0.3, shards[0] * 0.3])),
    ]
    mp.start_processes(
        _worker,
        args=(str(tmp_path / "init"), str(tmp_path)),
        nprocs=WORLD,
        join=True,
        start_method="fork",
    )
    results = [torch.load(tmp_path / f"rank{r}.pt") for r in range(WORLD)]
    for res in results:
        for got, expected in zip(res["weights"], want, strict=True):
            assert torch.allclose(got, expected, atol=1e-6)
        assert torch.allclose(res["usage"], single.usage)
    assert torch.equal(results[0]["weights"][1], results[1]["weights"][1])
    # a rank alone would have seen other statistics
    alone = _fresh()
    assert not torch.allclose(_step(alone, shards[0]), want[0], atol=1e-6)
