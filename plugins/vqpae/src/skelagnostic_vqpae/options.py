"""VQ-PAE's option values: what the aligner's options may be, and the named sets of them.

:data:`PLUS_OPTIONS` are skelagnostic's changes to the authors' training
(``experiment=vqpae_plus``); :data:`PREVIOUS_DEFAULTS` what older checkpoints were
trained with. Re-exported by :mod:`skelagnostic_vqpae.aligner`.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

__all__ = [
    "AUTHORS_OPTIMIZER",
    "AUTHORS_SCHEDULER",
    "COSINE_SCHEDULER",
    "PHASE_RATE_GRADS",
    "PLUS_OPTIONS",
    "POSE_MODES",
    "PREVIOUS_DEFAULTS",
    "DatasetSpec",
]

#: What the average-pose MLPs do (``model.pose_mlp``).
POSE_MODES = ("none", "detached", "joint")
#: What the phase-rate loss trains (``model.phase_rate_grad``).
PHASE_RATE_GRADS = ("network", "timing", "head")

#: The authors' optimizer (``model.optimizer``): AdamW, ``--learning_rate`` and
#: ``--weight_decay`` 1e-4.
AUTHORS_OPTIMIZER = MappingProxyType(
    {"_target_": "torch.optim.AdamW", "_partial_": True, "lr": 1e-4, "weight_decay": 1e-4}
)
#: The authors' schedule (``model.scheduler``): ``CyclicLRWithRestarts``, a first cycle of
#: ``--restart_period`` 10 epochs growing by ``--restart_mult`` 2.
AUTHORS_SCHEDULER = MappingProxyType(
    {
        "_target_": "skelagnostic_vqpae.schedule.authors_restarts",
        "_partial_": True,
        "period": 10,
        "mult": 2,
    }
)
#: PyTorch's cosine annealing with warm restarts (the default before the authors').
COSINE_SCHEDULER = MappingProxyType(
    {
        "_target_": "skelagnostic_vqpae.schedule.cosine_restarts",
        "_partial_": True,
        "period": 10,
        "mult": 2,
    }
)

#: skelagnostic's changes to the authors' training, enabled together by
#: ``experiment=vqpae_plus`` (conf/experiment/vqpae_plus.yaml holds the same values; a test
#: checks it). docs/reports/vqpae.md lists each with the authors' value and the reason.
PLUS_OPTIONS: dict[str, Any] = {
    "freq_layers": 5,
    "decoder_centering": False,
    "spectrum": "normalized",
    "padding_mode": "replicate",
    "frequency_head": "centroid_residual",
    "phase_kernel": 1,
    "freq_hidden_elu": False,
    "center_windows": True,
    "lambda_phase_rate": 1.0,
    "reinit_squared_distance": False,
    "pose_mlp": "detached",
}

#: The defaults before they became the authors' (with the cosine schedule): what a
#: checkpoint lacking one of these hyperparameters was trained with, and what the presets
#: written for them (``vqpae_main``, ``vqpae_human_dog``, ``vqpae_stylized``) still use.
PREVIOUS_DEFAULTS: dict[str, Any] = {
    **PLUS_OPTIONS,
    "frequency_head": "mlp",
    "scheduler": dict(COSINE_SCHEDULER),
}

#: Per dataset: ``{"channels", "window", "fps", "skeleton" (Skeleton.to_dict())}``; a run
#: of the authors' trainer (:mod:`~skelagnostic_vqpae.authors`) has no skeleton unless one
#: is given, and with its phase decoders ``"pose_channels"`` (their output size) and
#: ``"pose_features"`` (their feature names).
DatasetSpec = Mapping[str, Any]
