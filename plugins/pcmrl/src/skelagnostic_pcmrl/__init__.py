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

from typing import Any

__all__ = ["PcmrlReconDataModule", "PcmrlReconstruction"]
__version__ = "0.1.0"


def __getattr__(name: str) -> Any:
    if name == "PcmrlReconstruction":
        from skelagnostic_pcmrl.recon import PcmrlReconstruction

        return PcmrlReconstruction
    if name == "PcmrlReconDataModule":
        from skelagnostic_pcmrl.recon_data import PcmrlReconDataModule

        return PcmrlReconDataModule
    raise AttributeError(f"module 'skelagnostic_pcmrl' has no attribute {name!r}")
