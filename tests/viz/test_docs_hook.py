"""The MkDocs hook that renders the docs' example images (docs/hooks/render_examples.py)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from script_loader import load_script

DOCS = Path(__file__).resolve().parents[2] / "docs"


@pytest.fixture(scope="module")
def hook():
    return load_script("docs/hooks/render_examples.py", "render_examples")


@pytest.mark.slow
def test_pre_build_renders_every_image_the_page_shows(hook, tmp_path):
    hook.on_pre_build({"docs_dir": str(tmp_path)})
    out = tmp_path / "assets" / "generated"
    assert (out / ".gitignore").read_text().strip().endswith("*")
    shown = set(re.findall(r"assets/generated/([\w.]+)", (DOCS / "viz.md").read_text()))
    written = {p.name for p in out.iterdir() if p.name != ".gitignore"}
    assert shown and shown == written
    for name in written:
        with Image.open(out / name) as image:
            assert image.size[0] > 100 and image.size[1] > 100
            frames = getattr(image, "n_frames", 1)
            image.seek(frames // 2)
            assert np.asarray(image.convert("RGB")).min() < 100, name
    with Image.open(out / "side_by_side.gif") as gif:
        assert gif.n_frames == 31 and gif.size == (720, 240)
    # deterministic output: a second build rewrites nothing (no `mkdocs serve` rebuild loop)
    stamps = {p.name: p.stat().st_mtime_ns for p in out.iterdir()}
    assert hook.generate(out) == []
    assert stamps == {p.name: p.stat().st_mtime_ns for p in out.iterdir()}
