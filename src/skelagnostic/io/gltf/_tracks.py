"""Animation channels of a glTF file: their keyframes, sampled at any time.

Quaternions here are glTF's (x, y, z, w); the arithmetic is :mod:`skelagnostic.core.quaternion`'s
(w, x, y, z), through :func:`to_wxyz` and :func:`to_xyzw`.
"""

from __future__ import annotations

import numpy as np
import torch

from skelagnostic.core import quaternion as Q
from skelagnostic.io.gltf._common import _SNAP

__all__ = ["Track", "mul_xyzw", "rotate_xyzw", "slerp_xyzw", "to_wxyz"]


def to_wxyz(q: np.ndarray) -> torch.Tensor:
    """(x, y, z, w) numpy quaternions as (w, x, y, z) torch ones (same dtype)."""
    return torch.from_numpy(np.ascontiguousarray(np.asarray(q)[..., [3, 0, 1, 2]]))


def _to_xyzw(q: torch.Tensor) -> np.ndarray:
    return q[..., [1, 2, 3, 0]].numpy()


def mul_xyzw(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of (x, y, z, w) quaternions (broadcasting)."""
    return _to_xyzw(Q.mul(*torch.broadcast_tensors(to_wxyz(a), to_wxyz(b))))


def rotate_xyzw(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors ``v`` by an (x, y, z, w) quaternion ``q`` (broadcasting)."""
    return Q.rotate(to_wxyz(q), torch.from_numpy(np.asarray(v, dtype=np.float64))).numpy()


def slerp_xyzw(a: np.ndarray, b: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Shortest-arc spherical interpolation of (x, y, z, w) quaternions ``[N, 4]`` by ``[N, 1]``."""
    return _to_xyzw(Q.slerp(to_wxyz(a), to_wxyz(b), torch.from_numpy(u[..., 0])))


class Track:
    """The keyframes of one animation channel."""

    def __init__(
        self, times: np.ndarray, values: np.ndarray, interpolation: str, field: str
    ) -> None:
        self.times, self.values, self.interpolation, self.field = (
            times,
            values,
            interpolation,
            field,
        )

    def keyframes(self) -> np.ndarray:
        """The values at the key times (the middle element of CUBICSPLINE triples)."""
        return self.values[1::3] if self.interpolation == "CUBICSPLINE" else self.values

    def at(self, t: np.ndarray, rotation: bool) -> np.ndarray:
        """Values at times ``t`` (clamped to the first and last keyframe)."""
        keys, values = self.times, self.keyframes()
        if len(keys) == 1:
            return np.repeat(values[:1], len(t), axis=0)
        k = (np.searchsorted(keys, t, side="right") - 1).clip(0, len(keys) - 2)
        t0, t1 = keys[k], keys[k + 1]
        u = ((t - t0) / (t1 - t0)).clip(0.0, 1.0)
        u = np.where(u < _SNAP, 0.0, np.where(u > 1.0 - _SNAP, 1.0, u))[:, None]
        a, b = values[k], values[k + 1]
        if self.interpolation == "STEP":
            out = np.where(u < 1.0, a, b)
        elif self.interpolation == "LINEAR":
            out = slerp_xyzw(a, b, u) if rotation else (1.0 - u) * a + u * b
        else:  # CUBICSPLINE: Hermite with the file's tangents, scaled by the interval
            dt = (t1 - t0)[:, None]
            out_tangent, in_tangent = self.values[3 * k + 2], self.values[3 * (k + 1)]
            u2, u3 = u * u, u * u * u
            out = (
                (2 * u3 - 3 * u2 + 1) * a
                + (u3 - 2 * u2 + u) * dt * out_tangent
                + (-2 * u3 + 3 * u2) * b
                + (u3 - u2) * dt * in_tangent
            )
        if rotation:
            out = out / np.linalg.norm(out, axis=-1, keepdims=True).clip(min=1e-12)
        return out
