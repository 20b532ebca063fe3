"""humot.ablations: the per-clip MPJPE, bone-length consistency and baselines in numpy.

The protocol retrains the three variants 2 steps on procedural biped31 clips
(whose zero-length hip bones the bone-length metric must leave out); the test
captures the variants it trains and recomputes, for the checkpoint and each
variant, ``mpjpe_cm`` and ``blc_x1e3`` (HuMoT Eq. 2: per bone and chunk the
population variance over time of predicted / true length, mean over bones and
chunks, x1000) from its own numpy chunks, plus the two mean-pose baselines.
Taken from the library: the networks (the methods), the per-chunk templates
they are given and the major-joint mask. ``upsampling_half_cm`` is not
recomputed: the random half of the joints is drawn inside the protocol.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from skelagnostic_humot import ablations
from skelagnostic_humot.aligner import HumotAligner
from skelagnostic_humot.data import HumotDataModule, prepare_chunks

from numpy_reference import global_pose, humot_chunks, mpjpe
from skelagnostic.data import ProceduralSource
from skelagnostic.evaluation import MODEL, held_out


def _blc(pred: np.ndarray, true: np.ndarray, parents: list[int]) -> float:
    """Eq. 2 over the bones of non-zero true length in every frame, mean over chunks."""
    terms = []
    for c, p in enumerate(parents):
        if p < 0:
            continue
        true_len = np.linalg.norm(true[..., c, :] - true[..., p, :], axis=-1)
        if not (true_len > 1e-6).all():
            continue
        ratio = np.linalg.norm(pred[..., c, :] - pred[..., p, :], axis=-1) / true_len
        terms.append(ratio.var(axis=-1))  # [C]: over the frames of each chunk
    return float(np.mean(terms))


def _figures(model: HumotAligner, clip: Any) -> dict[str, float]:
    topo = model.topology(clip.skeleton)
    chunks = humot_chunks(global_pose(clip)[1], topo.major.numpy())
    _, tmpl = prepare_chunks(torch.from_numpy(chunks).float(), topo)
    with torch.no_grad():
        out = model.net(torch.from_numpy(chunks).float(), tmpl, tmpl, None).double().numpy()
    return {
        "mpjpe_cm": 100 * mpjpe(out, chunks),
        "blc_x1e3": 1000 * _blc(out, chunks, list(clip.skeleton.parents)),
    }


def test_rows_equal_an_independent_computation(
    tmp_path: Path, humot_small: dict[str, int], monkeypatch: pytest.MonkeyPatch
) -> None:
    source = ProceduralSource(kinds=["biped31"], gaits=["walk"], clips_per_gait=3, seconds=2.0)
    dm = HumotDataModule(
        [source], cache_dir=tmp_path / "cache", batch_size=4, val_fraction=0.0, test_fraction=0.34
    )
    held = held_out(dm)
    trained: dict[str, HumotAligner] = {}

    def capture(hparams: Any, changes: Any, *args: Any, **kwargs: Any) -> HumotAligner:
        model = train_variant(hparams, changes, *args, **kwargs)
        name = next(n for n, c in ablations.ABLATIONS.items() if dict(c) == dict(changes))
        trained[name] = model
        return model

    train_variant = ablations.train_variant
    monkeypatch.setattr(ablations, "train_variant", capture)
    torch.manual_seed(0)
    model = HumotAligner(**humot_small).eval()
    with torch.no_grad():
        out = ablations.ablation_protocol(model, held, tmp_path, steps=2)
    assert set(trained) == set(ablations.ABLATIONS)
    assert [r["clip"] for r in out.rows] == held.names
    for row, clip in zip(out.rows, held.clips, strict=True):
        values = row["values"]
        for name, net in {MODEL: model, **trained}.items():
            want = _figures(net, clip)
            for metric, value in want.items():
                assert values[name][metric] == pytest.approx(value, rel=1e-4), (name, metric)
        chunks = humot_chunks(global_pose(clip)[1], model.topology(clip.skeleton).major.numpy())
        assert row["chunks"] == len(chunks) == 2
        root = chunks[:, :, :1]
        static = np.broadcast_to(chunks.mean(axis=1, keepdims=True), chunks.shape)
        on_path = (chunks - root).mean(axis=1, keepdims=True) + root
        assert values["mean_pose"]["mpjpe_cm"] == pytest.approx(100 * mpjpe(static, chunks))
        assert values["mean_pose_on_trajectory"]["mpjpe_cm"] == pytest.approx(
            100 * mpjpe(on_path, chunks)
        )
