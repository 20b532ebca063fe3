"""The stage-2 training probe (benchmarks/pcmrl_interp_probe.py) on a real clip."""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import ModuleType

import pytest

from script_loader import load_script


def _probe() -> ModuleType:
    return load_script("benchmarks/pcmrl_interp_probe.py", "interp_probe")


@pytest.mark.data
def test_probe_compares_with_lerp_and_learns(lafan_clip: Path, tmp_path: Path) -> None:
    probe = _probe()
    common = [
        "--train",
        str(lafan_clip),
        "--test",
        str(lafan_clip),
        "--units",
        "cm",
        "--data",
        "key_mode=regular",
    ]
    tiny = ["--model", "dim=16", "heads=2", "layers=1"]
    # no training step: the zero-initialised residual model IS the LERP baseline
    assert probe.main([*common, *tiny, "--minutes", "0", "--json", str(tmp_path / "a.json")]) == 0
    untrained = json.loads((tmp_path / "a.json").read_text())["trajectory"][-1]
    for figures in untrained["probe"].values():
        assert figures["ratio"] == pytest.approx(1.0, abs=1e-9)
        assert 0.01 < figures["lerp_m"] < 1.0  # metres: centimetres of LERP error
    # a few steps later the model is not the baseline any more
    assert (
        probe.main(
            [
                *common,
                *tiny,
                "interm_tokens=lerp",
                "--minutes",
                "0.05",
                "--every",
                "3",
                "--ema",
                "0.5",
                "--json",
                str(tmp_path / "b.json"),
            ]
        )
        == 0
    )
    trained = json.loads((tmp_path / "b.json").read_text())
    assert trained["model"]["interm_tokens"] == "lerp" and trained["model"]["dim"] == 16
    assert trained["data"]["key_mode"] == "regular"
    last = trained["trajectory"][-1]
    assert last["step"] >= 1
    assert all(math.isfinite(f["ratio"]) and f["ratio"] != 1.0 for f in last["probe"].values())
    # the EMA of the weights is probed beside them, and is neither them nor the start
    for gap, figures in last["probe_ema"].items():
        assert figures["lerp_m"] == last["probe"][gap]["lerp_m"]
        assert figures["ratio"] not in (1.0, last["probe"][gap]["ratio"])
    with pytest.raises(SystemExit, match="decay"):
        probe.main([*common, *tiny, "--minutes", "0", "--ema", "1.5"])


def test_probe_reads_options_as_yaml_values() -> None:
    probe = _probe()
    assert probe._options(
        ["lr=3e-3", "dim=16", "residual=false", "interm_tokens=lerp"], "--model"
    ) == {"lr": 0.003, "dim": 16, "residual": False, "interm_tokens": "lerp"}
    with pytest.raises(SystemExit, match="key=value"):
        probe._options(["lr"], "--model")
