"""Plot helpers for the methods and the docs: phase manifolds, codes, metric curves.

Every helper takes plain arrays (numpy, torch or lists), draws on a fresh
matplotlib :class:`~matplotlib.figure.Figure` with an Agg canvas (no pyplot, no
display), optionally saves it (the suffix of ``out`` picks PNG, SVG or PDF) and
returns the figure for further styling.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from skelagnostic.viz.stick import RenderError

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = [
    "plot_codebook_usage",
    "plot_method_comparison",
    "plot_metric_curves",
    "plot_phase_manifold",
    "plot_phase_over_time",
]

#: Anything numpy can turn into a numeric array (numpy, torch tensors, lists).
ArrayLike = Any


def plot_phase_manifold(
    codebook: ArrayLike,
    usage: Mapping[str, ArrayLike] | None = None,
    *,
    points: Mapping[str, ArrayLike] | None = None,
    samples: int = 64,
    out: str | Path | None = None,
) -> Figure:
    """Draw the phase manifold: every codebook ellipse, reduced to 2-D by PCA.

    Each code ``A = (A0, A1)`` (``[2d]``) spans the closed curve
    ``P(phi) = A0 sin(2 pi phi) + A1 cos(2 pi phi)`` in ``R^d`` (WalkTheDog,
    Sec. 3.1). The curves are sampled at ``samples`` phases, projected on the two
    principal axes of all samples and coloured by code index. With ``usage`` there
    is one panel per character: every ellipse in light grey, those the
    character uses in colour, thicker the more frames use them. All panels share
    the projection, so shared codes sit at the same place.

    Args:
        codebook: ``[K, 2d]`` amplitudes (first half ``A0``, second half ``A1``).
        usage: Per character, the code index of each of its frames ``[N]``.
        points: Per character, manifold points of its frames ``[N, d]`` to
            scatter on its panel (e.g. the encoder's per-frame embeddings).
        samples: Phases sampled per ellipse.
        out: Optional path to save the figure to.

    Returns:
        The figure.

    Raises:
        RenderError: On arrays of the wrong shape or out-of-range codes.

    Examples:
        >>> import numpy as np
        >>> from skelagnostic.viz import plot_phase_manifold
        >>> book = np.random.default_rng(0).normal(size=(8, 6))
        >>> fig = plot_phase_manifold(book, {"human": [0, 0, 1, 2], "dog": [1, 2, 2, 7]})
        >>> len(fig.axes)  # two panels and the colour bar
        3
    """
    from matplotlib.collections import LineCollection

    book = _array(codebook, "codebook")
    if book.ndim != 2 or book.shape[1] < 2 or book.shape[1] % 2:
        raise RenderError(f"codebook must have shape [K, 2d], got {tuple(book.shape)}")
    if samples < 3:
        raise RenderError(f"samples must be at least 3, got {samples}")
    num_codes, dim = book.shape[0], book.shape[1] // 2
    phase = np.arange(samples) / samples
    curves = (
        book[:, None, :dim] * np.sin(2 * np.pi * phase)[None, :, None]
        + book[:, None, dim:] * np.cos(2 * np.pi * phase)[None, :, None]
    )  # [K, S, d]
    mean, axes = _pca(curves.reshape(-1, dim))
    flat = (curves - mean) @ axes  # [K, S, 2]
    closed = np.concatenate([flat, flat[:, :1]], axis=1)

    names = list(usage) if usage is not None else [""]
    counts = {}
    for name, values in (usage or {}).items():
        codes = _array(values, f"usage[{name!r}]").astype(np.int64).reshape(-1)
        if codes.size and (codes.min() < 0 or codes.max() >= num_codes):
            raise RenderError(f"usage[{name!r}] has codes outside [0, {num_codes})")
        counts[name] = np.bincount(codes, minlength=num_codes)
    figure = _figure((4.2 * len(names) + 0.8, 4.2))
    cmap = _colormap("turbo", num_codes)
    colors = cmap(np.arange(num_codes) / num_codes)
    panels = figure.subplots(1, len(names), squeeze=False)[0]
    for ax, name in zip(panels, names, strict=True):
        if name in counts:
            share = counts[name] / max(counts[name].sum(), 1)
            used = share > 0
            widths = 0.8 + 3.2 * share[used] / share.max()
            ax.add_collection(LineCollection(list(closed[~used]), colors="#d0d0d0", linewidths=0.8))
            ax.add_collection(
                LineCollection(list(closed[used]), colors=colors[used], linewidths=widths)
            )
            ax.set_title(f"{name}: {int(used.sum())}/{num_codes} codes")
        else:
            ax.add_collection(LineCollection(list(closed), colors=colors, linewidths=1.4))
            ax.set_title(f"phase manifold ({num_codes} codes)")
        if points is not None and name in points:
            pts = _array(points[name], f"points[{name!r}]")
            if pts.ndim != 2 or pts.shape[1] != dim:
                raise RenderError(f"points[{name!r}] must have shape [N, {dim}], got {pts.shape}")
            xy = (pts - mean) @ axes
            dot_colors = colors[_codes_or_zero(usage, name, len(pts))]
            ax.scatter(xy[:, 0], xy[:, 1], s=4, c=dot_colors, alpha=0.6, linewidths=0)
        ax.autoscale_view()
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("PC 1")
        ax.set_ylabel("PC 2")
    _colorbar(figure, panels, cmap, num_codes)
    return _finish(figure, out)


def plot_phase_over_time(
    phase: ArrayLike | Mapping[str, ArrayLike],
    frequency: ArrayLike | Mapping[str, ArrayLike] | None = None,
    code: ArrayLike | Mapping[str, ArrayLike] | None = None,
    *,
    fps: float = 30.0,
    out: str | Path | None = None,
) -> Figure:
    """Plot phase, frequency and code index against time, one row per quantity.

    Pass one array per quantity, or a mapping ``name -> array`` to compare
    characters on the same axes (e.g. ``{"human": ..., "dog": ...}``).

    Args:
        phase: Phase per frame ``[T]`` (cycles; drawn wrapped to ``[-0.5, 0.5)`` as dots).
        frequency: Frequency per frame ``[T]`` in Hz.
        code: Codebook index per frame ``[T]``.
        fps: Frame rate, for the time axis.
        out: Optional path to save the figure to.

    Returns:
        The figure.

    Raises:
        RenderError: If ``fps`` is not positive or a series is not 1-D.

    Examples:
        >>> import numpy as np
        >>> from skelagnostic.viz import plot_phase_over_time
        >>> t = np.arange(90) / 30
        >>> fig = plot_phase_over_time(1.5 * t, frequency=np.full(90, 1.5), fps=30)
        >>> [ax.get_ylabel() for ax in fig.axes]
        ['phase (cycles)', 'frequency (Hz)']
    """
    if not fps > 0:
        raise RenderError(f"fps must be positive, got {fps}")
    rows = [("phase", phase, "phase (cycles)")]
    optional = (("frequency", frequency, "frequency (Hz)"), ("code", code, "code"))
    rows += [row for row in optional if row[1] is not None]
    figure = _figure((8.0, 2.0 * len(rows) + 0.6))
    axes = figure.subplots(len(rows), 1, sharex=True, squeeze=False)[:, 0]
    for ax, (quantity, series, label) in zip(axes, rows, strict=True):
        for k, (name, values) in enumerate(_named(series, quantity).items()):
            t = np.arange(len(values)) / fps
            color = f"C{k}"
            if quantity == "phase":
                wrapped = (values + 0.5) % 1.0 - 0.5
                ax.scatter(t, wrapped, s=4, color=color, label=name or None)
                ax.set_ylim(-0.55, 0.55)
            elif quantity == "code":
                ax.step(t, values, where="post", color=color, label=name or None)
            else:
                ax.plot(t, values, color=color, label=name or None)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    if any(_named(phase, "phase")):
        axes[0].legend(loc="upper right", fontsize=8, markerscale=3)
    axes[-1].set_xlabel("time (s)")
    return _finish(figure, out)


def plot_codebook_usage(
    codes: Mapping[str, ArrayLike],
    num_codes: int,
    *,
    out: str | Path | None = None,
) -> Figure:
    """Bar chart of how often each code is used, per dataset.

    Bars are the share of each dataset's frames per code; the title reports the
    share of codes used by any dataset and by every dataset (the manifold overlap
    of WalkTheDog, Table 2).

    Args:
        codes: Per dataset, the code index of each frame ``[N]``.
        num_codes: Codebook size ``K``.
        out: Optional path to save the figure to.

    Returns:
        The figure.

    Raises:
        RenderError: If ``codes`` is empty or holds indices outside ``[0, num_codes)``.

    Examples:
        >>> from skelagnostic.viz import plot_codebook_usage
        >>> fig = plot_codebook_usage({"human": [0, 1, 1, 3], "dog": [1, 3, 3, 3]}, 4)
        >>> fig.axes[0].get_title()
        'codes used: 3/4 (75%), by every dataset: 2/4 (50%)'
    """
    if not codes:
        raise RenderError("codes: needs at least one dataset")
    if num_codes < 1:
        raise RenderError(f"num_codes must be at least 1, got {num_codes}")
    shares = {}
    for name, values in codes.items():
        index = _array(values, f"codes[{name!r}]").astype(np.int64).reshape(-1)
        if index.size and (index.min() < 0 or index.max() >= num_codes):
            raise RenderError(f"codes[{name!r}] has indices outside [0, {num_codes})")
        shares[name] = np.bincount(index, minlength=num_codes) / max(index.size, 1)
    used = np.stack([s > 0 for s in shares.values()])
    any_used, all_used = int(used.any(0).sum()), int(used.all(0).sum())
    figure = _figure((max(6.0, 0.22 * num_codes + 2.0), 3.4))
    ax = figure.subplots()
    width = 0.8 / len(shares)
    x = np.arange(num_codes)
    for k, (name, share) in enumerate(shares.items()):
        ax.bar(x - 0.4 + width * (k + 0.5), share, width=width, label=name, color=f"C{k}")
    ax.set_xlabel("code")
    ax.set_ylabel("share of frames")
    ax.set_xlim(-0.6, num_codes - 0.4)
    ax.set_title(
        f"codes used: {any_used}/{num_codes} ({100 * any_used / num_codes:.0f}%), "
        f"by every dataset: {all_used}/{num_codes} ({100 * all_used / num_codes:.0f}%)"
    )
    ax.legend(fontsize=8)
    ax.grid(axis="y", alpha=0.3)
    return _finish(figure, out)


def plot_metric_curves(
    x: ArrayLike | None,
    series: Mapping[str, ArrayLike | tuple[ArrayLike, ArrayLike]],
    *,
    xlabel: str,
    ylabel: str,
    title: str | None = None,
    spread: Mapping[str, ArrayLike] | None = None,
    logx: bool = False,
    logy: bool = False,
    out: str | Path | None = None,
) -> Figure:
    """Plot an error metric against a varying setting, one line per method.

    For instance noise level vs MPJPE (denoising), joints kept vs error
    (upsampling), keyframe gap vs L2P (interpolation).

    Args:
        x: Shared x values ``[N]``; ``None`` when every series brings its own.
        series: ``name -> y`` (``[N]``, on the shared ``x``) or ``name -> (x, y)``.
        xlabel: Label of the x axis.
        ylabel: Label of the y axis.
        title: Optional title.
        spread: Optional ``name -> s``: shades ``y - s .. y + s`` (e.g. a std).
        logx: Logarithmic x axis.
        logy: Logarithmic y axis.
        out: Optional path to save the figure to.

    Returns:
        The figure.

    Raises:
        RenderError: If ``series`` is empty or x and y lengths differ.

    Examples:
        >>> from skelagnostic.viz import plot_metric_curves
        >>> fig = plot_metric_curves([5, 15, 30], {"interp": [0.37, 1.25, 2.32]},
        ...                          xlabel="transition (frames)", ylabel="L2P")
        >>> fig.axes[0].get_lines()[0].get_ydata().tolist()
        [0.37, 1.25, 2.32]
    """
    if not series:
        raise RenderError("series: needs at least one curve")
    figure = _figure((6.0, 4.0))
    ax = figure.subplots()
    for k, (name, values) in enumerate(series.items()):
        if isinstance(values, tuple):
            xs, ys = (_array(v, f"series[{name!r}]").reshape(-1) for v in values)
        elif x is None:
            raise RenderError(f"series[{name!r}]: give x, or an (x, y) pair for this series")
        else:
            xs, ys = _array(x, "x").reshape(-1), _array(values, f"series[{name!r}]").reshape(-1)
        if len(xs) != len(ys):
            raise RenderError(f"series[{name!r}]: {len(xs)} x values for {len(ys)} y values")
        ax.plot(xs, ys, marker="o", markersize=4, color=f"C{k}", label=name)
        if spread is not None and name in spread:
            s = _array(spread[name], f"spread[{name!r}]").reshape(-1)
            if len(s) != len(ys):
                raise RenderError(f"spread[{name!r}]: {len(s)} values for {len(ys)} points")
            ax.fill_between(xs, ys - s, ys + s, color=f"C{k}", alpha=0.2, linewidth=0)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title)
    if logx:
        ax.set_xscale("log")
    if logy:
        ax.set_yscale("log")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return _finish(figure, out)


def plot_method_comparison(
    values: Mapping[str, Mapping[str, float | None]],
    *,
    title: str | None = None,
    out: str | Path | None = None,
) -> Figure:
    """One bar panel per metric: a model's figure beside its baselines'.

    Args:
        values: ``method -> metric -> value`` (``None`` or a missing metric: no bar).
        title: Optional title of the figure.
        out: Optional path to save the figure to.

    Returns:
        The figure.

    Raises:
        RenderError: If ``values`` holds no finite value.

    Examples:
        >>> from skelagnostic.viz import plot_method_comparison
        >>> fig = plot_method_comparison({"model": {"mpjpe": 2.0}, "mean_pose": {"mpjpe": 9.0}})
        >>> [float(round(b.get_height(), 1)) for b in fig.axes[0].patches]
        [2.0, 9.0]
    """
    metrics = list(dict.fromkeys(m for row in values.values() for m in row))
    if not metrics:
        raise RenderError("values: needs at least one method with one metric")
    figure = _figure((min(3.2 * len(metrics), 16.0), 3.6))
    axes = figure.subplots(1, len(metrics), squeeze=False)[0]
    methods = list(values)
    for ax, metric in zip(axes, metrics, strict=True):
        shown = [(k, m, values[m].get(metric)) for k, m in enumerate(methods)]
        shown = [(k, m, float(v)) for k, m, v in shown if v is not None and np.isfinite(v)]
        ax.bar(range(len(shown)), [v for _, _, v in shown], color=[f"C{k}" for k, _, _ in shown])
        ax.set_xticks(
            range(len(shown)), [m for _, m, _ in shown], rotation=30, ha="right", fontsize=8
        )
        ax.set_title(metric, fontsize=9)
        ax.grid(alpha=0.3, axis="y")
    if title:
        figure.suptitle(title, fontsize=10)
    return _finish(figure, out)


def _array(values: Any, name: str) -> np.ndarray:
    if hasattr(values, "detach"):
        values = values.detach().cpu().numpy()
    try:
        array = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise RenderError(f"{name}: not a numeric array ({error})") from error
    if not np.isfinite(array).all():
        raise RenderError(f"{name}: contains NaN or inf values")
    return array


def _named(series: ArrayLike | Mapping[str, ArrayLike], quantity: str) -> dict[str, np.ndarray]:
    items = series.items() if isinstance(series, Mapping) else [("", series)]
    named = {}
    for name, values in items:
        array = _array(values, f"{quantity}[{name!r}]" if name else quantity)
        if array.ndim != 1:
            raise RenderError(f"{quantity}: expected a 1-D array per series, got {array.shape}")
        named[name] = array
    return named


def _codes_or_zero(usage: Mapping[str, ArrayLike] | None, name: str, count: int) -> np.ndarray:
    """Codes of ``name``'s frames for colouring its points (code 0 when unknown)."""
    if usage is None or name not in usage:
        return np.zeros(count, dtype=np.int64)
    codes = np.asarray(usage[name]).astype(np.int64).reshape(-1)
    if len(codes) != count:
        raise RenderError(f"points[{name!r}] has {count} rows but usage[{name!r}] {len(codes)}")
    return codes


def _pca(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and the two leading principal axes ``[d, 2]`` (zero-padded when d < 2)."""
    mean = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - mean, full_matrices=False)
    axes = vt[:2].T
    if axes.shape[1] < 2:
        axes = np.pad(axes, ((0, 0), (0, 2 - axes.shape[1])))
    return mean, axes


def _colormap(name: str, count: int) -> Any:
    import matplotlib

    return matplotlib.colormaps[name].resampled(max(count, 1))


def _colorbar(figure: Figure, axes: Sequence[Any], cmap: Any, count: int) -> None:
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    mappable = ScalarMappable(norm=Normalize(-0.5, count - 0.5), cmap=cmap)
    figure.colorbar(mappable, ax=list(axes), label="code", fraction=0.04)


def _figure(size: tuple[float, float]) -> Figure:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=size, dpi=100, layout="constrained")
    FigureCanvasAgg(figure)
    return figure


def _finish(figure: Figure, out: str | Path | None) -> Figure:
    if out is not None:
        path = Path(out)
        if path.suffix.lower() not in (".png", ".svg", ".pdf"):
            raise RenderError(f"out: unsupported figure format {path.suffix!r}; use .png/.svg/.pdf")
        from skelagnostic.io.outputs import write_output

        fmt = path.suffix.lower()[1:]  # atomically: a failed write keeps the previous figure
        write_output(path, lambda fh: figure.savefig(fh, format=fmt), "out")
    return figure
