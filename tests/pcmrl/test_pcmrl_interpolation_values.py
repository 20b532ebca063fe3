"""pcmrl.interpolation: every per-clip figure and its mean recomputed independently in numpy.

Two procedural biped31 clips (the CMU-31 hierarchy stage 2 works on), 32-frame
windows every 16 frames, an untrained seeded stage-2 model and the LERP/SLERP
baseline. For each clip, method and keyframe gap the test builds its own keys,
windows and numpy forward kinematics and recomputes:

* the authors' Table 1 (``l2p``, ``l2q``, ``npss``): keys pasted from the ground
  truth, metres, centred on the keyframes' mean position over the joints that move
  a bone, all frames; rotations of the other joints set to identity, the ground
  truth's made sign-continuous in time and the prediction's put on its hemisphere;
  NPSS (squared magnitude) on positions and quaternions, weighted over the windows;
* the LaFAN1 benchmark's definitions (``lafan1_*``, ``design/METHODS.md``): L2P
  z-scored per channel with statistics of the evaluated windows (no training clips
  here), L2Q on sign-continuous global quaternions, both over the non-key frames;
  NPSS on global quaternions over the whole window;
* the foot skate (cm/s) and the share of planted steps above 0.05 heights/s of
  every method and of the ground truth (``ground_truth``, a reference row), over
  the planted steps of all windows, with numpy loops.

Taken from the library: the two methods' outputs (the interpolated motions) and
the contact detector (``foot_contacts`` on each ground-truth window, tested
against an independent rule in ``tests/analysis/test_foot_contacts.py``).
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import torch
from skelagnostic_pcmrl.evaluation import interpolation_protocol
from skelagnostic_pcmrl.interp.aligner import PcmrlInterpAligner

from numpy_reference import foot_skate, global_pose, hemisphere_continuous, npss
from skelagnostic import Motion, procedural
from skelagnostic.analysis import foot_contacts
from skelagnostic.baselines import lerp_slerp
from skelagnostic.evaluation import HeldOut, mean_rows

WINDOW, STRIDE, GAPS = 32, 16, (5, 15, 30)


def _clips() -> list[Motion]:
    out = []
    for seed, gait, name in ((5, "walk", "walk"), (6, "run", "run")):
        motion, _ = procedural.generate("biped31", gait, seconds=2.2, fps=30, seed=seed)
        motion = motion.convert_units("m")
        motion.name = name
        out.append(motion)
    return out


def _keys(gap: int) -> list[int]:
    return sorted(set(range(0, WINDOW, gap)) | {WINDOW - 1})


def _moving_joints(motion: Motion) -> list[int]:
    """The root and every joint with a child at a non-zero offset (it moves a bone)."""
    offsets = motion.skeleton.offsets.double().numpy()
    parents = motion.skeleton.parents
    return sorted({0} | {parents[c] for c in range(1, len(parents)) if np.linalg.norm(offsets[c])})


def _horizontal_centre(motion: Motion) -> np.ndarray:
    centre = motion.root_positions.double().numpy().mean(axis=0)
    centre[motion.skeleton.up_index] = 0.0
    return centre


def _authors(preds: list[Motion], wins: list[Motion], keys: list[int]) -> dict[str, float]:
    joints = _moving_joints(wins[0])
    still = [j for j in range(wins[0].num_joints) if j not in joints]
    pp, pq, tp, tq = [], [], [], []
    for pred, win in zip(preds, wins, strict=True):
        q_true, p_true = global_pose(win)
        q_pred, p_pred = global_pose(pred)
        q_true[:, still] = q_pred[:, still] = (1.0, 0.0, 0.0, 0.0)
        q_true = hemisphere_continuous(q_true)
        q_pred = np.where((q_pred * q_true).sum(-1, keepdims=True) < 0, -q_pred, q_pred)
        p_pred[keys], q_pred[keys] = p_true[keys], q_true[keys]
        centre = p_true[keys][:, joints].mean(axis=(0, 1))
        pp.append(p_pred - centre)
        tp.append(p_true - centre)
        pq.append(q_pred)
        tq.append(q_true)
    pp, pq, tp, tq = map(np.stack, (pp, pq, tp, tq))
    frames = pp.shape[:2]
    return {
        "l2p": float(np.linalg.norm((pp - tp).reshape(*frames, -1), axis=-1).mean()),
        "l2q": float(np.linalg.norm((pq - tq).reshape(*frames, -1), axis=-1).mean()),
        "npss": npss(
            np.concatenate([pp, pq], axis=-1).reshape(*frames, -1),
            np.concatenate([tp, tq], axis=-1).reshape(*frames, -1),
        ),
    }


def _lafan1(
    preds: list[Motion], wins: list[Motion], keys: list[int], stats: tuple[np.ndarray, np.ndarray]
) -> dict[str, float]:
    mean, std = stats
    free = [t for t in range(WINDOW) if t not in keys]
    l2p, l2q, pq, tq = [], [], [], []
    for pred, win in zip(preds, wins, strict=True):
        q_true, p_true = global_pose(win, 1.0)
        q_pred, p_pred = global_pose(pred, 1.0)
        centre = _horizontal_centre(win)
        a = ((p_pred - centre).reshape(WINDOW, -1) - mean) / std
        b = ((p_true - centre).reshape(WINDOW, -1) - mean) / std
        l2p.extend(np.linalg.norm(a - b, axis=-1)[free])
        q_true, q_pred = hemisphere_continuous(q_true), hemisphere_continuous(q_pred)
        l2q.extend(np.linalg.norm((q_pred - q_true).reshape(WINDOW, -1), axis=-1)[free])
        pq.append(q_pred.reshape(WINDOW, -1))
        tq.append(q_true.reshape(WINDOW, -1))
    return {
        "lafan1_l2p": float(np.mean(l2p)),
        "lafan1_l2q": float(np.mean(l2q)),
        "lafan1_npss": npss(np.stack(pq), np.stack(tq)),
    }


def _skate(motions: list[Motion], wins: list[Motion]) -> dict[str, float]:
    """Foot skate (cm/s) of ``motions`` on the contacts of the windows ``wins`` (metres)."""
    detected = [foot_contacts(w) for w in wins]
    feet = detected[0].joints
    contacts = np.stack([c.contacts.numpy() for c in detected])
    positions = 100 * np.stack([global_pose(m, 1.0)[1] for m in motions])
    sk = wins[0].skeleton
    mean, ratio = foot_skate(positions, contacts, feet, wins[0].fps, sk.up_index, 5 * sk.height())
    if not np.isfinite(mean):  # no planted step: no value
        return {}
    return {"foot_skate_cm_s": mean, "foot_skate_ratio": ratio}


def test_rows_and_means_equal_an_independent_computation(tmp_path: Path) -> None:
    torch.manual_seed(0)
    model = PcmrlInterpAligner(
        dim=16,
        heads=2,
        layers=1,
        ff_mult=2,
        max_relative=16,
        skeleton=_clips()[0].skeleton.to_dict(),
    ).eval()
    clips = _clips()
    held = HeldOut("test", clips, SimpleNamespace(window=WINDOW))
    with torch.no_grad():
        out = interpolation_protocol(model, held, tmp_path)
    # the LaFAN1 statistics: centred positions of every evaluated window (no training clip)
    all_windows = [
        c[s : s + WINDOW] for c in clips for s in range(0, c.num_frames - WINDOW + 1, STRIDE)
    ]
    flat = np.concatenate(
        [(global_pose(w, 1.0)[1] - _horizontal_centre(w)).reshape(WINDOW, -1) for w in all_windows]
    )
    stats = flat.mean(axis=0), np.maximum(flat.std(axis=0, ddof=1), 1e-3)
    methods = {"model": model.interpolate, "lerp_slerp": lerp_slerp}
    expected = {}
    for clip in clips:
        wins = [clip[s : s + WINDOW] for s in range(0, clip.num_frames - WINDOW + 1, STRIDE)]
        expected[clip.name] = {"windows": len(wins)}
        truth = {f"{k}@{gap}": v for k, v in _skate(wins, wins).items() for gap in GAPS}
        expected[clip.name]["ground_truth"] = truth
        for method, interpolate in methods.items():
            values = {}
            for gap in GAPS:
                keys = _keys(gap)
                with torch.no_grad():
                    preds = [interpolate(w, keys) for w in wins]
                figures = _authors(preds, wins, keys) | _lafan1(preds, wins, keys, stats)
                figures |= _skate(preds, wins)
                values |= {f"{k}@{gap}": v for k, v in figures.items()}
            expected[clip.name][method] = values
    assert [r["clip"] for r in out.rows] == ["walk", "run"]
    for row in out.rows:
        want = expected[row["clip"]]
        assert row["windows"] == want["windows"] == 3
        assert set(row["values"]) == {*methods, "ground_truth"}
        for method in (*methods, "ground_truth"):
            assert set(row["values"][method]) == set(want[method])
            for metric, value in want[method].items():
                got = row["values"][method][metric]
                assert got == pytest.approx(value, rel=1e-6, abs=1e-10), (
                    row["clip"],
                    method,
                    metric,
                )
    mean = mean_rows(out.rows)
    for method in (*methods, "ground_truth"):
        for metric in expected["walk"][method]:  # over the clips that have the value
            have = [c[method][metric] for c in expected.values() if metric in c[method]]
            average = sum(have) / len(have)
            assert mean[method][metric] == pytest.approx(average, rel=1e-6, abs=1e-10)
    # sanity of the reference: LERP is worse with sparser keys
    # the walk plants its feet (the run's windows have no planted step: no skate value)
    assert expected["walk"]["ground_truth"] and not expected["run"]["ground_truth"]
    lerp = expected["walk"]["lerp_slerp"]
    assert lerp["l2p@5"] < lerp["l2p@15"] and lerp["lafan1_l2p@5"] < lerp["lafan1_l2p@15"]
