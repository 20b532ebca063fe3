"""PC-MRL (Mo et al.): point-cloud motion representation learning for any human skeleton.

Registered through the ``skelagnostic`` entry-point group
(:mod:`skelagnostic_pcmrl.plugin`) as ``model=pcmrl`` (stage 1, reconstruction)
and ``model=pcmrl_interp`` (stage 2, keyframe interpolation). One subpackage per
stage: :mod:`skelagnostic_pcmrl.recon` (point encoder, temporal transformer,
losses, the stage-1 aligner and data module) and :mod:`skelagnostic_pcmrl.interp`
(keyframe features, the CITL network, rest pose augmentation, the stage-2 aligner,
data module and Table 1 protocol). What both stages use stays at the top:
:mod:`~skelagnostic_pcmrl.points` (point sampling, zero-length bones, Eq. 1 and 3),
:mod:`~skelagnostic_pcmrl.layouts` (the networks' parameter layouts),
:mod:`~skelagnostic_pcmrl.authors` (the authors' checkpoints of both stages) and
:mod:`~skelagnostic_pcmrl.evaluation` (paper Table 2 and the protocols).
Imports are lazy: ``import skelagnostic_pcmrl`` loads no model code.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from skelagnostic.lazy import lazy_exports
from skelagnostic.version import distribution_version

__all__ = [
    "PcmrlInterpAligner",
    "PcmrlInterpDataModule",
    "PcmrlReconAligner",
    "PcmrlReconDataModule",
]
#: Version of the distribution that ships this plugin (built-in: skelagnostic's).
__version__ = distribution_version("skelagnostic")

__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "PcmrlInterpAligner": "skelagnostic_pcmrl.interp.aligner",
        "PcmrlInterpDataModule": "skelagnostic_pcmrl.interp.data",
        "PcmrlReconDataModule": "skelagnostic_pcmrl.recon.data",
        "PcmrlReconAligner": "skelagnostic_pcmrl.recon.aligner",
    },
)

if TYPE_CHECKING:  # pragma: no cover
    from skelagnostic_pcmrl.interp.aligner import PcmrlInterpAligner
    from skelagnostic_pcmrl.interp.data import PcmrlInterpDataModule
    from skelagnostic_pcmrl.recon.aligner import PcmrlReconAligner
    from skelagnostic_pcmrl.recon.data import PcmrlReconDataModule
