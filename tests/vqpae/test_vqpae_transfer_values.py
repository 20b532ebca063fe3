"""vqpae.transfer: the acceleration figures in numpy, the derived rhythm figures by hand.

A VQ-PAE trained 3 steps on procedural biped22 and quadruped clips re-enacts
the held-out biped clips with the quadruped's training clips. The test captures
the three outputs of every clip (the model's, ``unscaled_matching``'s and
``own_rate_clip``'s: the methods under test) and recomputes from them, with
numpy forward kinematics, ``accel_height_per_s2`` and
``accel_max_height_per_s2`` (second difference of the joint positions times
fps^2, its norm averaged over the joints, over the skeleton height; mean and
maximum over the frames) and the foot skate (cm/s, and the share of planted steps
above 0.05 heights/s) of every output and of the source (``source``, a reference
row) on their own contacts (the library's detector, tested in
``tests/analysis/test_foot_contacts.py``). From the row's measured frequencies it recomputes
``frequency_error_pct``, ``gait_ratio``, ``contact_rhythm_error_pct`` and
``contact_rhythm_within_10pct``. Not recomputed: the measured frequencies
themselves (``output_hz``, ``source_hz``, ``contact_hz``) and ``contact_lock``,
whose foot-detection and touch-down rules are checked against the procedural
generator in ``test_vqpae_transfer_eval.py`` instead
(``docs/reports/protocol_tests.md``).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from skelagnostic_vqpae.protocols import transfer as evaluation

from numpy_reference import foot_skate, global_pose, metres
from skelagnostic.analysis import foot_contacts
from skelagnostic.evaluation import mean_rows


def _acceleration(motion: Any) -> tuple[float, float]:
    pos = global_pose(motion, 1.0)[1]
    per_frame = np.linalg.norm(pos[2:] - 2 * pos[1:-1] + pos[:-2], axis=-1).mean(-1)
    per_frame = per_frame * motion.fps**2 / motion.skeleton.height()
    return float(per_frame.mean()), float(per_frame.max())


def _skate(motion: Any) -> dict[str, float]:
    """Foot skate (cm/s) of a motion on its own contacts; empty without a planted step."""
    contacts, feet = foot_contacts(motion)
    pos = 100 * global_pose(motion)[1]
    threshold = 5 * motion.skeleton.height() * metres(motion)
    up = motion.skeleton.up_index
    mean, ratio = foot_skate(pos, contacts.numpy(), feet, motion.fps, up, threshold)
    return {"foot_skate_cm_s": mean, "foot_skate_ratio": ratio} if np.isfinite(mean) else {}


def test_acceleration_and_derived_figures_equal_an_independent_computation(
    helpers: dict[str, Any], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    model, held = helpers["tiny"](tmp_path, 0.3)
    captured: dict[str, list[Any]] = {}
    transfer_rows = evaluation.transfer_rows

    def capture(*args: Any, **kwargs: Any) -> Any:
        rows, outputs = transfer_rows(*args, **kwargs)
        captured.update(outputs)
        return rows, outputs

    monkeypatch.setattr(evaluation, "transfer_rows", capture)
    with torch.no_grad():
        out = evaluation.transfer_protocol(model, held, tmp_path)
    methods = [evaluation.MODEL, evaluation.UNSCALED, evaluation.OWN_RATE]
    assert out.methods == [*methods, evaluation.SOURCE] and out.rows
    skated = 0
    for row in out.rows:
        source, *made = captured[row["clip"]]
        assert row["frames"] == source.num_frames
        for method, output in zip(methods, made, strict=True):
            values = row["values"][method]
            mean_acc, max_acc = _acceleration(output)
            assert values["accel_height_per_s2"] == pytest.approx(mean_acc, rel=1e-6)
            assert values["accel_max_height_per_s2"] == pytest.approx(max_acc, rel=1e-6)
            skate = _skate(output)
            skated += bool(skate)
            assert {k: values[k] for k in values if k.startswith("foot_skate")} == pytest.approx(
                skate, rel=1e-6
            )
            hz, src = values["output_hz"], row["source_hz"]
            assert values["gait_ratio"] == pytest.approx(hz / src, nan_ok=True)
            assert values["frequency_error_pct"] == pytest.approx(
                100 * abs(hz / src - 1), nan_ok=True
            )
            error = 100 * abs(values["contact_hz"] / row["source_contact_hz"] - 1)
            assert values["contact_rhythm_error_pct"] == pytest.approx(error, nan_ok=True)
            within = math.nan if math.isnan(error) else float(error <= 10)
            assert values["contact_rhythm_within_10pct"] == pytest.approx(within, nan_ok=True)
        assert row["values"][evaluation.SOURCE] == pytest.approx(_skate(source), rel=1e-6)
    assert skated  # some output plants a foot: the skate columns are exercised
    # the model's output motions, handed over for evaluate cleanup=footlock
    assert {c: out.outputs[c]() for c in out.outputs} == {c: m[1] for c, m in captured.items()}
    # means over the clips (NaN values skipped): the acceleration of each method
    mean = mean_rows(out.rows)
    for method in methods:
        accs = [_acceleration(captured[r["clip"]][1 + methods.index(method)])[0] for r in out.rows]
        assert mean[method]["accel_height_per_s2"] == pytest.approx(np.mean(accs), rel=1e-6)


def test_the_protocol_embeds_each_source_once_for_its_four_transfers(
    helpers: dict[str, Any], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The model, two baselines and the touch-down bound reuse one embedding per source."""
    from skelagnostic_vqpae import transfer as transfer_module

    model, held = helpers["tiny"](tmp_path, 0.3)
    calls: list[str] = []
    embed = evaluation.embed_clip

    def counting(aligner: Any, motion: Any) -> Any:
        calls.append(str(motion.name))
        return embed(aligner, motion)

    monkeypatch.setattr(evaluation, "embed_clip", counting)
    monkeypatch.setattr(transfer_module, "embed_clip", counting)
    with torch.no_grad():
        out = evaluation.transfer_protocol(model, held, tmp_path)
    sources = [row["clip"] for row in out.rows]
    assert sources and all(calls.count(name) == 1 for name in sources), calls
    # given embeddings change nothing; a wrong count is refused
    monkeypatch.undo()
    clips = [c for c in held.clips if model.dataset_of(c.skeleton) == 0]
    database = transfer_module.build_database(
        model, [c for c in held.clips if model.dataset_of(c.skeleton) == 1]
    )
    with torch.no_grad():
        given = evaluation.touchdown_bound(
            model, clips, database, embeddings=[embed(model, c) for c in clips]
        )
        computed = evaluation.touchdown_bound(model, clips, database)
    assert given["per_clip"].keys() == computed["per_clip"].keys()
    for clip, figures in given["per_clip"].items():
        assert figures == pytest.approx(computed["per_clip"][clip], nan_ok=True)
    with pytest.raises(ValueError, match=f"embeddings: 0 given for {len(clips)} source clips"):
        evaluation.transfer_rows(model, clips, database, embeddings=[])
