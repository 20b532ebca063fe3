"""Rendering stick figures to frames, GIF, MP4 and contact sheets (synthetic input)."""

from __future__ import annotations

import math
import os
import stat
import sys

import matplotlib
import numpy as np
import pytest
from PIL import Image

from skelagnostic.errors import SkelagnosticError
from skelagnostic.viz import (
    Camera,
    RenderError,
    StickFigure,
    contact_sheet,
    render_contact_sheet,
    render_frames,
    render_motion,
    write_animation,
)
from skelagnostic.viz.camera import auto_azimuth


def _inside(box: np.ndarray, rect: np.ndarray) -> bool:
    return bool(box[0] >= rect[0] and box[1] >= rect[1] and box[2] <= rect[2] and box[3] <= rect[3])


class TestCamera:
    def test_basis_is_right_handed_and_orthonormal(self):
        basis = Camera(azim=37.0, elev=21.0).basis()
        np.testing.assert_allclose(basis @ basis.T, np.eye(3), atol=1e-12)
        np.testing.assert_allclose(np.cross(basis[0], basis[1]), basis[2], atol=1e-12)

    def test_up_is_screen_up_and_closer_is_deeper(self):
        camera = Camera(azim=0.0, elev=10.0)
        uv, depth = camera.project(np.array([[0.0, 0, 0], [0, 0, 1], [1, 0, 0]]))
        assert uv[1, 1] > uv[0, 1]  # +z goes up on screen
        assert depth[2] > depth[0]  # the eye is on the +x side at azimuth 0

    def test_auto_azimuth_makes_travel_go_left_to_right(self, walker):
        for heading in (0.0, 1.0, 2.5, -2.0):
            positions = walker(frames=30).z_up()
            c, s = math.cos(heading), math.sin(heading)
            rotated = positions @ np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]])
            uv, _ = Camera(auto_azimuth([rotated]), 15.0).project(rotated[:, 0])
            assert uv[-1, 0] > uv[0, 0]


