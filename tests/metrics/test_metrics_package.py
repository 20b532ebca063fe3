"""Package-level contract of skelagnostic.metrics: public names, runnable docstring examples.

That the package imports no lightning, hydra or pluggy is checked in tests/test_layering.py.
"""

from __future__ import annotations

import doctest
import importlib

import pytest

MODULES = [
    "skelagnostic.metrics",
    "skelagnostic.metrics.functional",
    "skelagnostic.metrics.functional.positions",
    "skelagnostic.metrics.functional.lafan",
    "skelagnostic.metrics.functional.manifold",
    "skelagnostic.metrics.functional.point_cloud",
    "skelagnostic.metrics.functional.feet",
    "skelagnostic.metrics.positions",
    "skelagnostic.metrics.lafan",
    "skelagnostic.metrics.manifold",
    "skelagnostic.metrics.point_cloud",
    "skelagnostic.metrics.feet",
]


def test_public_names():
    import skelagnostic.metrics as metrics
    from skelagnostic.metrics import functional

    assert set(metrics.__all__) == {
        "MPJPE",
        "L2P",
        "L2Q",
        "NPSS",
        "ManifoldOverlap",
        "BoneLengthConsistency",
        "TemporalKNNDistance",
        "EndEffectorError",
        "FootSkate",
        "FootSkateRatio",
        "functional",
    }
    for name in ("mpjpe", "l2p", "l2q", "npss", "manifold_overlap", "foot_skate"):
        assert callable(getattr(functional, name))


@pytest.mark.parametrize("module", MODULES)
def test_docstring_examples_run(module):
    result = doctest.testmod(importlib.import_module(module), raise_on_error=False)
    assert result.failed == 0
    assert result.attempted > 0
