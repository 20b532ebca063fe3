"""Functional metrics: the same math as the :mod:`skelagnostic.metrics` classes, as plain functions.

Every metric ``x`` is split torchmetrics-style into a private ``_x_update``
(validates one batch and returns additive sufficient statistics, e.g. a sum and
a count) and ``_x_compute`` (turns accumulated statistics into the value). The
public function ``x(...)`` is ``_x_compute(*_x_update(...))``; the metric
classes keep the statistics as ``dist_reduce_fx="sum"`` states, which is why
they are exact under DDP.

Each function lives in the module that mirrors its class module (torchmetrics'
layout): :mod:`~skelagnostic.metrics.functional.positions` (``mpjpe``,
``bone_length_consistency``, ``end_effector_error``),
:mod:`~skelagnostic.metrics.functional.lafan` (``l2p``, ``l2q``, ``npss``,
``feature_npss``),
:mod:`~skelagnostic.metrics.functional.manifold` (``manifold_overlap``),
:mod:`~skelagnostic.metrics.functional.feet` (``foot_skate``, ``foot_skate_ratio``) and
:mod:`~skelagnostic.metrics.functional.point_cloud` (``temporal_knn_distance``).
All of them are importable from this package.

Conventions: positions are ``[..., J, 3]`` in the data's units, quaternions are
``(w, x, y, z)``, ``preds`` is the model output and ``target`` the ground truth.
Bad input (wrong shapes or dtypes, NaN/inf, unknown options) raises
`MotionError` naming the argument.

Examples:
    >>> import torch
    >>> from skelagnostic.metrics.functional import mpjpe
    >>> mpjpe(torch.ones(2, 5, 3), torch.zeros(2, 5, 3), mode="root")
    tensor(0.)
"""

# The constants and the ``_x_update`` / ``_x_compute`` halves stay importable from here (as
# before the split into modules) for metric classes written outside this package.
from skelagnostic.metrics.functional._utils import REDUCTIONS as REDUCTIONS
from skelagnostic.metrics.functional._utils import _mean_compute as _mean_compute
from skelagnostic.metrics.functional.feet import foot_skate, foot_skate_ratio
from skelagnostic.metrics.functional.lafan import NPSS_POWERS as NPSS_POWERS
from skelagnostic.metrics.functional.lafan import _l2p_update as _l2p_update
from skelagnostic.metrics.functional.lafan import _l2q_update as _l2q_update
from skelagnostic.metrics.functional.lafan import _npss_update as _npss_update
from skelagnostic.metrics.functional.lafan import feature_npss, l2p, l2q, npss
from skelagnostic.metrics.functional.manifold import (
    _manifold_overlap_compute as _manifold_overlap_compute,
)
from skelagnostic.metrics.functional.manifold import (
    _manifold_overlap_update as _manifold_overlap_update,
)
from skelagnostic.metrics.functional.manifold import manifold_overlap
from skelagnostic.metrics.functional.point_cloud import (
    _temporal_knn_update as _temporal_knn_update,
)
from skelagnostic.metrics.functional.point_cloud import temporal_knn_distance
from skelagnostic.metrics.functional.positions import MPJPE_MODES as MPJPE_MODES
from skelagnostic.metrics.functional.positions import (
    _bone_length_consistency_update as _bone_length_consistency_update,
)
from skelagnostic.metrics.functional.positions import (
    _end_effector_update as _end_effector_update,
)
from skelagnostic.metrics.functional.positions import _mpjpe_update as _mpjpe_update
from skelagnostic.metrics.functional.positions import (
    bone_length_consistency,
    end_effector_error,
    mpjpe,
)

__all__ = [
    "bone_length_consistency",
    "end_effector_error",
    "feature_npss",
    "foot_skate",
    "foot_skate_ratio",
    "l2p",
    "l2q",
    "manifold_overlap",
    "mpjpe",
    "npss",
    "temporal_knn_distance",
]
