"""The benchmark harness runs every suite at smoke size and writes the fixed JSON format."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
#: Suites checked here (extend when a suite is added to benchmarks/run.py).
SUITES = [
    "io", "kinematics", "matching", "bigdata", "training", "quality", "inference", "scaling",
    "allocators", "startup",
]  # fmt: skip
RESULT_KEYS = {
    "name", "unit", "value", "baseline", "baseline_value", "speedup", "higher_is_better",
}  # fmt: skip


def check_report(report: dict, suite: str) -> None:
    assert set(report) == {"suite", "machine", "versions", "results"}
    assert report["suite"] == suite
    machine = report["machine"]
    assert {"cpu_count", "platform", "processor", "ram_gib"} <= set(machine)
    assert isinstance(machine["cpu_count"], int) and machine["cpu_count"] >= 1
    versions = report["versions"]
    assert {"python", "torch", "numpy", "skelagnostic"} <= set(versions)
    assert all(isinstance(v, str) for k, v in versions.items() if k != "skelagnostic")
    assert report["results"], "a suite must report at least one figure"
    assert machine["load_average_start"] >= 0 and machine["load_average_end"] >= 0
    wall = report["results"][-1]
    assert wall["name"] == "wall_time" and wall["unit"] == "s" and wall["value"] > 0
    names = [r["name"] for r in report["results"]]
    assert len(names) == len(set(names)), "result names must be unique"
    for r in report["results"]:
        assert set(r) == RESULT_KEYS
        assert isinstance(r["name"], str) and isinstance(r["unit"], str)
        assert isinstance(r["value"], float) and math.isfinite(r["value"])
        assert isinstance(r["higher_is_better"], bool)
        if r["baseline_value"] is None:
            assert r["speedup"] is None
            continue
        assert isinstance(r["baseline"], str) and r["baseline"]
        num, den = (
            (r["value"], r["baseline_value"])
            if r["higher_is_better"]
            else (r["baseline_value"], r["value"])
        )
        if den == 0:
            assert r["speedup"] is None
        else:
            assert r["speedup"] == pytest.approx(num / den)


@pytest.mark.slow
@pytest.mark.parametrize("suite", SUITES)
def test_suite_smoke_writes_valid_json(suite: str, tmp_path: Path) -> None:
    out = tmp_path / f"{suite}.json"
    proc = subprocess.run(
        [sys.executable, "benchmarks/run.py", "--suite", suite, "--size", "smoke",
         "--threads", "1", "--json", str(out)],
        cwd=REPO_ROOT, capture_output=True, text=True, timeout=600, check=False,
    )  # fmt: skip
    if proc.returncode != 0 and "MachineBusyError" in proc.stderr:  # benchmarks.harness
        pytest.skip(f"the machine is busy: {proc.stderr.strip().splitlines()[-1]}")
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert suite in proc.stdout  # the rich table was printed
    check_report(json.loads(out.read_text()), suite)


def test_speedup_is_above_one_when_we_are_better() -> None:
    sys.path.insert(0, str(REPO_ROOT))
    try:
        from benchmarks.harness import Result
    finally:
        sys.path.remove(str(REPO_ROOT))
    faster = Result("q", "ms", 2.0, "naive", 10.0)
    assert faster.speedup == 5.0
    better = Result("r", "fraction", 0.5, "naive", 0.25, higher_is_better=True)
    assert better.speedup == 2.0
    assert Result("x", "ms", 1.0).to_dict()["speedup"] is None
    # a zero numerator is a real ratio; a zero denominator has none
    assert Result("o", "share", 0.0, "ablation", 0.5, higher_is_better=True).speedup == 0.0
    assert Result("o", "share", 0.5, "ablation", 0.0, higher_is_better=True).speedup is None
    assert Result("t", "ms", 0.0, "naive", 1.0).speedup is None


def test_training_parts_add_a_gpu_when_torch_sees_one(monkeypatch: pytest.MonkeyPatch) -> None:
    import torch

    sys.path.insert(0, str(REPO_ROOT))
    try:
        from benchmarks.suites.steptime import accelerators, suffix
    finally:
        sys.path.remove(str(REPO_ROOT))
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert accelerators() == ["cpu"]
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    assert accelerators() == ["cpu", "gpu"]
    # CPU figures keep their names (external tooling reads them); GPU ones get a suffix
    assert suffix("cpu") == "" and suffix("gpu") == "_gpu"
