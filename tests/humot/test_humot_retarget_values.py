"""humot.retarget: every per-clip figure, its mean and the paired table recomputed in numpy.

A procedural biped22 clip and an untrained seeded small HuMoT. The cycle
source -> biped31 -> source is made by each method (HuMoT, ``name_copy``,
``primal_copy``: the methods under test); the test recomputes with numpy
forward kinematics the MPJPE of the cycled motion against the source, globally
and with the roots aligned, over the source's height. ``extra`` holds the
paired procedural retargeting (every ordered pair of the three human rigs, the
same gait and seed generated on the target rig as ground truth): each pair's
means over its clips and the mean over pairs are recomputed the same way.
Taken from the library: the methods' outputs, the procedural generator (the
data) and :meth:`Skeleton.height` (the extent of the canonical template).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from skelagnostic_humot.aligner import HumotAligner
from skelagnostic_humot.evaluation.retarget import retarget_protocol

import skelagnostic as sa
from numpy_reference import foot_skate, global_pose
from skelagnostic.analysis import foot_contacts
from skelagnostic.baselines import direction_copy, name_copy, primal_copy
from skelagnostic.evaluation import HeldOut, mean_rows

pytestmark = pytest.mark.slow  # about 30 s on a loaded 2-core machine

KINDS = ("biped22", "biped31", "biped17")


def _errors(pred: sa.Motion, truth: sa.Motion) -> dict[str, float]:
    """MPJPE in the truth's units, with the roots aligned, and both over its height."""
    a, b = global_pose(pred, 1.0)[1], global_pose(truth, 1.0)[1]
    frames = min(len(a), len(b))
    a, b = a[:frames], b[:frames]
    err = float(np.linalg.norm(a - b, axis=-1).mean())
    local = float(np.linalg.norm((a - a[:, :1]) - (b - b[:, :1]), axis=-1).mean())
    height = truth.skeleton.height()
    return {
        "mpjpe": err,
        "mpjpe_over_height": err / height,
        "root_aligned_mpjpe": local,
        "root_aligned_over_height": local / height,
    }


def _skate_cm_s(pred: sa.Motion, truth: sa.Motion) -> tuple[float, float]:
    """Mean horizontal speed (cm/s) of the truth's planted feet and the share above
    0.05 heights/s, numpy loops."""
    contacts, feet = foot_contacts(truth)  # the library's detector: shared by every method
    positions = global_pose(pred, 1.0)[1]
    frames = min(len(positions), truth.num_frames)
    threshold = 0.05 * truth.skeleton.height()  # procedural rigs are in cm
    return foot_skate(
        positions[:frames],
        contacts.numpy()[:frames],
        feet,
        truth.fps,
        truth.skeleton.up_index,
        threshold,
    )


def _methods(model: HumotAligner) -> dict[str, object]:
    def humot(m: sa.Motion, sk: sa.Skeleton, su: str, tu: str) -> sa.Motion:
        return model.retarget(m, sk, su, tu)

    return {
        "humot": humot,
        "name_copy": name_copy,
        "primal_copy": primal_copy,
        "direction_copy": direction_copy,
    }


