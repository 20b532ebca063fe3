"""Render real motion capture (CMU, LaFAN1, MANN dog) and check the written files."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

import skelagnostic as sa
from skelagnostic.viz import render_contact_sheet, render_frames, write_animation

pytestmark = pytest.mark.data

CLIPS = {
    "cmu": ("human/xia_cmu/neutral_01_000.bvh", 120.0),
    "lafan": ("human/lafan1/Lafan1_example.bvh", 30.0),
    "dog": ("dog/mann/D1_007_KAN01_001.bvh", 60.0),
}
LIMBS = {
    "cmu": ("spine", "left_arm", "right_arm", "left_leg", "right_leg"),
    "lafan": ("spine", "left_arm", "right_arm", "left_leg", "right_leg"),
    "dog": ("spine", "left_arm", "right_arm", "left_leg", "right_leg", "tail"),
}


@pytest.fixture(scope="module")
def clips(shared_data):
    """Half a second of each clip (the three have different fps, units and topologies)."""
    out = {}
    for name, (path, fps) in CLIPS.items():
        motion = sa.read_bvh(shared_data / path)
        assert motion.fps == fps
        out[name] = motion[: int(fps * 0.5) + 1]
    return out


def _frames(path):
    with Image.open(path) as gif:
        frames = []
        for k in range(gif.n_frames):
            gif.seek(k)
            frames.append(np.asarray(gif.convert("RGB")))
        return gif.size, np.stack(frames)


def test_side_by_side_gif_of_three_skeletons(clips, tmp_path, color_pixels, ink):
    rendering = render_frames(list(clips.values()), labels=list(clips), fps=20.0, size=(160, 200))
    path = write_animation(rendering, tmp_path / "three.gif")
    size, frames = _frames(path)
    assert size == (3 * 160, 200)
    assert len(frames) == 11  # 0.5 s at 20 fps, first and last frame included
    for f, frame in enumerate(frames):
        for k, name in enumerate(clips):
            x0, y0, x1, y1 = rendering.panels[k].astype(int)
            box = rendering.boxes[f, k]
            assert box[0] >= x0 and box[2] <= x1 and box[1] >= y0 and box[3] <= y1, (name, f)
            bx0, by0, bx1, by1 = np.round(box).astype(int)
            assert ink(frame[by0 : by1 + 1, bx0 : bx1 + 1]) > 40, (name, f)
            # a character fills a good part of its own panel (framed on its own units)
            assert box[3] - box[1] > 0.3 * (y1 - y0) or box[2] - box[0] > 0.3 * (x1 - x0)
            if f == 5:
                panel = frame[y0:y1, x0:x1]
                for group in LIMBS[name]:
                    assert color_pixels(panel, group) > 3, (name, group)


def test_overlay_is_time_synchronised_across_frame_rates(clips):
    lafan = clips["lafan"]
    fast = lafan.resample(90.0)
    rendering = render_frames([lafan, fast], mode="overlay", fps=10.0, size=(200, 200))
    assert len(rendering.frames) == 6
    # the same motion sampled at 30 and 90 fps lands on the same pixels at every tick
    np.testing.assert_allclose(rendering.boxes[:, 0], rendering.boxes[:, 1], atol=1.5)


def test_dog_contact_sheet(clips, tmp_path, color_pixels):
    path = render_contact_sheet(
        clips["dog"], tmp_path / "dog.png", frames=4, columns=2, size=(120, 100), trajectory=True
    )
    with Image.open(path) as image:
        assert image.size == (2 * 120 + 4, 2 * 100 + 4)
        sheet = np.asarray(image.convert("RGB"))
    for r in range(2):
        for c in range(2):
            tile = sheet[r * 104 : r * 104 + 100, c * 124 : c * 124 + 120]
            assert color_pixels(tile, "tail") > 2
            assert color_pixels(tile, "left_leg") > 3
