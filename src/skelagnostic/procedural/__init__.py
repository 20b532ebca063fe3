"""Procedural motion: synthetic, parametric gaits on several skeletons.

This is the embedded default data of skelagnostic: demos, the default training
data of every method and the fast tests use it, so nothing needs downloading.
It is **synthetic**: joint angles are smooth periodic functions of a gait phase,
not motion capture. Its value is that the truth is known (gait frequency,
phase, speed) and that the same gait can be played on different topologies.

Skeletons (all in centimetres, Y up, facing +Z, left +X):

* ``biped22``: LaFAN1-like, 22 joints (``Hips``, ``LeftUpLeg``, ... ``RightHand``).
* ``biped31``: CMU-like, 31 joints with zero-length hip/back joints, fingers and
  thumbs (Xia/MotionBuilder names).
* ``biped17``: Human3.6M-like, 17 joints with short names (``RHip``, ``LKnee``, ...).
* ``quadruped``: a dog, 21 joints with a tail and human-style names
  (``LeftArm`` is a front leg), like the MANN dog data.

Gaits: ``walk``, ``run``, ``idle`` for bipeds; ``walk`` (lateral sequence),
``trot`` (diagonal pairs), ``gallop`` (rotary) and ``idle`` for the quadruped.

The rigs live in :mod:`skelagnostic.procedural.rigs`, the gaits in
:mod:`skelagnostic.procedural.gaits`; this package re-exports their public
names, so ``sa.procedural.generate(...)`` is the call to write.
"""

from skelagnostic.procedural.gaits import GAITS, dataset, generate
from skelagnostic.procedural.rigs import KINDS, joint_roles, skeleton

__all__ = ["GAITS", "KINDS", "dataset", "generate", "joint_roles", "skeleton"]