def test_rows_means_and_paired_table_equal_an_independent_computation(
    tmp_path: Path, humot_small: dict[str, int]
) -> None:
    torch.manual_seed(0)
    model = HumotAligner(**humot_small).eval()
    a = sa.procedural.generate("biped22", "walk", seconds=1.0, fps=30, seed=3)[0]
    b = sa.procedural.generate("biped17", "run", seconds=1.0, fps=30, seed=4)[0]
    a.name, b.name = "a", "b"
    with torch.no_grad():
        out = retarget_protocol(model, HeldOut("test", [a, b]), tmp_path, paired_seconds=1.0)
        methods = _methods(model)
        expected = {}
        for clip in (a, b):
            via = next(
                sa.procedural.skeleton(k)
                for k in KINDS
                if sa.procedural.skeleton(k).parents != clip.skeleton.parents
            )
            expected[clip.name] = {"via": via.name}
            for name, f in methods.items():
                there = f(clip, via, "cm", "cm")
                back = f(there, clip.skeleton, "cm", "cm")
                expected[clip.name][name] = _errors(back, clip)
                skate, ratio = _skate_cm_s(back, clip)
                expected[clip.name][name] |= {"skate": skate, "ratio": ratio}
            skate, ratio = _skate_cm_s(clip, clip)
            expected[clip.name]["source"] = {"skate": skate, "ratio": ratio}
        paired = {}
        data = {
            k: sa.procedural.dataset(
                kinds=(k,), gaits=("walk", "run"), clips_per_gait=1, seconds=1.0, seed=1000
            )
            for k in KINDS
        }
        for src_kind in KINDS:
            for dst_kind in KINDS:
                if src_kind == dst_kind:
                    continue
                sums: dict[str, float] = {}
                for (src, _), (truth, _) in zip(data[src_kind], data[dst_kind], strict=True):
                    for name, f in methods.items():
                        pred = f(src, truth.skeleton, "cm", "cm")
                        for key, value in _errors(pred, truth).items():
                            sums[f"{name}_{key}"] = sums.get(f"{name}_{key}", 0.0) + value
                paired[f"{src_kind}->{dst_kind}"] = {k: v / 2 for k, v in sums.items()}
    assert [r["clip"] for r in out.rows] == ["a", "b"]
    for row in out.rows:
        want = expected[row["clip"]]
        assert row["via"] == want["via"]
        for method, prefix in (
            ("model", "humot"),
            ("name_copy", "name_copy"),
            ("primal_copy", "primal_copy"),
            ("direction_copy", "direction_copy"),
        ):
            got = row["values"][method]
            assert got["cycle_over_height"] == pytest.approx(
                want[prefix]["mpjpe_over_height"], rel=1e-6
            ), (row["clip"], method)
            assert got["cycle_root_aligned_over_height"] == pytest.approx(
                want[prefix]["root_aligned_over_height"], rel=1e-6
            ), (row["clip"], method)
            assert got["cycle_foot_skate_cm_s"] == pytest.approx(
                want[prefix]["skate"], rel=1e-6, nan_ok=True
            ), (row["clip"], method)
            assert got["cycle_foot_skate_ratio"] == pytest.approx(
                want[prefix]["ratio"], rel=1e-6, nan_ok=True
            ), (row["clip"], method)
        # the source's own skate: a reference row beside the methods
        assert row["values"]["ground_truth"] == {
            "cycle_foot_skate_cm_s": pytest.approx(want["source"]["skate"], rel=1e-6, nan_ok=True),
            "cycle_foot_skate_ratio": pytest.approx(want["source"]["ratio"], rel=1e-6, nan_ok=True),
        }
    # clip a plants a foot for 6 frames (b runs without a contact: NaN, no value)
    assert np.isfinite(expected["a"]["source"]["skate"])
    mean = mean_rows(out.rows)
    assert mean["model"]["cycle_over_height"] == pytest.approx(
        (expected["a"]["humot"]["mpjpe_over_height"] + expected["b"]["humot"]["mpjpe_over_height"])
        / 2,
        rel=1e-6,
    )
    table = out.extra["procedural_paired_retargeting"]
    assert set(table) == {*paired, "mean"}
    for pair, figures in paired.items():
        assert table[pair]["clips"] == 2
        for key, value in figures.items():
            assert table[pair][key] == pytest.approx(value, rel=1e-6), (pair, key)
    for key in paired["biped22->biped31"]:
        average = sum(p[key] for p in paired.values()) / len(paired)
        assert table["mean"][key] == pytest.approx(average, rel=1e-6), key
        method, metric = next((m, key[len(m) + 1 :]) for m in methods if key.startswith(f"{m}_"))
        by_method = out.extra["procedural_paired_mean"]["model" if method == "humot" else method]
        assert by_method[metric] == pytest.approx(average, rel=1e-6), key
    # sanity of the reference: every error is a finite positive length
    assert all(0 < v < np.inf for p in paired.values() for v in p.values())
