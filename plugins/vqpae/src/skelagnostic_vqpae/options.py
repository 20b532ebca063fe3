"""VQ-PAE's option values: what the aligner's options may be, and the named sets of them.

:data:`PLUS_OPTIONS` are skelagnostic's changes to the authors' training
(``experiment=vqpae_plus``); :data:`PREVIOUS_DEFAULTS` what older checkpoints were
trained with. Re-exported by :mod:`skelagnostic_vqpae.aligner`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

__all__ = [
    "PHASE_RATE_GRADS",
    "PLUS_OPTIONS",
    "POSE_MODES",
    "PREVIOUS_DEFAULTS",
    "SCHEDULES",
    "DatasetSpec",
]

#: What the average-pose MLPs do (``model.pose_mlp``).
POSE_MODES = ("none", "detached", "joint")
#: What the phase-rate loss trains (``model.phase_rate_grad``).
PHASE_RATE_GRADS = ("network", "timing", "head")

#: Learning-rate schedules (``model.schedule``).
SCHEDULES = ("authors", "cosine")

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

#: The defaults before they became the authors' (with ``schedule="cosine"``): what a
#: checkpoint lacking one of these hyperparameters was trained with, and what the presets
#: written for them (``vqpae_main``, ``vqpae_human_dog``, ``vqpae_stylized``) still use.
PREVIOUS_DEFAULTS: dict[str, Any] = {**PLUS_OPTIONS, "frequency_head": "mlp", "schedule": "cosine"}

#: Per dataset: ``{"channels", "window", "fps", "skeleton" (Skeleton.to_dict())}``; a run
#: of the authors' trainer (:mod:`~skelagnostic_vqpae.authors`) has no skeleton unless one
#: is given, and with its phase decoders ``"pose_channels"`` (their output size) and
#: ``"pose_features"`` (their feature names).
DatasetSpec = Mapping[str, Any]
