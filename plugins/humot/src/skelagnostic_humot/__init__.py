"""HuMoT (Mourot et al.): a topology-agnostic transformer autoencoder for human motion.

Registered as ``model=humot`` through the ``skelagnostic`` entry-point group
(:mod:`skelagnostic_humot.plugin`). Modules: :mod:`~skelagnostic_humot.xcit`
(XCiT blocks), :mod:`~skelagnostic_humot.model` (network and losses),
:mod:`~skelagnostic_humot.template` (templates, major joints, axes),
:mod:`~skelagnostic_humot.data` (chunks, joint subsampling, data module),
:mod:`~skelagnostic_humot.aligner` (training and inference),
:mod:`~skelagnostic_humot.evaluation` (paper evaluations and protocols).
"""

from skelagnostic_humot.aligner import HumotAligner
from skelagnostic_humot.data import HumotDataModule
from skelagnostic_humot.model import HuMoT

__all__ = ["HuMoT", "HumotAligner", "HumotDataModule"]
__version__ = "0.1.0"
