"""The main job's picture (plot_transfer) on procedural clips: size, panels, one scale."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from skelagnostic_vqpae.picture import plot_transfer, side_view
from skelagnostic_vqpae.protocols.summary import shared_codes_sentence

from skelagnostic import procedural
from skelagnostic.viz import StickFigure
from skelagnostic.viz.stick import RenderError


@pytest.fixture(scope="module")
def clips() -> tuple:
    human, _ = procedural.generate("biped22", "walk", seconds=4.0, fps=30, seed=0)
    human.name = "held_out_walk"
    dogs = {
        "dog: model": procedural.generate("quadruped", "walk", seconds=4.0, fps=30, seed=1)[0],
        "dog: unscaled": procedural.generate("quadruped", "trot", seconds=4.0, fps=30, seed=2)[0],
        # a smaller dog: drawn at the same scale, it must look smaller, not fill its panel
        "dog: own rate": procedural.generate(
            "quadruped", "walk", seconds=4.0, fps=30, seed=3, scale=0.6
        )[0],
    }
    return human, dogs


def test_picture_has_large_panels_one_scale_and_timelines(clips, tmp_path: Path) -> None:
    human, dogs = clips
    fig = plot_transfer(
        human,
        dogs,
        instants=[1.0, 1.3, 1.6],
        source_label="human",
        target_label="dog",
        out=tmp_path / "p.png",
    )
    fig.canvas.draw()
    rows, columns = 3, 1 + len(dogs)
    poses, timelines = fig.axes[: rows * columns], fig.axes[rows * columns :]
    assert len(timelines) == len(dogs)
    for ax in poses:  # readable: every pose panel at least 400 pixels high
        assert ax.get_window_extent().height >= 400
    dog_axes = [ax for k, ax in enumerate(poses) if k % columns]
    limits = {(ax.get_xlim(), ax.get_ylim()) for ax in dog_axes}
    assert len(limits) == 1  # one scale for every dog, whatever its size
    human_axes = [ax for k, ax in enumerate(poses) if k % columns == 0]
    assert {(ax.get_xlim(), ax.get_ylim()) for ax in human_axes} != limits
    # the small dog's poses span less of the shared panel than the others'
    heights = [
        float(np.ptp(np.concatenate([ln.get_ydata() for ln in ax.lines[:-1]])))
        for ax in dog_axes[:3]
    ]
    assert heights[2] < 0.8 * heights[0]
    # each timeline draws the source's feet (2) over the dog's (4), labelled
    for ax, label in zip(timelines, dogs, strict=True):
        assert ax.get_title(loc="left") == label
        names = [t.get_text() for t in ax.get_yticklabels()]
        assert sum(n.startswith("human ") for n in names) == 2
        assert sum(n.startswith("dog ") for n in names) == 4
        # one lane of ticks per foot, the source's (black) over the dog's
        assert len(ax.collections) == 6
        assert ax.get_xlim() == pytest.approx((0, (human.num_frames - 1) / human.fps))
    from PIL import Image

    with Image.open(tmp_path / "p.png") as image:
        assert image.width == 4 * 450 and image.height > 3 * 450  # 4 columns, 3 rows


def test_picture_checks_its_arguments(clips) -> None:
    human, dogs = clips
    with pytest.raises(RenderError, match="outputs"):
        plot_transfer(human, {})
    with pytest.raises(RenderError, match="instants"):
        plot_transfer(human, dogs, instants=[10.0])
    with pytest.raises(RenderError, match="events"):
        plot_transfer(human, dogs, events="footsteps")


def test_swing_timeline_marks_one_event_per_stride(clips) -> None:
    from skelagnostic.analysis import forward_swings, gait_frequency

    human, dogs = clips
    fig = plot_transfer(human, dogs, events="swing")
    timeline = fig.axes[-len(dogs)]
    swings = forward_swings(human)
    ticks = [len(c.get_positions()) for c in timeline.collections[: len(swings)]]
    assert ticks == [len(s) for s in swings]
    # the events of the gait frequency: their rate is the clip's stride frequency
    spans = [(s[-1] - s[0]) / human.fps for s in swings]
    rate = sum(len(s) - 1 for s in swings) / sum(spans)
    assert rate == pytest.approx(gait_frequency(human))


def test_code_strip_shows_each_motion_codes_in_one_colour_per_code(clips) -> None:
    human, dogs = clips
    frames = human.num_frames
    same = np.r_[np.zeros(frames // 2, int), np.full(frames - frames // 2, 3)]
    codes = [(same, human.fps), (same, human.fps), (np.full(frames, 5), human.fps)]
    codes.append((same, human.fps))
    fig = plot_transfer(human, dogs, codes=codes)
    rows, columns = 2, 1 + len(dogs)
    strip = fig.axes[rows * columns]
    assert "same colour" in strip.get_title(loc="left")
    assert strip.get_yticklabels()[0].get_text().startswith("source")
    bars = strip.collections  # one bar per run of equal codes: 2 + 2 + 1 + 2
    assert len(bars) == 7
    colours = [tuple(np.round(b.get_facecolor()[0], 3)) for b in bars]
    assert colours[0] == colours[2] and colours[1] == colours[3]  # same code, same colour
    assert colours[4] not in (colours[0], colours[1])
    assert len(fig.axes) == rows * columns + 1 + len(dogs)  # the strip, then the timelines
    with pytest.raises(RenderError, match="codes"):
        plot_transfer(human, dogs, codes=codes[:2])


def test_side_view_stands_on_the_ground_facing_the_travel() -> None:
    dog, _ = procedural.generate("quadruped", "walk", seconds=3.0, fps=30, seed=1, turn_rate=40)
    figure = StickFigure.from_motion(dog.to_metres())
    view = side_view(figure, [0.5, 1.5, 2.5])
    assert view.shape == (3, dog.skeleton.num_joints, 2)
    assert view[..., 1].min() >= -1e-6  # heights over the lowest joint of the clip
    assert np.allclose(view[:, 0, 0], 0)  # the root at the origin
    head = dog.skeleton.end_effectors()
    ahead = view[:, head, 0].max(1)
    assert (ahead > 0).all()  # something (the head) ahead of the root, whichever way it turns


def test_shared_codes_are_stated_plainly() -> None:
    none = shared_codes_sentence("human", "dog", {"human": [4, 7, 9], "dog": [10]})
    assert "codes 4, 7, 9" in none and "code 10" in none and "share no code" in none
    some = shared_codes_sentence("human", "dog", {"human": [1, 2], "dog": [2, 3]})
    assert some.endswith("they share code 2.")
    assert "No held-out clip" in shared_codes_sentence("human", "dog", {"human": [1]})
