"""Motion metrics as torchmetrics ``Metric`` classes, with a functional twin.

Classes (stateful, exact under DDP) live here; the same math as plain
functions lives in :mod:`skelagnostic.metrics.functional`. Importing this
package needs only torch and torchmetrics (no lightning, hydra or pluggy), so
other projects can reuse it cheaply:

    >>> import torch
    >>> from skelagnostic.metrics import MPJPE
    >>> MPJPE(mode="root")(torch.ones(2, 5, 3), torch.zeros(2, 5, 3))
    tensor(0.)
"""

from skelagnostic.metrics import functional
from skelagnostic.metrics.feet import FootSkate, FootSkateRatio
from skelagnostic.metrics.lafan import L2P, L2Q, NPSS
from skelagnostic.metrics.manifold import ManifoldOverlap
from skelagnostic.metrics.point_cloud import TemporalKNNDistance
from skelagnostic.metrics.positions import MPJPE, BoneLengthConsistency, EndEffectorError

__all__ = [
    "L2P",
    "L2Q",
    "MPJPE",
    "NPSS",
    "BoneLengthConsistency",
    "EndEffectorError",
    "FootSkate",
    "FootSkateRatio",
    "ManifoldOverlap",
    "TemporalKNNDistance",
    "functional",
]
