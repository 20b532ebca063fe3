"""StickFigure validation, conversions and the common clock."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import skelagnostic as sa
from skelagnostic.viz import RenderError, StickFigure, synchronise
from skelagnostic.viz.stick import to_stick_figures


class TestStickFigure:
    def test_accepts_torch_and_builds_bones(self):
        fig = StickFigure(torch.zeros(3, 3, 3), parents=[-1, 0, 1], groups=["spine"] * 3)
        assert isinstance(fig.positions, np.ndarray)
        assert fig.bones.tolist() == [[0, 1], [1, 2]]
        assert fig.num_frames == 3 and fig.num_joints == 3

    @pytest.mark.parametrize(
        ("kwargs", "field"),
        [
            ({"positions": np.zeros((3, 2))}, "positions"),
            ({"positions": np.full((1, 2, 3), np.nan)}, "positions"),
            ({"parents": [-1]}, "parents"),
            ({"parents": [-1, 5]}, r"parents\[1\]"),
            ({"parents": [-1, 1]}, r"parents\[1\]"),
            ({"groups": ["spine"]}, "groups"),
            ({"groups": ["spine", "wing"]}, "wing"),
            ({"fps": 0.0}, "fps"),
            ({"up_axis": "w"}, "up_axis"),
        ],
    )
    def test_bad_fields_are_named(self, kwargs, field):
        args = {"positions": np.zeros((2, 2, 3)), "parents": [-1, 0], **kwargs}
        with pytest.raises(RenderError, match=field):
            StickFigure(**args)

    def test_z_up_is_a_rotation(self):
        point = np.array([[[1.0, 2.0, 3.0]]])
        for axis, expected in (
            ("y", [3.0, 1.0, 2.0]),
            ("z", [1.0, 2.0, 3.0]),
            ("x", [2.0, 3.0, 1.0]),
        ):
            fig = StickFigure(point, parents=[-1], up_axis=axis)
            np.testing.assert_allclose(fig.z_up()[0, 0], expected)
            assert fig.z_up()[0, 0, 2] == point[0, 0, "xyz".index(axis)]

    def test_sample_interpolates_and_holds(self):
        positions = np.zeros((3, 1, 3))
        positions[:, 0, 0] = [0.0, 1.0, 4.0]
        fig = StickFigure(positions, parents=[-1], fps=10.0, up_axis="z")
        got = fig.sample(np.array([-1.0, 0.05, 0.15, 0.2, 5.0]))[:, 0, 0]
        np.testing.assert_allclose(got, [0.0, 0.5, 2.5, 4.0, 4.0])


class TestSynchronise:
    def test_default_rate_is_capped_at_30(self):
        fig = StickFigure(np.zeros((121, 1, 3)), parents=[-1], fps=120.0)
        times, rate = synchronise([fig])
        assert rate == 30.0 and len(times) == 31

    def test_longest_clip_sets_the_duration(self):
        a = StickFigure(np.zeros((61, 1, 3)), parents=[-1], fps=60.0)
        b = StickFigure(np.zeros((3, 1, 3)), parents=[-1], fps=1.0)
        times, rate = synchronise([a, b])
        assert rate == 30.0 and times[-1] == pytest.approx(2.0) and len(times) == 61


class TestConversions:
    def test_motion_and_labels(self):
        motion, _ = sa.procedural.generate(
            kind="quadruped", gait="trot", seconds=0.5, fps=30, seed=1
        )
        (fig,) = to_stick_figures(motion)
        assert fig.name == motion.name
        assert fig.fps == 30.0 and fig.up_axis == motion.skeleton.up_axis
        assert "tail" in fig.groups
        np.testing.assert_allclose(fig.positions, motion.global_positions().numpy())
        figs = to_stick_figures([motion, fig], labels=["x", "y"])
        assert [f.name for f in figs] == ["x", "y"]
        assert fig.name == motion.name  # the caller's figure is not renamed

    def test_bvh_path(self, tmp_path):
        motion, _ = sa.procedural.generate(kind="biped22", gait="walk", seconds=0.3, fps=30, seed=0)
        sa.write_bvh(motion, tmp_path / "clip.bvh")
        (fig,) = to_stick_figures(tmp_path / "clip.bvh")
        assert fig.name == "clip"
        assert fig.num_joints == motion.skeleton.num_joints
        np.testing.assert_allclose(fig.positions, motion.global_positions().numpy(), atol=1e-3)

    def test_missing_bvh_is_a_bvh_error(self, tmp_path):
        with pytest.raises(sa.BVHError):
            to_stick_figures(str(tmp_path / "missing.bvh"))
