"""The stage-2 fast-path comparison (benchmarks/pcmrl_fastpath.py) on a real clip."""

from __future__ import annotations

import json
from pathlib import Path
from types import ModuleType

import pytest

from script_loader import load_script


def _script() -> ModuleType:
    return load_script("benchmarks/pcmrl_fastpath.py", "pcmrl_fastpath")


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
        s["flops_fast"] for s in result["steps"]
    )
    assert result["total_flop_ratio"] == pytest.approx(total)
