"""PC-MRL (Mo et al.): point-cloud motion representation learning for any human skeleton.

Registered through the ``skelagnostic`` entry-point group
(:mod:`skelagnostic_pcmrl.plugin`) as ``model=pcmrl`` (stage 1, reconstruction)
and ``model=pcmrl_interp`` (stage 2, keyframe interpolation). Stage-1 modules:
:mod:`~skelagnostic_pcmrl.points` (point sampling, zero-length bones, Eq. 1 and
3), :mod:`~skelagnostic_pcmrl.fps` (farthest point sampling, kNN),
:mod:`~skelagnostic_pcmrl.point_transformer` (per-frame encoder),
:mod:`~skelagnostic_pcmrl.temporal` (temporal transformer),
:mod:`~skelagnostic_pcmrl.losses` (Eq. 5-6, unit norm),
:mod:`~skelagnostic_pcmrl.recon` (the aligner), :mod:`~skelagnostic_pcmrl.recon_data`
(data module), :mod:`~skelagnostic_pcmrl.evaluation` (paper Table 2 and the protocols).
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
        "PcmrlInterpAligner": "skelagnostic_pcmrl.interp_aligner",
        "PcmrlInterpDataModule": "skelagnostic_pcmrl.interp_data",
        "PcmrlReconDataModule": "skelagnostic_pcmrl.recon_data",
        "PcmrlReconAligner": "skelagnostic_pcmrl.recon",
    },
)

if TYPE_CHECKING:  # pragma: no cover
    from skelagnostic_pcmrl.interp_aligner import PcmrlInterpAligner
    from skelagnostic_pcmrl.interp_data import PcmrlInterpDataModule
    from skelagnostic_pcmrl.recon import PcmrlReconAligner
    from skelagnostic_pcmrl.recon_data import PcmrlReconDataModule
