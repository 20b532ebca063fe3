"""What the networks of both PC-MRL stages share: their two parameter layouts.

``layout="skelagnostic"`` builds this package's networks; ``layout="authors"``
builds the networks of the authors' code, whose checkpoints
:mod:`skelagnostic_pcmrl.authors` reads. The stage-1 encoder and temporal
transformer (:mod:`skelagnostic_pcmrl.recon`) and the stage-2 interpolator
(:mod:`skelagnostic_pcmrl.interp`) take the same values.
"""

from __future__ import annotations

__all__ = ["AUTHORS_RMS_EPS", "LAYOUTS"]

#: Values of the ``layout`` option of the PC-MRL networks (encoder, temporal, CITL).
LAYOUTS = ("skelagnostic", "authors")
#: RMSNorm epsilon inside the square root equivalent to the authors' 1e-8 added to the RMS.
AUTHORS_RMS_EPS = 1e-16
