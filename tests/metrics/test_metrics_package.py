"""Package-level contract of skelagnostic.metrics: light imports, runnable docstring examples."""

from __future__ import annotations

import doctest
import importlib
import subprocess
import sys

import pytest

MODULES = [
    "skelagnostic.metrics",
    "skelagnostic.metrics.functional",
    "skelagnostic.metrics.functional.positions",
    "skelagnostic.metrics.functional.lafan",
    "skelagnostic.metrics.functional.manifold",
    "skelagnostic.metrics.functional.point_cloud",
    "skelagnostic.metrics.positions",
    "skelagnostic.metrics.lafan",
    "skelagnostic.metrics.manifold",
    "skelagnostic.metrics.point_cloud",
]


def test_import_pulls_no_framework_dependencies():
    code = (
        "import sys, skelagnostic.metrics, skelagnostic.metrics.functional\n"
        "heavy = sorted(m for m in sys.modules if m.split('.')[0] in "
        "{'lightning', 'pytorch_lightning', 'hydra', 'omegaconf', 'pluggy'})\n"
        "print(','.join(heavy))\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120
    )
    assert result.stdout.strip() == ""


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
        "functional",
    }
    for name in ("mpjpe", "l2p", "l2q", "npss", "manifold_overlap"):
        assert callable(getattr(functional, name))


@pytest.mark.parametrize("module", MODULES)
def test_docstring_examples_run(module):
    result = doctest.testmod(importlib.import_module(module), raise_on_error=False)
    assert result.failed == 0
    assert result.attempted > 0
