"""PC-MRL parity with the authors' code (issue #26 items 4-5), from committed fixtures.

The fixtures under ``tests/fixtures/pcmrl`` were written by
``scripts/fixtures/pcmrl_authors_fixtures.py``, which runs the authors' ``KNNLoss`` and
``eval_inpainter.py`` (github.com/MiniEval/PC-MRL); the tests need neither.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from skelagnostic_pcmrl.interp.evaluation import authors_table1, keyframe_centre
from skelagnostic_pcmrl.recon.losses import authors_alpha, authors_knn_terms, temporal_knn_loss

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


def test_knn_terms_in_float32_are_within_1e5_of_the_authors() -> None:
    for c in KNN:
        with torch.no_grad():
            terms = authors_knn_terms(
                c["actual"].float(),
                c["expected"].float(),
                c["actual_groups"],
                c["expected_groups"],
                c["k"],
            )
        for value, name in zip(terms, ("glob", "norm", "vel"), strict=True):
            assert float(value) == pytest.approx(float(c[name]), abs=1e-5)


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


TABLE1 = _load("authors_table1.pt")


@pytest.mark.parametrize("run", range(len(TABLE1["runs"])))
def test_table1_metrics_equal_the_authors_eval(run: int) -> None:
    """L2P, L2Q, NPSS and the keyframe centre of their eval_inpainter.py."""
    r = TABLE1["runs"][run]
    tpos = TABLE1["target_positions"].double()
    trot = TABLE1["target_rotations"].double()
    valid = TABLE1["valid_joints"]
    centre = keyframe_centre(tpos, r["keys"], valid)
    assert torch.allclose(centre, r["centre"].double(), atol=1e-5)
    out = authors_table1(
        r["pred_positions"].double(), r["pred_rotations"].double(), tpos, trot, r["keys"], valid
    )
    for name in ("l2p", "l2q", "npss"):
        assert out[name] == pytest.approx(r[name], abs=1e-5), name
    # the centre matters for NPSS (positions' spectra), not for L2P and L2Q
    off = authors_table1(
        r["pred_positions"].double(), r["pred_rotations"].double(), tpos, trot, r["keys"], None
    )
    assert off["l2p"] == pytest.approx(out["l2p"], abs=1e-9)
    assert abs(off["npss"] - out["npss"]) > 1e-4


def test_table1_pastes_the_keys_of_the_target() -> None:
    r = TABLE1["runs"][0]
    keys = r["keys"]
    tpos = TABLE1["target_positions"].double()
    trot = TABLE1["target_rotations"].double()
    pos, rot = r["pred_positions"].double().clone(), r["pred_rotations"].double().clone()
    ref = authors_table1(pos, rot, tpos, trot, keys, TABLE1["valid_joints"])
    pos[:, keys] += 3.0
    rot[:, keys] = -rot[:, keys]
    assert authors_table1(pos, rot, tpos, trot, keys, TABLE1["valid_joints"]) == pytest.approx(ref)
    with pytest.raises(SkelagnosticError, match="keyframe"):
        authors_table1(pos, rot, tpos, trot, torch.zeros_like(keys), None)
    with pytest.raises(SkelagnosticError, match="rotations"):
        authors_table1(pos, rot[..., :3], tpos, trot, keys, None)