class TestRenderFrames:
    def test_shapes_boxes_and_colours(self, walker, color_pixels, ink):
        out = render_frames(walker(frames=20), size=(160, 120))
        assert out.frames.shape == (20, 120, 160, 3)
        assert out.frames.dtype == np.uint8
        assert out.fps == 30.0
        np.testing.assert_allclose(out.times, np.arange(20) / 30.0)
        assert out.boxes.shape == (20, 1, 4)
        for f in range(20):
            box = out.boxes[f, 0]
            assert _inside(box, out.panels[0]), (f, box)
            x0, y0, x1, y1 = (int(v) for v in box)
            assert ink(out.frames[f, y0 : y1 + 1, x0 : x1 + 1]) > 30
        for group in ("spine", "left_leg", "right_leg", "left_arm", "right_arm"):
            assert color_pixels(out.frames[10], group) > 5, group

    def test_figure_moves_and_frames_differ(self, walker):
        out = render_frames(walker(frames=31, speed=2.0), size=(160, 120), time_label=False)
        assert out.boxes[-1, 0, 0] > out.boxes[0, 0, 0] + 20
        assert not np.array_equal(out.frames[0], out.frames[-1])

    def test_side_by_side_panels_in_any_units(self, walker, ink):
        small, big = walker(name="m"), walker(scale=100.0, name="cm")
        out = render_frames([small, big], size=(100, 120))
        assert out.frames.shape[1:] == (120, 200, 3)
        np.testing.assert_array_equal(out.panels, [[0, 0, 100, 120], [100, 0, 200, 120]])
        for k in range(2):
            assert all(_inside(out.boxes[f, k], out.panels[k]) for f in range(len(out.times)))
        # the same pose at 100x the size fills its own panel the same way
        widths = out.boxes[:, :, 2] - out.boxes[:, :, 0]
        np.testing.assert_allclose(widths[:, 0], widths[:, 1], atol=2.0)

    @pytest.mark.parametrize("follow", [False, True])
    def test_same_scale_keeps_real_sizes_across_panels(self, walker, follow):
        small, big = walker(name="small"), walker(scale=2.0, name="twice as tall")
        kwargs = {"size": (100, 120), "time_label": False, "follow": follow}
        own = render_frames([small, big], **kwargs)
        same = render_frames([small, big], same_scale=True, **kwargs)
        heights = [r.boxes[:, :, 3] - r.boxes[:, :, 1] for r in (own, same)]
        # each framed on its own, both fill their panels alike; at one scale the taller is 2x
        np.testing.assert_allclose(heights[0][:, 1] / heights[0][:, 0], 1.0, atol=0.05)
        np.testing.assert_allclose(heights[1][:, 1] / heights[1][:, 0], 2.0, rtol=0.05)
        assert same.scales[0] == pytest.approx(same.scales[1])
        assert own.scales[0] == pytest.approx(2.0 * own.scales[1], rel=0.02)
        for k in range(2):  # the one needing the most room still fits
            assert all(_inside(same.boxes[f, k], same.panels[k]) for f in range(len(same.times)))

    def test_same_scale_over_chosen_panels_only(self, walker):
        figures = [walker(scale=s, name=f"x{s:g}") for s in (10.0, 1.0, 2.0)]
        out = render_frames(figures, same_scale=[1, 2], times=[0.0], size=(80, 96))
        assert out.scales[1] == pytest.approx(out.scales[2])
        # the first, in other units, keeps its own framing: as large as the largest shared one
        height = out.boxes[0, :, 3] - out.boxes[0, :, 1]
        assert height[0] == pytest.approx(height[2], rel=0.05) and height[1] < 0.6 * height[2]
        single = render_frames(figures[0], same_scale=True, times=[0.0], size=(80, 96))
        assert single.scales[0] == pytest.approx(out.scales[0])

    @pytest.mark.parametrize("value", [[0, 2], [-1], ["a"], "01", 1.5])
    def test_same_scale_refuses_what_is_not_panel_indices(self, walker, value):
        with pytest.raises(RenderError, match="same_scale"):
            render_frames([walker(), walker()], same_scale=value, times=[0.0], size=(48, 48))

    def test_label_stays_above_the_figure(self, walker):
        from skelagnostic.viz.render import _prepare

        scene = _prepare(walker(name="a label\non two lines"), size=(120, 120), time_label=False)
        try:
            scene.canvas.draw()
            label = scene.panels[0].ax.texts[0].get_window_extent()
            _, boxes = scene.draw_all()
        finally:
            scene.close()
        assert boxes[:, 0, 1].min() > 120 - label.y0  # below the label's last line

    @pytest.mark.parametrize("follow", [False, True])
    def test_a_panel_draws_nothing_into_the_next(self, walker, follow):
        kwargs = {"size": (80, 120), "time_label": False, "follow": follow, "trajectory": True}
        a, b = walker(frames=31, speed=3.0, name="a"), walker(frames=31, name="b")
        pair = render_frames([a, b], **kwargs)
        alone = render_frames(b, **kwargs)
        np.testing.assert_array_equal(pair.frames[:, :, 80:], alone.frames)

    def test_overlay_shares_one_camera(self, walker):
        a, b = walker(name="a"), walker(speed=0.5, name="b")
        out = render_frames([a, b], mode="overlay", size=(160, 120))
        assert out.frames.shape[1:] == (120, 160, 3)
        np.testing.assert_array_equal(out.panels[0], out.panels[1])
        np.testing.assert_allclose(out.boxes[0, 0], out.boxes[0, 1], atol=1e-6)  # same start
        assert out.boxes[-1, 0, 0] > out.boxes[-1, 1, 0] + 5  # a travels further

    def test_time_synchronisation_across_frame_rates(self, walker):
        fast = walker(frames=121, fps=120.0)  # 1 s
        slow = walker(frames=16, fps=30.0)  # 0.5 s, then holds its last pose
        out = render_frames([fast, slow], mode="overlay", fps=10.0, size=(64, 64))
        assert len(out.frames) == 11
        np.testing.assert_allclose(out.boxes[:6, 0], out.boxes[:6, 1], atol=1e-6)
        np.testing.assert_allclose(out.boxes[6:, 1], out.boxes[[5] * 5, 1], atol=1e-6)

    def test_max_frames_subsamples_in_real_time(self, walker):
        out = render_frames(walker(frames=91), max_frames=10, size=(48, 48))
        assert len(out.frames) == 10
        assert out.fps == pytest.approx(30.0 / 10)
        assert out.times[-1] == pytest.approx(3.0)

    def test_trajectory_adds_a_path(self, walker):
        fig = walker(frames=31, speed=2.0)
        kwargs = {"times": [0.0, 1.0], "size": (160, 120), "time_label": False}
        plain = render_frames(fig, **kwargs)
        path = render_frames(fig, trajectory=True, **kwargs)
        changed = np.abs(path.frames[0].astype(int) - plain.frames[0]).max(axis=-1) > 30
        assert changed.sum() > 40
        rows = np.nonzero(changed)[0]
        assert rows.min() > path.boxes[0, 0, 3] - 10  # on the floor, near the feet

    def test_follow_camera_keeps_a_travelling_figure_centred_and_large(self, walker):
        fig = walker(frames=61, speed=5.0)
        kwargs = {"size": (160, 120), "time_label": False, "trajectory": True}
        fixed = render_frames(fig, **kwargs)
        follow = render_frames(fig, follow=True, **kwargs)
        centre = (follow.boxes[:, 0, 0] + follow.boxes[:, 0, 2]) / 2
        assert np.ptp(centre) < 12  # swinging limbs only; the root stays put
        assert np.ptp((fixed.boxes[:, 0, 0] + fixed.boxes[:, 0, 2]) / 2) > 60
        heights = [(r.boxes[:, 0, 3] - r.boxes[:, 0, 1]).mean() for r in (fixed, follow)]
        assert heights[1] > 1.5 * heights[0]
        # the floor grid slides under the figure: the background changes between frames
        top = follow.boxes[:, 0, 1].min()
        below_box = slice(int(follow.boxes[:, 0, 3].max()) + 2, None)
        assert top > 0 and not np.array_equal(
            follow.frames[0, below_box], follow.frames[7, below_box]
        )
        assert all(_inside(b, follow.panels[0]) for b in follow.boxes[:, 0])

    def test_up_axis_is_respected(self, walker):
        fig = walker()
        z_up = StickFigure(
            fig.positions[..., [2, 0, 1]], fig.parents, fig.groups, name=fig.name, up_axis="z"
        )
        a = render_frames(fig, times=[0.0], size=(64, 64), azim=0.0)
        b = render_frames(z_up, times=[0.0], size=(64, 64), azim=0.0)
        np.testing.assert_allclose(a.boxes, b.boxes, atol=1e-6)
        box = a.boxes[0, 0]
        assert box[3] - box[1] > box[2] - box[0]  # a standing figure is tall

    @pytest.mark.parametrize(
        ("kwargs", "word"),
        [
            ({"mode": "stacked"}, "mode"),
            ({"size": (8, 100)}, "size"),
            ({"elev": 120.0}, "elev"),
            ({"azim": float("nan")}, "azim"),
            ({"fps": 0.0}, "fps"),
            ({"max_frames": 0}, "max_frames"),
            ({"times": []}, "times"),
            ({"labels": ["a", "b"]}, "labels"),
        ],
    )
    def test_bad_arguments_name_the_argument(self, walker, kwargs, word):
        with pytest.raises(RenderError, match=word) as info:
            render_frames(walker(), **kwargs)
        assert isinstance(info.value, SkelagnosticError)

    def test_bad_items(self):
        with pytest.raises(RenderError, match="empty"):
            render_frames([])
        with pytest.raises(RenderError, match=r"motions\[0\].*int"):
            render_frames([3])


