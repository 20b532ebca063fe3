"""Plot helpers: phase manifold, phase over time, codebook usage, metric curves."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from PIL import Image

from skelagnostic.viz import (
    RenderError,
    plot_codebook_usage,
    plot_metric_curves,
    plot_phase_manifold,
    plot_phase_over_time,
)


def _saved_image(path):
    with Image.open(path) as image:
        return np.asarray(image.convert("RGB"))


class TestPhaseManifold:
    def test_ellipses_are_exact_in_pca_plane(self, tmp_path):
        # Codes whose ellipses live in a 2-D subspace: PCA keeps them exactly (up to rotation).
        book = np.zeros((3, 8))
        book[:, 0], book[:, 5] = [1.0, 2.0, 3.0], [1.0, 2.0, 3.0]  # A0 = r e0, A1 = r e1
        fig = plot_phase_manifold(book, samples=16, out=tmp_path / "m.png")
        segments = fig.axes[0].collections[0].get_segments()
        radii = [np.linalg.norm(s - s[:-1].mean(axis=0), axis=1) for s in segments]
        for r, expected in zip(radii, [1.0, 2.0, 3.0], strict=True):
            np.testing.assert_allclose(r, expected, rtol=1e-6)
        assert _saved_image(tmp_path / "m.png").min() < 100

    def test_one_panel_per_character_with_used_codes_coloured(self):
        book = torch.randn(6, 10, generator=torch.Generator().manual_seed(0))
        usage = {"human": np.array([0, 0, 0, 1]), "dog": np.array([1, 5])}
        points = {"dog": np.random.default_rng(0).normal(size=(2, 5))}
        fig = plot_phase_manifold(book, usage, points=points)
        human, dog = fig.axes[:2]
        assert human.get_title() == "human: 2/6 codes"
        assert dog.get_title() == "dog: 2/6 codes"
        grey, coloured = human.collections[:2]
        assert len(grey.get_segments()) == 4 and len(coloured.get_segments()) == 2
        widths = coloured.get_linewidths()
        assert widths[0] > widths[1]  # code 0 holds 3/4 of the human frames
        assert len(dog.collections) == 3  # grey, coloured, scattered frame points

    @pytest.mark.parametrize(
        ("args", "kwargs", "word"),
        [
            ((np.zeros((4, 3)),), {}, "codebook"),
            ((np.zeros((4, 4)),), {"samples": 2}, "samples"),
            ((np.zeros((4, 4)), {"a": [0, 4]}), {}, "usage"),
            ((np.zeros((4, 4)), {"a": [0, 1]}), {"points": {"a": np.zeros((2, 3))}}, "points"),
            ((np.zeros((4, 4)), {"a": [0]}), {"points": {"a": np.zeros((2, 2))}}, "points"),
            ((np.full((2, 4), np.nan),), {}, "NaN"),
        ],
    )
    def test_bad_input(self, args, kwargs, word):
        with pytest.raises(RenderError, match=word):
            plot_phase_manifold(*args, **kwargs)


class TestPhaseOverTime:
    def test_rows_and_series(self, tmp_path):
        t = np.arange(60) / 30
        fig = plot_phase_over_time(
            {"human": 1.2 * t, "dog": 2.0 * t},
            frequency={"human": np.full(60, 1.2), "dog": np.full(60, 2.0)},
            code={"human": np.zeros(60), "dog": np.ones(60)},
            fps=30,
            out=tmp_path / "p.svg",
        )
        assert [ax.get_ylabel() for ax in fig.axes] == ["phase (cycles)", "frequency (Hz)", "code"]
        wrapped = fig.axes[0].collections[0].get_offsets()[:, 1]
        assert wrapped.min() >= -0.5 and wrapped.max() < 0.5
        assert fig.axes[1].get_lines()[1].get_xdata()[-1] == pytest.approx(59 / 30)
        assert (tmp_path / "p.svg").read_text().startswith("<?xml")

    def test_bad_input(self):
        with pytest.raises(RenderError, match="fps"):
            plot_phase_over_time(np.zeros(3), fps=0)
        with pytest.raises(RenderError, match="frequency"):
            plot_phase_over_time(np.zeros(3), frequency=np.zeros((3, 2)))


class TestCodebookUsage:
    def test_shares_and_overlap_title(self, tmp_path):
        fig = plot_codebook_usage(
            {"human": [0, 0, 1, 1], "dog": torch.tensor([1, 2])}, 5, out=tmp_path / "u.pdf"
        )
        ax = fig.axes[0]
        assert ax.get_title() == "codes used: 3/5 (60%), by every dataset: 1/5 (20%)"
        heights = [p.get_height() for p in ax.patches]
        np.testing.assert_allclose(heights, [0.5, 0.5, 0, 0, 0, 0, 0.5, 0.5, 0, 0])
        assert (tmp_path / "u.pdf").read_bytes().startswith(b"%PDF")

    def test_bad_input(self):
        with pytest.raises(RenderError, match="codes"):
            plot_codebook_usage({}, 4)
        with pytest.raises(RenderError, match="num_codes"):
            plot_codebook_usage({"a": [0]}, 0)
        with pytest.raises(RenderError, match=r"codes\['a'\]"):
            plot_codebook_usage({"a": [4]}, 4)


class TestMetricCurves:
    def test_shared_and_own_x_with_spread(self, tmp_path):
        fig = plot_metric_curves(
            [0.0, 0.1, 0.2],
            {"ours": [1.0, 2.0, 3.0], "baseline": ([0.0, 0.2], [2.0, 5.0])},
            spread={"ours": [0.1, 0.2, 0.3]},
            xlabel="noise",
            ylabel="MPJPE (cm)",
            title="denoising",
            logy=True,
            out=tmp_path / "c.png",
        )
        ax = fig.axes[0]
        lines = ax.get_lines()
        assert [line.get_label() for line in lines] == ["ours", "baseline"]
        assert lines[1].get_xdata().tolist() == [0.0, 0.2]
        assert ax.get_yscale() == "log" and ax.get_title() == "denoising"
        assert len(ax.collections) == 1  # the spread band
        assert _saved_image(tmp_path / "c.png").shape == (400, 600, 3)

    def test_bad_input(self, tmp_path):
        with pytest.raises(RenderError, match="series"):
            plot_metric_curves([1], {}, xlabel="x", ylabel="y")
        with pytest.raises(RenderError, match=r"series\['a'\].*2 x values for 3"):
            plot_metric_curves([1, 2], {"a": [1, 2, 3]}, xlabel="x", ylabel="y")
        with pytest.raises(RenderError, match="give x"):
            plot_metric_curves(None, {"a": [1, 2]}, xlabel="x", ylabel="y")
        with pytest.raises(RenderError, match="spread"):
            plot_metric_curves([1], {"a": [1]}, spread={"a": [1, 2]}, xlabel="x", ylabel="y")
        with pytest.raises(RenderError, match="out"):
            plot_metric_curves([1], {"a": [1]}, xlabel="x", ylabel="y", out=tmp_path / "c.gif")
