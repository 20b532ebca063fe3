"""Shared fixtures: the real clips in ../shared/data and seeded RNGs."""

from __future__ import annotations

import os
from pathlib import Path

# Tests run in 2 xdist workers on 2-core machines: one intra-op thread per worker
# (and per subprocess, through the environment) avoids oversubscription, which
# makes torch's elementwise kernels an order of magnitude slower.
os.environ.setdefault("OMP_NUM_THREADS", "1")

import pytest
import torch

torch.set_num_threads(int(os.environ["OMP_NUM_THREADS"]))

REPO_ROOT = Path(__file__).resolve().parents[1]


def shared_data_dir() -> Path | None:
    """Where the real motion clips live, or None when they are not available.

    ``SKELAGNOSTIC_TEST_DATA`` wins; the default is ``../shared/data`` next to the
    repository checkout.
    """
    env = os.environ.get("SKELAGNOSTIC_TEST_DATA")
    path = Path(env) if env else REPO_ROOT.parent / "shared" / "data"
    return path if path.is_dir() else None


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Root of the real clips (human/, dog/); skips the test when absent."""
    path = shared_data_dir()
    if path is None:
        pytest.skip(
            "real clips not found: set SKELAGNOSTIC_TEST_DATA or place them in ../shared/data"
        )
    return path


@pytest.fixture(scope="session")
def lafan_clip(shared_data: Path) -> Path:
    """The short LaFAN1 clip (391 frames, 30 fps)."""
    return shared_data / "human" / "lafan1" / "Lafan1_example.bvh"