class TestFiles:
    def test_gif(self, walker, tmp_path):
        path = render_motion(walker(frames=45), tmp_path / "sub" / "walk.gif", size=(96, 80))
        with Image.open(path) as gif:
            assert gif.format == "GIF"
            assert gif.n_frames == 45
            assert gif.size == (96, 80)
            durations = []
            for k in range(gif.n_frames):
                gif.seek(k)
                durations.append(gif.info["duration"])
                assert np.asarray(gif.convert("RGB")).min() < 100  # not blank
        assert sum(durations) == pytest.approx(45 / 30 * 1000, abs=10)
        assert set(durations) <= {30, 40}

    def test_gif_delays_are_capped_at_the_format_limit(self, tmp_path):
        # a 4000 s clip in 2 frames: each would stay 2000 s, a GIF frame holds at most 655.35 s
        slow = StickFigure(np.random.default_rng(0).random((2000, 2, 3)), parents=[-1, 0], fps=0.5)
        path = render_motion(slow, tmp_path / "slow.gif", max_frames=2, size=(32, 32))
        with Image.open(path) as gif:
            assert gif.n_frames == 2 and gif.info["duration"] == 655350

    def test_gif_refuses_more_than_50_fps(self, walker, tmp_path):
        with pytest.raises(RenderError, match="50"):
            render_motion(walker(fps=60.0), tmp_path / "a.gif", fps=60.0, size=(32, 32))

    def test_png_contact_sheet(self, walker, tmp_path, ink):
        path = render_motion(
            walker(frames=61), tmp_path / "sheet.png", sheet_frames=6, columns=3, size=(80, 60)
        )
        with Image.open(path) as image:
            assert image.size == (3 * 80 + 2 * 4, 2 * 60 + 4)
            sheet = np.asarray(image.convert("RGB"))
        for r in range(2):
            for c in range(3):
                tile = sheet[r * 64 : r * 64 + 60, c * 84 : c * 84 + 80]
                assert ink(tile) > 20

    def test_contact_sheet_only_draws_its_frames(self, walker, tmp_path):
        path = render_contact_sheet(walker(frames=300), tmp_path / "s.png", frames=2, size=(40, 40))
        with Image.open(path) as image:
            assert image.size == (2 * 40 + 4, 40)
        with pytest.raises(RenderError, match="frames"):
            render_contact_sheet(walker(), tmp_path / "s.png", frames=0)
        with pytest.raises(RenderError, match="times"):
            render_contact_sheet(walker(), tmp_path / "s.png", times=[0.0])

    def test_contact_sheet_picks_first_and_last(self, walker):
        out = render_frames(walker(frames=10), size=(32, 32))
        sheet = contact_sheet(out, frames=3, columns=3, gap=0)
        np.testing.assert_array_equal(sheet[:, :32], out.frames[0])
        np.testing.assert_array_equal(sheet[:, 64:], out.frames[-1])

    def test_unknown_suffix(self, walker, tmp_path):
        with pytest.raises(RenderError, match="out"):
            render_motion(walker(), tmp_path / "a.avi")
        with pytest.raises(RenderError, match="out"):
            write_animation(render_frames(walker(frames=2), size=(32, 32)), tmp_path / "a.png")

    def test_mp4_without_ffmpeg_is_a_clear_error(self, walker, tmp_path, monkeypatch):
        monkeypatch.setitem(matplotlib.rcParams, "animation.ffmpeg_path", "no-such-ffmpeg-here")
        with pytest.raises(RenderError, match="ffmpeg"):
            render_motion(walker(), tmp_path / "a.mp4")
        assert not (tmp_path / "a.mp4").exists()

    @pytest.mark.skipif(sys.platform == "win32", reason="uses a shell script as fake ffmpeg")
    def test_mp4_pipes_raw_frames_to_ffmpeg(self, walker, tmp_path, monkeypatch):
        # A stand-in ffmpeg that stores stdin in the output file and its arguments beside it.
        fake = tmp_path / "ffmpeg"
        fake.write_text(
            '#!/bin/sh\nfor last; do :; done\necho "$@" > "$last.args"\ncat > "$last"\n'
        )
        fake.chmod(fake.stat().st_mode | stat.S_IEXEC)
        monkeypatch.setitem(matplotlib.rcParams, "animation.ffmpeg_path", os.fspath(fake))
        path = render_motion(walker(frames=12), tmp_path / "a.mp4", size=(33, 20))
        assert path.stat().st_size == 12 * 20 * 34 * 3  # odd width padded to even
        # ffmpeg writes a temporary file next to a.mp4, which then replaces it (atomic write)
        (arg_file,) = tmp_path.glob("*.args")
        args = arg_file.read_text()
        assert "-s 34x20" in args and "-r 30" in args and "yuv420p" in args and "-f mp4" in args
        assert sorted(p.name for p in tmp_path.iterdir() if p.suffix != ".args") == [
            "a.mp4",
            "ffmpeg",
        ]

    def test_mp4_ffmpeg_failure_is_reported(self, walker, tmp_path, monkeypatch):
        fake = tmp_path / "ffmpeg"
        fake.write_text("#!/bin/sh\necho broken codec >&2\nexit 3\n")
        fake.chmod(fake.stat().st_mode | stat.S_IEXEC)
        monkeypatch.setitem(matplotlib.rcParams, "animation.ffmpeg_path", os.fspath(fake))
        with pytest.raises(RenderError, match="broken codec"):
            render_motion(walker(frames=3), tmp_path / "a.mp4", size=(32, 32))
