"""Every PC-MRL preset lists its deviations from the paper, exactly (issue #26, item 7).

The model defaults (``model=pcmrl``, ``model=pcmrl_interp``) are the paper's settings.
Each experiment preset's header has a block

    # Deviations from the paper (...):
    #   - model.KEY=VALUE: why
    #   - data.KEY=VALUE: why
    #   - callbacks=NAME: why

(or ``#   none``). The documented ``model.*`` entries must be exactly the model keys
whose composed value differs from the model defaults, with those values; ``data.*``
entries must hold in the composed config; ``callbacks=NAME`` must be one of the
preset's overrides. The PC-MRL guide's table of presets must name every documented
model key, so neither the comments nor the guide can drift from the configs.
"""

from __future__ import annotations

import re
from importlib.resources import files
from pathlib import Path
from typing import Any

import pytest
import yaml
from omegaconf import OmegaConf

from skelagnostic.cli import app
from skelagnostic.plugins import read_aligner_config

REPO = Path(__file__).resolve().parents[2]
EXPERIMENTS = REPO / "plugins" / "pcmrl" / "src" / "skelagnostic_pcmrl" / "conf" / "experiment"
GUIDE = REPO / "docs" / "methods" / "pcmrl.md"
PRESETS = sorted(p.stem for p in EXPERIMENTS.glob("*.yaml"))
HEADER = re.compile(r"^# Deviations from the paper \(checked against model=(\w+)")
ENTRY = re.compile(r"^#\s+- ((?:model|data)\.[\w.]+=\S+|callbacks=\w+): \S")


def _dotted(mapping: Any, prefix: str) -> dict[str, Any]:
    """``{"optimizer": {"lr": 1}}`` -> ``{"<prefix>optimizer.lr": 1}`` (nested options by key)."""
    out: dict[str, Any] = {}
    for key, value in mapping.items():
        if isinstance(value, dict) and value:
            out.update(_dotted(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def deviations(preset: str) -> tuple[str, dict[str, Any], bool]:
    """``(model name, {"model.KEY" | "data.KEY" | "callbacks": value}, says_none)``."""
    lines = (EXPERIMENTS / f"{preset}.yaml").read_text(encoding="utf-8").splitlines()
    starts = [i for i, line in enumerate(lines) if HEADER.match(line)]
    assert len(starts) == 1, f"{preset}.yaml: no (or several) 'Deviations from the paper' block"
    model = HEADER.match(lines[starts[0]]).group(1)  # type: ignore[union-attr]
    out: dict[str, Any] = {}
    none = False
    for line in lines[starts[0] + 1 :]:
        if not line.startswith("#"):
            break
        if line.strip("# ") == "none":
            none = True
            continue
        found = ENTRY.match(line)
        if found is None:
            if re.match(r"^#\s+-", line):
                pytest.fail(f"{preset}.yaml: unreadable deviation line {line!r}")
            continue
        key, _, value = found.group(1).partition("=")
        out[key] = yaml.safe_load(value)
    return model, out, none


def test_every_preset_is_checked() -> None:
    assert {
        "pcmrl_cpu",
        "pcmrl_quick",
        "pcmrl_lafan1_cmu",
        "pcmrl_paper",
        "pcmrl_interp_cpu",
        "pcmrl_interp_cmu",
        "pcmrl_interp_stage1",
        "pcmrl_cpu2h",
        "pcmrl_interp_cpu2h",
    } <= set(PRESETS)


@pytest.mark.parametrize(
    ("model", "preset", "steps"),
    [("pcmrl", "pcmrl_cpu2h", 7700), ("pcmrl_interp", "pcmrl_interp_cpu2h", 32000)],
)
def test_budget_presets_train_on_the_lafan1_train_split(pcmrl_pm, tmp_path, model, preset, steps):
    """The 2-hour presets: data=lafan1 (subject 5 held out), a step budget and a time guard."""
    cfg = app.compose(
        [f"model={model}", f"experiment={preset}", f"run_dir={tmp_path}"], plugin_manager=pcmrl_pm
    )
    assert cfg.model.name == model and cfg.data.source == "lafan1" and cfg.data.root is None
    assert cfg.trainer.max_steps == steps and cfg.trainer.max_time == "00:02:30:00"
    if model == "pcmrl":
        assert str(cfg.data.target).endswith("human/cmu/131_01.bvh")
        assert cfg.data.target_units == "cmu"
    else:
        assert cfg.data.val_fraction == 0.0
        assert cfg.callbacks.ema._target_ == "skelagnostic.callbacks.EMAWeights"


@pytest.mark.parametrize("preset", PRESETS)
def test_documented_deviations_are_exactly_the_overrides(pcmrl_pm, tmp_path, preset) -> None:
    model, documented, none = deviations(preset)
    assert none == (not documented), f"{preset}.yaml: list the deviations or say 'none'"
    cfg = app.compose(
        [f"model={model}", f"experiment={preset}", f"run_dir={tmp_path}"], plugin_manager=pcmrl_pm
    )
    defaults = read_aligner_config(files("skelagnostic_pcmrl.conf") / f"{model}.yaml")["model"]
    composed = _dotted(OmegaConf.to_container(cfg.model, resolve=False), "model.")
    default = _dotted(defaults, "model.")
    changed = {k: v for k, v in composed.items() if k in default and v != default[k]}
    assert {k: v for k, v in documented.items() if k.startswith("model.")} == changed
    for key, value in documented.items():
        if key.startswith("data."):
            assert cfg.data[key[5:]] == value, f"{preset}.yaml documents {key}={value}"
        elif key == "callbacks":
            text = yaml.safe_load((EXPERIMENTS / f"{preset}.yaml").read_text(encoding="utf-8"))
            assert {"override /callbacks": value} in text["defaults"], key


@pytest.mark.parametrize("preset", PRESETS)
def test_the_guide_table_names_every_deviation(preset) -> None:
    _, documented, none = deviations(preset)
    rows = [
        line
        for line in GUIDE.read_text(encoding="utf-8").splitlines()
        if line.startswith(f"| `{preset}` |")
    ]
    assert len(rows) == 1, f"docs/methods/pcmrl.md: no row for {preset} in the preset table"
    for key in documented:
        name = {"model": key[6:], "callbacks": f"callbacks={documented[key]}"}.get(
            key.split(".")[0], key
        )
        assert f"`{name}" in rows[0], f"the guide's {preset} row does not name {key}"
    if none:
        assert "none" in rows[0]
