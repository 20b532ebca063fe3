"""PC-MRL stage 1: unsupervised point-cloud reconstruction onto a target skeleton (Sec. 3.2).

Modules: :mod:`~skelagnostic_pcmrl.recon.fps` (farthest point sampling, kNN),
:mod:`~skelagnostic_pcmrl.recon.point_transformer` (per-frame encoder),
:mod:`~skelagnostic_pcmrl.recon.temporal` (temporal transformer),
:mod:`~skelagnostic_pcmrl.recon.losses` (Eq. 4-6, unit norm),
:mod:`~skelagnostic_pcmrl.recon.aligner`
(:class:`~skelagnostic_pcmrl.recon.aligner.PcmrlReconAligner`, ``model=pcmrl``) and
:mod:`~skelagnostic_pcmrl.recon.data` (its data module). The point sampling both
stages use is :mod:`skelagnostic_pcmrl.points`.
"""
