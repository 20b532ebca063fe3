"""PC-MRL parity with the authors' code (issue #26 items 4-5), from committed fixtures.

The fixtures under ``tests/fixtures/pcmrl`` were written by
``scripts/pcmrl_authors_fixtures.py``, which runs the authors' ``KNNLoss`` and
``eval_inpainter.py`` (github.com/MiniEval/PC-MRL); the tests need neither.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from skelagnostic_pcmrl.losses import authors_alpha, authors_knn_terms, temporal_knn_loss

from skelagnostic.errors import SkelagnosticError

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "pcmrl"


def _load(name: str) -> dict:
    return torch.load(FIXTURES / name, weights_only=False)


KNN = _load("authors_knn.pt")["cases"]


@pytest.mark.parametrize("case", range(len(KNN)))
def test_knn_terms_and_gradients_equal_the_authors(case: int) -> None:
    c = KNN[case]
    dtype = getattr(torch, c["dtype"])
    target = c["expected"].to(dtype)
    for i, name in enumerate(("glob", "norm", "vel")):
        preds = c["actual"].to(dtype).requires_grad_(True)
        terms = authors_knn_terms(preds, target, c["actual_groups"], c["expected_groups"], c["k"])
        assert float(terms[i].detach()) == pytest.approx(float(c[name]), abs=1e-5, rel=1e-6)
        (grad,) = torch.autograd.grad(terms[i], preds)
        ref = c[f"grad_{name}"].to(dtype)
        assert torch.allclose(grad, ref, atol=1e-8, rtol=1e-5), (name, (grad - ref).abs().max())


def test_knn_loss_authors_variant_is_their_weighted_sum() -> None:
    c = KNN[1]
    args = (
        c["actual"].double(),
        c["expected"].double(),
        c["actual_groups"],
        c["expected_groups"],
        c["k"],
    )
    total = float(c["glob"]) + 0.25 * float(c["norm"]) + float(c["vel"])
    loss = temporal_knn_loss(*args[:4], k=c["k"], variant="authors", alpha=0.25)
    assert float(loss) == pytest.approx(total, abs=1e-6)
    m = c["expected"].shape[2]
    loss_sum = temporal_knn_loss(
        *args[:4], k=c["k"], variant="authors", reduction="sum", alpha=0.25
    )
    assert float(loss_sum) == pytest.approx(total * m * c["k"], rel=1e-9)


def test_knn_terms_per_sequence_groups_equal_one_sequence_at_a_time() -> None:
    """Sequences with their own groups: the batch mean of each sequence on its own."""
    c = KNN[0]
    preds, target = c["actual"].double(), c["expected"].double()
    g_p = torch.stack([c["actual_groups"], c["actual_groups"].roll(1)])
    g_t = torch.stack([c["expected_groups"], c["expected_groups"].roll(2)])
    both = authors_knn_terms(preds, target, g_p, g_t, c["k"])
    single = [
        authors_knn_terms(preds[b : b + 1], target[b : b + 1], g_p[b], g_t[b], c["k"])
        for b in range(2)
    ]
    for i in range(3):
        assert float(both[i]) == pytest.approx((float(single[0][i]) + float(single[1][i])) / 2)


def test_knn_terms_reject_a_group_smaller_than_k() -> None:
    c = KNN[2]
    with pytest.raises(SkelagnosticError, match="fewer than k"):
        authors_knn_terms(
            c["actual"],
            c["expected"],
            c["actual_groups"],
            c["expected_groups"],
            k=c["actual"].shape[2],
        )


def test_authors_alpha_schedule() -> None:
    assert authors_alpha(250, 500, 50000) == pytest.approx(0.5)
    assert authors_alpha(500, 500, 50000) == pytest.approx(1.0)
    assert authors_alpha(25250, 500, 50000) == pytest.approx(0.5)
    assert authors_alpha(50000, 500, 50000) == 0.0
    assert authors_alpha(10, 0, 100) == 1.0
