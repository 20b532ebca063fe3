"""Joint positions in a character's own frame, shared by the analysis modules."""

from __future__ import annotations

import torch

from skelagnostic.core import quaternion as Q
from skelagnostic.core.motion import Motion


def root_frame_positions(motion: Motion) -> torch.Tensor:
    """``[T, J, 3]`` joint positions relative to the body root's ground projection, facing frame.

    The numbers of :class:`~skelagnostic.representations.GlobalPositions` with
    ``frame="root"``, computed here because the analysis layer sits below the
    representations (``tests/test_layering.py``).
    """
    pos = motion.global_positions()
    ground = pos[:, motion.skeleton.body_root].clone()  # the body's, not a carrier's
    ground[:, motion.skeleton.up_index] = 0.0
    return Q.rotate(Q.inv(motion.facing()).unsqueeze(1), pos - ground.unsqueeze(1))
