"""``data.up`` / ``data.forward``: Z-up exports in a data module, detection in the log line."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest

import skelagnostic as sa
from skelagnostic.cli import app
from skelagnostic.core.axes import AxesError
from skelagnostic.data import BVHSource, MotionDataModule, preset_source
from skelagnostic.data.sources import bvh_sources
from skelagnostic.errors import SkelagnosticError

CLIPS = ("human/cmu/131_01.bvh", "dog/mann/D1_001_KAN01_001.bvh")


@pytest.fixture(scope="module")
def exports(shared_data: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """Two short real clips as they are (Y up) and as Z-up, +Y-facing exports."""
    y_up, z_up = tmp_path_factory.mktemp("y_up"), tmp_path_factory.mktemp("z_up")
    for clip in CLIPS:
        motion = sa.read_bvh(shared_data / clip)[:90]
        name = Path(clip).name
        sa.write_bvh(motion, y_up / name)
        sa.write_bvh(motion, z_up / name, up="z", forward="y")
    return y_up, z_up


def _windows(dm: MotionDataModule) -> dict[str, np.ndarray]:
    """Every training window of each dataset, stacked in order."""
    dm.setup()
    out = {}
    for name in dm.dataset_names:
        ds = dm.datasets["train"][name]
        out[name] = np.stack([ds[i]["features"].numpy() for i in range(len(ds))])
    return out


@pytest.mark.parametrize(("up", "forward"), [("z", "y"), ("auto", "y"), ("auto", "auto")])
def test_z_up_files_give_the_windows_of_the_y_up_files(
    exports: tuple[Path, Path], up: str, forward: str, tmp_path: Path, caplog
) -> None:
    y_up, z_up = exports
    options = {"window": 16, "stride": 16, "fps": 30, "val_fraction": 0.0}
    plain = MotionDataModule(BVHSource([y_up], units="cm"), cache_dir=tmp_path, **options)
    source = BVHSource([z_up], units="cm", up=up, forward=forward)
    turned = MotionDataModule(source, cache_dir=tmp_path, **options)
    with caplog.at_level(logging.INFO):
        got = _windows(turned)
    expected = _windows(plain)
    if forward == "auto":  # the dog's rest pose faces -X: its file forward is found as x
        del expected["bvh/D1_001_KAN01_001"], got["bvh/D1_001_KAN01_001"]
    assert expected.keys() == got.keys()
    for name, windows in expected.items():
        np.testing.assert_allclose(got[name], windows, atol=1e-4)
    lines = [r.getMessage() for r in caplog.records if "dataset 'bvh/131_01'" in r.getMessage()]
    detected = {"z": "", "auto": " (up detected)"}[up] if forward != "auto" else " (up and "
    assert lines and f"file axes up z, forward y{detected}" in lines[0]


def test_the_dog_rest_pose_faces_minus_x_in_the_log(
    exports: tuple[Path, Path], tmp_path: Path, caplog
) -> None:
    source = BVHSource([exports[1]], pattern="D1_*.bvh", up="auto", forward="auto")
    with caplog.at_level(logging.INFO):
        MotionDataModule(source, window=16, stride=16, cache_dir=tmp_path).setup()
    assert "file axes up z, forward x (up and forward detected)" in caplog.text


def test_bad_axes_name_the_option(exports: tuple[Path, Path]) -> None:
    with pytest.raises(AxesError, match=r"data\.up='w' is not an axis"):
        BVHSource([exports[0]], up="w")
    with pytest.raises(AxesError, match=r"data\.up, data\.forward: .* same axis"):
        BVHSource([exports[0]], up="z", forward="-z")
    with pytest.raises(SkelagnosticError, match=r"data\.paths\[0\]: data\.forward='q'"):
        bvh_sources([{"path": exports[0], "forward": "q"}])


def test_path_entries_and_presets_take_axes(exports: tuple[Path, Path]) -> None:
    y_up, z_up = exports
    human, blender = bvh_sources([{"path": y_up, "name": "h"}, {"path": z_up, "up": "z"}])
    assert (human.up, blender.up, blender.forward) == (None, "z", None)
    assert preset_source("mann_dog", z_up, up="auto").loading()["up"] == "auto"
    # the same files read with other axes are other windows: the cache key changes
    assert BVHSource([z_up]).loading() != BVHSource([z_up], up="z").loading()


def test_configs_route_up_and_forward_to_the_source(
    exports: tuple[Path, Path], example_plugin: Path
) -> None:
    pm = sa.plugins.PluginManager()  # the example plugin, installed by the fixture
    for data in (
        ["data=bvh", f"data.paths=[{exports[1]}]"],
        ["data=cmu", f"data.root={exports[1]}"],
    ):
        overrides = ["model=example", "run_dir=/tmp/x", *data, "data.up=z", "data.forward=y"]
        cfg = app.compose(overrides, plugin_manager=pm)
        (source,) = app.build_datamodule(cfg, pm).sources
        assert (source.up, source.forward) == ("z", "y")
    overrides = ["model=example", "run_dir=/tmp/x", "data=bvh", f"data.paths=[{exports[1]}]"]
    cfg = app.compose(overrides, plugin_manager=pm)
    cfg.data.up = "w"
    with pytest.raises(AxesError, match=r"data\.up='w'"):
        app.build_datamodule(cfg, pm)


def test_log_line_counts_clips_read_with_different_axes() -> None:
    from types import SimpleNamespace

    from skelagnostic.data.describe import describe_axes

    def member(axes: dict | None) -> tuple[None, SimpleNamespace]:
        return None, SimpleNamespace(meta={} if axes is None else {"axes": axes})

    z = {"up": "z", "forward": "-y", "detected": ["up"]}
    y = {"up": "y", "forward": "z", "detected": []}
    assert describe_axes([member(z), member(z)]) == ", file axes up z, forward -y (up detected)"
    assert describe_axes([member(None)]) == ""  # an entry cached before axes were recorded
    assert describe_axes([member(z), member(y), member(z)]) == (
        ", file axes up z, forward -y (up detected): 2 clip(s); up y, forward z: 1 clip(s)"
    )
