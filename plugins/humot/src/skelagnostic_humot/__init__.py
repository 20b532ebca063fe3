"""HuMoT (Mourot et al.): a topology-agnostic transformer autoencoder for human motion.

Registered as ``model=humot`` through the ``skelagnostic`` entry-point group
(:mod:`skelagnostic_humot.plugin`). Modules: :mod:`~skelagnostic_humot.xcit`
(XCiT blocks), :mod:`~skelagnostic_humot.model` (network and losses),
:mod:`~skelagnostic_humot.template` (templates, major joints, axes),
:mod:`~skelagnostic_humot.data` (chunks, joint subsampling, data module),
:mod:`~skelagnostic_humot.aligner` (training and inference),
:mod:`~skelagnostic_humot.evaluation` (paper evaluations, one module per protocol),
:mod:`~skelagnostic_humot.receptive` (receptive field of the encoder).
Imports are lazy: ``import skelagnostic_humot`` loads no model code until one of
the names below is used.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from skelagnostic.lazy import lazy_exports
from skelagnostic.version import distribution_version

__all__ = ["HuMoT", "HumotAligner", "HumotDataModule", "ReceptiveField", "receptive_field"]
#: Version of the distribution that ships this plugin (built-in: skelagnostic's).
__version__ = distribution_version("skelagnostic")

__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "HuMoT": "skelagnostic_humot.model",
        "HumotAligner": "skelagnostic_humot.aligner",
        "HumotDataModule": "skelagnostic_humot.data",
        "ReceptiveField": "skelagnostic_humot.receptive",
        "receptive_field": "skelagnostic_humot.receptive",
    },
)

if TYPE_CHECKING:  # pragma: no cover
    from skelagnostic_humot.aligner import HumotAligner
    from skelagnostic_humot.data import HumotDataModule
    from skelagnostic_humot.model import HuMoT
    from skelagnostic_humot.receptive import ReceptiveField, receptive_field
