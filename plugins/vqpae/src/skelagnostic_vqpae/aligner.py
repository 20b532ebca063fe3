"""The VQ-PAE aligner: the model with its fit summary and transfer (the plugin's top floor).

:class:`VqpaeAligner` is what ``model=vqpae`` registers, checkpoints load into and
users import. It is :class:`~skelagnostic_vqpae.training.VqpaeModel` (training,
``encode``/``decode``, export) plus the two methods whose work lives on higher floors
of the plugin: :meth:`VqpaeAligner.fit_summary`
(:mod:`skelagnostic_vqpae.protocols.summary`) and :meth:`VqpaeAligner.transfer`
(:mod:`skelagnostic_vqpae.transfer`). This module imports them; the model, its
embedding, transfer and protocols take a ``VqpaeModel`` and never import this module.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, ClassVar

from skelagnostic.core.motion import Motion
from skelagnostic_vqpae.options import (
    AUTHORS_OPTIMIZER,
    AUTHORS_SCHEDULER,
    COSINE_SCHEDULER,
    PLUS_OPTIONS,
    PREVIOUS_DEFAULTS,
    DatasetSpec,
)
from skelagnostic_vqpae.protocols.summary import fit_summary
from skelagnostic_vqpae.training import VqpaeModel
from skelagnostic_vqpae.transfer import transfer_clips

if TYPE_CHECKING:
    import lightning as L

    from skelagnostic.callbacks import SummaryContent

__all__ = [
    "AUTHORS_OPTIMIZER",
    "AUTHORS_SCHEDULER",
    "COSINE_SCHEDULER",
    "PLUS_OPTIONS",
    "PREVIOUS_DEFAULTS",
    "DatasetSpec",
    "VqpaeAligner",
    "VqpaeModel",
]


class VqpaeAligner(VqpaeModel):
    """VQ-PAEs of several characters sharing one amplitude codebook (WalkTheDog).

    The options are those of :class:`~skelagnostic_vqpae.training.VqpaeModel`;
    this class adds the fit summary and ``transfer`` (capability ``"transfer"``).

    Attributes:
        last_transitions: Output frames where the last :meth:`transfer` switched to
            another matched window (``None`` before the first transfer).
    """

    capabilities: ClassVar[frozenset[str]] = VqpaeModel.capabilities | {"transfer"}
    last_transitions: list[int] | None = None

    def fit_summary(self, trainer: L.Trainer, mode: str = "full") -> SummaryContent:
        """The manifold overlap, figures and pictures of the fit summary.

        See :func:`skelagnostic_vqpae.protocols.summary.fit_summary`.
        """
        return fit_summary(self, trainer, mode=mode)

    def transfer(self, motion: Motion, targets: Sequence[Motion]) -> Motion:
        """Re-enact ``motion`` with the target character's clips (Sec. 4, Alg. 1, Eq. 9).

        :func:`skelagnostic_vqpae.transfer.transfer_clips`: the targets (one trained
        character) become a motion-matching database that the source's manifold points
        and frequencies query (frequency-scaled motion matching); the matched windows,
        time-warped to the source's periods, form the result, on the targets' skeleton
        at the trained frame rate. The frames where a new window starts are kept in
        :attr:`last_transitions`.

        Raises:
            SkelagnosticError: ``targets`` is empty, mixes characters, or a skeleton
                was not trained.
        """
        motion, self.last_transitions = transfer_clips(self, motion, list(targets))
        return motion
