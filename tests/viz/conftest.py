"""Fixtures for the rendering tests: a synthetic walker and pixel helpers."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from skelagnostic.viz import BODY_GROUP_COLORS, StickFigure

PARENTS = [-1, 0, 1, 0, 3, 0, 5, 1, 7, 1, 9]
GROUPS = [
    "spine",
    "spine",
    "spine",
    "left_leg",
    "left_leg",
    "right_leg",
    "right_leg",
    "left_arm",
    "left_arm",
    "right_arm",
    "right_arm",
]


def walker_positions(frames: int, fps: float, speed: float = 1.0, scale: float = 1.0) -> np.ndarray:
    """A y-up stick walker travelling along +x: [frames, 11, 3]."""
    t = np.arange(frames) / fps
    swing = np.sin(2 * np.pi * t)
    zero = np.zeros(frames)
    root = np.stack([speed * t, np.full(frames, 1.0), zero], axis=1)

    def joint(x: np.ndarray, y: float, z: float) -> np.ndarray:
        return root + np.stack([x, np.full(frames, y), np.full(frames, z)], axis=1)

    joints = [
        root,
        joint(zero, 0.5, 0),
        joint(zero, 0.8, 0),
        joint(0.3 * swing, -0.5, 0.1),
        joint(0.3 * swing, -1.0, 0.1),
        joint(-0.3 * swing, -0.5, -0.1),
        joint(-0.3 * swing, -1.0, -0.1),
        joint(zero, 0.5, 0.3),
        joint(-0.2 * swing, 0.2, 0.35),
        joint(zero, 0.5, -0.3),
        joint(0.2 * swing, 0.2, -0.35),
    ]
    return np.stack(joints, axis=1) * scale


@pytest.fixture
def walker() -> Callable[..., StickFigure]:
    """Factory: ``walker(frames=30, fps=30.0, speed=1.0, scale=1.0, name="walker")``."""

    def make(
        frames: int = 30,
        fps: float = 30.0,
        speed: float = 1.0,
        scale: float = 1.0,
        name: str = "walker",
    ) -> StickFigure:
        return StickFigure(
            walker_positions(frames, fps, speed, scale), PARENTS, GROUPS, fps=fps, name=name
        )

    return make


def _color_pixels(image: np.ndarray, group: str, tolerance: int = 40) -> int:
    hex_color = BODY_GROUP_COLORS[group].lstrip("#")
    rgb = np.array([int(hex_color[i : i + 2], 16) for i in (0, 2, 4)])
    return int((np.abs(image.astype(int) - rgb).max(axis=-1) <= tolerance).sum())


def _ink(image: np.ndarray) -> int:
    return int((image.astype(int).min(axis=-1) < 150).sum())


@pytest.fixture
def color_pixels() -> Callable[..., int]:
    """``color_pixels(image, group)``: pixels of an [H, W, 3] image near a body-group colour."""
    return _color_pixels


@pytest.fixture
def ink() -> Callable[[np.ndarray], int]:
    """``ink(image)``: pixels clearly darker than the background and the floor (drawn lines)."""
    return _ink
