"""skelagnostic.viz stays light: no lightning/hydra/pluggy, matplotlib only on use."""

from __future__ import annotations

import subprocess
import sys


def test_import_viz_pulls_no_framework_and_no_matplotlib():
    code = (
        "import sys, skelagnostic.viz\n"
        "heavy = [m for m in ('lightning', 'hydra', 'pluggy', 'matplotlib') if m in sys.modules]\n"
        "print(heavy)\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    assert result.stdout.strip() == "[]"
