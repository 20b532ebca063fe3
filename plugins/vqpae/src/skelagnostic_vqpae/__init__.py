"""VQ-PAE (WalkTheDog, Li et al. 2024): a phase manifold shared by characters of any skeleton.

Registered as ``model=vqpae`` through the ``skelagnostic`` entry-point group
(:mod:`skelagnostic_vqpae.plugin`). Modules: :mod:`~skelagnostic_vqpae.model`
(the periodic autoencoder), :mod:`~skelagnostic_vqpae.codebook` (the shared
codebook), :mod:`~skelagnostic_vqpae.data` (frame windows, data module),
:mod:`~skelagnostic_vqpae.training` (training and inference),
:mod:`~skelagnostic_vqpae.embed` (clip embeddings, retrieval),
:mod:`~skelagnostic_vqpae.transfer` (frequency-scaled motion matching),
:mod:`~skelagnostic_vqpae.protocols` (evaluation protocols and the fit summary),
:mod:`~skelagnostic_vqpae.authors` (runs of the authors' trainer, loaded) and
:mod:`~skelagnostic_vqpae.aligner` (:class:`VqpaeAligner`: the model with its fit
summary and transfer). Floors import downwards only (model < embed < transfer <
protocols < aligner, authors < plugin).
Imports are lazy: ``import skelagnostic_vqpae`` loads no model code until one of
the names below is used.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from skelagnostic.lazy import lazy_exports
from skelagnostic.version import distribution_version

__all__ = ["VqpaeAligner", "VqpaeDataModule"]
#: Version of the distribution that ships this plugin (built-in: skelagnostic's).
__version__ = distribution_version("skelagnostic")

__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "VqpaeAligner": "skelagnostic_vqpae.aligner",
        "VqpaeDataModule": "skelagnostic_vqpae.data",
    },
)

if TYPE_CHECKING:  # pragma: no cover
    from skelagnostic_vqpae.aligner import VqpaeAligner
    from skelagnostic_vqpae.data import VqpaeDataModule
