"""Aligners: LightningModules that encode motion of any skeleton into a shared latent space.

Build a registered one with :func:`skelagnostic.plugins.load_aligner`; write
your own by subclassing :class:`Aligner` and registering it through the
``register_aligners`` hook.
"""

from skelagnostic.aligners.base import (
    KNOWN_CAPABILITIES,
    Aligner,
    CapabilityError,
    Latent,
    batch_skeleton,
)
from skelagnostic.aligners.checkpoint_errors import CheckpointError
from skelagnostic.aligners.checkpoints import read_checkpoint
from skelagnostic.aligners.schedule import steps_per_epoch
from skelagnostic.aligners.trainer import QUIET_TRAINER_OPTIONS, quiet_trainer

__all__ = [
    "KNOWN_CAPABILITIES",
    "QUIET_TRAINER_OPTIONS",
    "Aligner",
    "CapabilityError",
    "CheckpointError",
    "Latent",
    "batch_skeleton",
    "quiet_trainer",
    "read_checkpoint",
    "steps_per_epoch",
]
