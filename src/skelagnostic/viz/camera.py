"""A fixed orthographic camera for z-up scenes."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["Camera", "auto_azimuth"]


@dataclass(frozen=True)
class Camera:
    """Orthographic camera looking at a z-up scene.

    Attributes:
        azim: Azimuth in degrees of the direction from the scene to the eye,
            measured in the ground plane from ``+x`` towards ``+y``.
        elev: Elevation in degrees of the eye above the ground plane.

    Examples:
        >>> import numpy as np
        >>> uv, depth = Camera(azim=0.0, elev=0.0).project(np.array([[0.0, 1.0, 2.0]]))
        >>> uv.round(6).tolist(), depth.round(6).tolist()
        ([[1.0, 2.0]], [0.0])
    """

    azim: float
    elev: float

    def basis(self) -> np.ndarray:
        """``[3, 3]`` rows: screen right, screen up, and the direction towards the eye."""
        az, el = math.radians(self.azim), math.radians(self.elev)
        ca, sa, ce, se = math.cos(az), math.sin(az), math.cos(el), math.sin(el)
        return np.array(
            [
                [-sa, ca, 0.0],
                [-se * ca, -se * sa, ce],
                [ce * ca, ce * sa, se],
            ]
        )

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project z-up points to the screen.

        Args:
            points: ``[..., 3]`` points.

        Returns:
            ``(uv, depth)``: ``[..., 2]`` screen coordinates (right, up) and
            ``[...]`` depth, larger meaning closer to the eye.
        """
        projected = np.asarray(points, dtype=np.float64) @ self.basis().T
        return projected[..., :2], projected[..., 2]


def auto_azimuth(positions: Sequence[np.ndarray], offset: float = 30.0) -> float:
    """Azimuth of a three-quarter view across the main horizontal direction of a scene.

    The main direction is the principal axis of the horizontal joint positions:
    the direction of travel for locomotion, the long axis of the body (shoulders
    of a standing human, spine of a dog) otherwise. The camera looks across it,
    turned by ``offset`` degrees towards its positive end, which is oriented
    along the net root displacement so that travelling characters move from
    left to right.

    Args:
        positions: z-up positions ``[T, J, 3]``, one array per character.
        offset: Degrees from the pure side view.

    Returns:
        The azimuth in degrees.
    """
    xy = np.concatenate([p[..., :2].reshape(-1, 2) for p in positions])
    centred = xy - xy.mean(axis=0)
    _, vectors = np.linalg.eigh(centred.T @ centred)
    direction = vectors[:, -1]
    travel = sum(p[-1, 0, :2] - p[0, 0, :2] for p in positions)
    reference = travel if np.linalg.norm(travel) > 1e-9 else np.array([1.0, 1e-3])
    if float(direction @ reference) < 0:
        direction = -direction
    return math.degrees(math.atan2(direction[1], direction[0])) - 90.0 + offset
