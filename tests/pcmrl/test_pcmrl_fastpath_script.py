"""The stage-2 fast-path comparison (benchmarks/pcmrl_fastpath.py) on a real clip."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "pcmrl_fastpath.py"


def _script():  # type: ignore[no-untyped-def]
    spec = importlib.util.spec_from_file_location("pcmrl_fastpath", SCRIPT)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.data
def test_fast_path_does_fewer_flops_on_the_same_batches(tmp_path: Path) -> None:
    out = tmp_path / "fastpath.json"
    assert _script().main(["--preset", "cpu2h", "--steps", "2", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["preset"] == "cpu2h" and len(result["steps"]) == 2
    for step in result["steps"]:
        # the keyframe-only encoder skips work on every batch, and the ratio is the counts'
        assert step["flops_fast"] < step["flops_reference"]
        assert step["flop_ratio"] == pytest.approx(step["flops_reference"] / step["flops_fast"])
        assert step["cpu_s_fast"] > 0 and step["cpu_s_reference"] > 0
        assert 2 <= step["keys"] <= 128
    total = sum(s["flops_reference"] for s in result["steps"]) / sum(
        s["flops_fast"] for s in result["steps"])
    assert result["total_flop_ratio"] == pytest.approx(total)
