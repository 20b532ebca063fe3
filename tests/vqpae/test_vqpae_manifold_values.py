"""vqpae.manifold: the code and phase figures recomputed independently in numpy.

A VQ-PAE trained 3 steps on procedural biped22 and quadruped clips (the
existing protocol test's set-up), evaluated on its held-out clips. From each
clip's per-frame codes and phases (the model's embedding, the method's output)
the test recomputes (the codes are replaced by seeded ones that overlap in part,
see :func:`_spread_codes`): the codes every character uses, each clip's share of
frames on them (``shared_code_share``), ``chance`` = shared / K, ``phase_r2``
(R^2 of a least-squares line through the phase unwrapped by hand), Table 2
(codes used per character, shared, used by any, ``shared_of_used``,
``shared_of_own``, ``frame_share``, frames), the overlap figures (usage,
overlap, per character share) and the per-character means. The average-pose
figures (``pose_mpjpe_cm``, ``pose_mpjpe_locomotion_cm``, Table 1) and the
procedural frequency figures are not recomputed here
(``docs/reports/protocol_tests.md`` says why).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from skelagnostic_vqpae.embed import embed_clip
from skelagnostic_vqpae.protocols import manifold as evaluation
from skelagnostic_vqpae.protocols.manifold import manifold_protocol


def _unwrap(phase: np.ndarray) -> np.ndarray:
    """Phase in cycles made continuous: each step taken as the nearest equivalent (mod 1)."""
    steps = np.diff(phase)
    steps = steps - np.round(steps)
    return np.concatenate([[phase[0]], phase[0] + np.cumsum(steps)])


def _r2(phase: np.ndarray) -> float:
    y = _unwrap(phase)
    t = np.arange(len(y), dtype=np.float64)
    design = np.stack([t, np.ones_like(t)], axis=1)
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    residual = y - design @ coef
    return float(1 - ((residual - residual.mean()) ** 2).mean() / ((y - y.mean()) ** 2).mean())


def _spread_codes(embed: Any) -> Any:
    """``embed_clip`` with seeded codes: biped frames on codes 0-4, quadruped frames on 2-6.

    Three training steps leave each character on one code of its own (no shared code,
    every share 0); these codes make the figures non-trivial. The phases stay the model's.
    """

    def wrapped(aligner: Any, motion: Any) -> Any:
        emb = embed(aligner, motion)
        low = 0 if "biped" in emb.dataset else 2
        gen = torch.Generator().manual_seed(len(emb.code) + low)
        code = torch.randint(low, low + 5, emb.code.shape, generator=gen)
        return dataclasses.replace(emb, code=code.to(emb.code.dtype))

    return wrapped


def test_code_and_phase_figures_equal_an_independent_computation(
    helpers: dict[str, Any], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    model, held = helpers["tiny"](tmp_path, 0.25)
    monkeypatch.setattr(evaluation, "embed_clip", _spread_codes(embed_clip))
    with torch.no_grad():
        out = manifold_protocol(model, held, tmp_path, procedural_seeds=0)
        embeddings = [evaluation.embed_clip(model, clip) for clip in held.clips]
    codes: dict[str, list[int]] = {}
    for emb in embeddings:
        codes.setdefault(emb.dataset, []).extend(emb.code.tolist())
    assert len(codes) == 2  # both characters are held out
    used = {name: set(c) for name, c in codes.items()}
    shared = set.intersection(*used.values())
    union = set.union(*used.values())
    assert 0 < len(shared) < len(union)  # some codes shared, some not
    assert [r["clip"] for r in out.rows] == held.names
    for row, emb in zip(out.rows, embeddings, strict=True):
        frame_codes = emb.code.numpy()
        assert row["character"] == emb.dataset and row["frames"] == len(frame_codes)
        share = sum(int(c) in shared for c in frame_codes) / len(frame_codes)
        model_values = row["values"]["model"]
        assert model_values["shared_code_share"] == pytest.approx(share, abs=1e-12)
        assert model_values["phase_r2"] == pytest.approx(_r2(emb.phase.double().numpy()), abs=1e-9)
        assert row["values"]["chance"] == {"shared_code_share": pytest.approx(len(shared) / 8)}
    table = out.extra["table2"]
    assert table["codes_used"] == {n: len(u) for n, u in used.items()}
    assert table["codes_shared"] == len(shared) and table["codes_used_any"] == len(union)
    assert table["shared_of_used"] == pytest.approx(len(shared) / len(union))
    for name, frame_codes in codes.items():
        assert table["shared_of_own"][name] == pytest.approx(len(shared) / len(used[name]))
        on_shared = sum(c in shared for c in frame_codes) / len(frame_codes)
        assert table["frame_share"][name] == pytest.approx(on_shared)
        assert table["frames"][name] == len(frame_codes)
    # shared components of the training data: codes of the training windows, one at a time
    dm = held.datamodule
    trained: dict[str, list[int]] = {}
    for name, dataset in dm.datasets["train"].items():
        k = model.dataset_names.index(name)
        for i in range(len(dataset)):
            with torch.no_grad():
                code = model.forward_dataset(k, dataset[i]["features"][None])[1].code
            trained.setdefault(name, []).append(int(code[0]))
    both = set.intersection(*(set(c) for c in trained.values()))
    assert table["codes_shared_training"] == len(both)
    assert table["shared_codes_training"] == sorted(both)
    for name, frame_codes in codes.items():
        on_trained = sum(c in both for c in frame_codes) / len(frame_codes)
        assert table["frame_share_heldout_on_training_shared"][name] == pytest.approx(on_trained)
        assert table["frame_share_training_shared"][name] == pytest.approx(on_trained)
        # the paper's Table 2: the training windows' own share on those codes
        windows = trained[name]
        assert table["frame_share_training"][name] == pytest.approx(
            sum(c in both for c in windows) / len(windows)
        )
        assert table["frames_training"][name] == len(windows)
    assert out.extra["num_codes"] == 8  # K, so a sweep's entries can be compared
    overlap = out.extra["overlap"]
    assert overlap["usage"] == pytest.approx(len(union) / 8)
    assert overlap["overlap"] == pytest.approx(len(shared) / 8)
    assert overlap["per_dataset"] == pytest.approx([table["frame_share"][n] for n in codes])
    # per-character means: plain averages of that character's rows
    for name in codes:
        rows = [r for r in out.rows if r["character"] == name]
        for metric in ("shared_code_share", "phase_r2"):
            average = sum(r["values"]["model"][metric] for r in rows) / len(rows)
            got = out.extra["per_character"][name]["model"][metric]
            assert got == pytest.approx(average, rel=1e-12), (name, metric)
