"""Independent numpy references for the protocol value tests (``tests/*/test_*_values.py``).

Everything here is written from the definitions in ``design/METHODS.md`` and the
protocols' docstrings, in plain numpy, without calling the library's kinematics
or metrics: forward kinematics from offsets and quaternions, MPJPE, the temporal
KNN distance (Eq. 5 of PC-MRL), L2P / L2Q / NPSS. The tests only read a motion's
raw fields (rotations, root path, offsets, parents) from the library objects.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from skelagnostic.core.units import UNITS, infer_units


def qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternions ``[..., 4]`` (w, x, y, z)."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def qrot(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors ``v [..., 3]`` by unit quaternions ``q [..., 4]`` (q v q*)."""
    zeros = np.zeros((*v.shape[:-1], 1))
    conj = q * np.array([1.0, -1.0, -1.0, -1.0])
    return qmul(qmul(q, np.concatenate([zeros, v], axis=-1)), conj)[..., 1:]


def fk(
    rotations: np.ndarray,
    root: np.ndarray,
    offsets: np.ndarray,
    parents: list[int],
    translations: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Forward kinematics: global rotations ``[T, J, 4]`` and positions ``[T, J, 3]``.

    Args:
        rotations: ``[T, J, 4]`` local unit quaternions (w, x, y, z).
        root: ``[T, 3]`` root positions.
        offsets: ``[J, 3]`` rest offsets from the parent.
        parents: Parent index per joint (-1 for the root), parents first.
        translations: Optional ``[T, J, 3]`` animated offsets replacing ``offsets``.
    """
    rotations = rotations / np.linalg.norm(rotations, axis=-1, keepdims=True)
    frames, joints = rotations.shape[:2]
    grot = np.zeros((frames, joints, 4))
    gpos = np.zeros((frames, joints, 3))
    for j, p in enumerate(parents):
        if p < 0:
            grot[:, j], gpos[:, j] = rotations[:, j], root
            continue
        off = offsets[j] if translations is None else translations[:, j]
        grot[:, j] = qmul(grot[:, p], rotations[:, j])
        gpos[:, j] = gpos[:, p] + qrot(grot[:, p], np.broadcast_to(off, (frames, 3)))
    return grot, gpos


def metres(motion: Any) -> float:
    """Metres per unit of ``motion`` (its ``units``, else the unit its height suggests)."""
    return UNITS[infer_units(motion.skeleton, motion.units)]


def global_pose(motion: Any, scale: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Numpy FK of a :class:`~skelagnostic.Motion`: global rotations and positions in metres.

    Args:
        motion: The motion (only its raw fields are read).
        scale: Metres per unit (default :func:`metres`).
    """
    s = metres(motion) if scale is None else scale
    trans = None if motion.translations is None else motion.translations.double().numpy() * s
    return fk(
        motion.rotations.double().numpy(),
        motion.root_positions.double().numpy() * s,
        motion.skeleton.offsets.double().numpy() * s,
        list(motion.skeleton.parents),
        trans,
    )


#: Y up (x, y, z) -> HuMoT's model frame, Z up: (x, -z, y).
Y_UP_TO_Z_UP = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])


def humot_chunks(positions: np.ndarray, major: np.ndarray, chunk: int = 30) -> np.ndarray:
    """``[C, chunk, J, 3]`` whole chunks of Y-up positions, in the Z-up frame, centred.

    Each chunk is centred on the mean over its frames and ``major`` joints (all
    joints when none is major), as HuMoT's input.
    """
    count = len(positions) // chunk
    out = positions[: count * chunk].reshape(count, chunk, *positions.shape[1:]) @ Y_UP_TO_Z_UP.T
    ref = out[:, :, major] if major.any() else out
    return out - ref.mean(axis=(1, 2), keepdims=True)


def mpjpe(a: np.ndarray, b: np.ndarray) -> float:
    """Mean over frames and joints of the Euclidean distance of ``[..., J, 3]`` positions."""
    return float(np.linalg.norm(a - b, axis=-1).mean())


def hemisphere_continuous(q: np.ndarray) -> np.ndarray:
    """Quaternions ``[T, ..., 4]`` with signs flipped so that consecutive frames agree."""
    out = q.copy()
    for t in range(1, len(out)):
        flip = (out[t] * out[t - 1]).sum(-1) < 0
        out[t][flip] *= -1
    return out


def npss(pred: np.ndarray, target: np.ndarray, power: str = "abs") -> float:
    """NPSS of ``[B, T, C]`` channels (LaFAN1 ``fast_npss``; ``power='abs'``: squared magnitude).

    Per window and channel: the power spectrum along time normalised to sum 1, its
    cumulative sum, the L1 distance of the two cumulative spectra; the mean of those
    distances weighted by the target's total power per window and channel.
    """

    def spectrum(x: np.ndarray) -> np.ndarray:
        f = np.fft.fft(x, axis=1)
        return np.abs(f) ** 2 if power == "abs" else f.real**2

    ps_p, ps_t = spectrum(pred), spectrum(target)
    weight = ps_t.sum(axis=1)
    # a channel without power (a constant zero) has an all-zero normalised spectrum
    tot_p, tot_t = ps_p.sum(axis=1, keepdims=True), ps_t.sum(axis=1, keepdims=True)
    norm_p = np.divide(ps_p, tot_p, out=np.zeros_like(ps_p), where=tot_p > 0)
    norm_t = np.divide(ps_t, tot_t, out=np.zeros_like(ps_t), where=tot_t > 0)
    emd = np.abs(np.cumsum(norm_p, axis=1) - np.cumsum(norm_t, axis=1)).sum(axis=1)
    return float((emd * weight).sum() / weight.sum())


def foot_skate(
    positions: np.ndarray,
    contacts: np.ndarray,
    feet: list[int],
    fps: float,
    up: int,
    threshold: float,
) -> tuple[float, float]:
    """Mean planted-foot horizontal speed and the share above ``threshold``, numpy loops.

    ``positions`` ``[..., T, J, 3]`` and ``contacts`` ``[..., T, F]`` (leading axes: one
    sequence each); a step counts where foot ``f`` is in contact at ``t`` and ``t + 1``.
    Returns ``(nan, nan)`` without such a step.
    """
    pos = np.asarray(positions, dtype=np.float64).reshape(-1, *np.shape(positions)[-3:])
    con = np.asarray(contacts, dtype=bool).reshape(-1, *np.shape(contacts)[-2:])
    speeds = [
        float(np.linalg.norm(np.delete(seq[t + 1, j] - seq[t, j], up))) * fps
        for seq, c in zip(pos, con, strict=True)
        for f, j in enumerate(feet)
        for t in range(len(seq) - 1)
        if c[t, f] and c[t + 1, f]
    ]
    if not speeds:
        return float("nan"), float("nan")
    return float(np.mean(speeds)), float(np.mean([s > threshold for s in speeds]))
