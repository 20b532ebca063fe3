"""The main job's picture: a held-out clip, its transfers, one scale, and the feet's rhythm.

:func:`plot_transfer` draws, for one source clip (a held-out human walk) and the
motions made from it on the target character (the VQ-PAE transfer and the two
baselines of :func:`~skelagnostic_vqpae.protocols.transfer.transfer_rows`):

* a grid of side views, one column per motion and one row per instant, every
  target motion at one scale (the same axis limits), the source at its own;
* a foot-contact timeline per target motion: the source's touch-downs drawn over
  the target's (:func:`~skelagnostic.analysis.motion_onsets`, the rule the
  rhythm figures use), so whether the target steps in the source's rhythm shows at
  a glance, with the touch-down rates of both.

The fit summary of a VQ-PAE run saves it as ``vqpae_transfer.png``;
``scripts/vqpae_main_picture.py`` draws it again from a finished run directory.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from skelagnostic.analysis import foot_joints, forward_swings, motion_onsets, onset_rate
from skelagnostic.core.motion import Motion
from skelagnostic.viz.render import BODY_GROUP_COLORS
from skelagnostic.viz.stick import RenderError, StickFigure

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["EVENTS", "PANEL_INCHES", "PICTURE_DPI", "plot_transfer", "side_view"]

#: Height (and width) of one pose panel's cell, inches (at :data:`PICTURE_DPI`: 450 pixels;
#: the panel itself, inside the cell's margins, is over 400 pixels high).
PANEL_INCHES = 4.5
#: Resolution of the picture, dots per inch.
PICTURE_DPI = 100
#: Height of one foot-contact timeline, inches.
TIMELINE_INCHES = 1.9
#: Colour of each target motion (the model first), in order.
METHOD_COLORS = ("#2e7d32", "#ef6c00", "#6a1b9a", "#1565c0", "#c62828")
#: Seconds over which :func:`side_view` reads the direction of travel (centred on the instant).
HEADING_SPAN = 1.0
#: Height of one row of the code strip (one motion's codebook index per frame), inches.
CODE_ROW_INCHES = 0.42


def _figure(width: float, height: float) -> Figure:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=(width, height), dpi=PICTURE_DPI)
    FigureCanvasAgg(figure)
    return figure


def side_view(figure: StickFigure, times: Sequence[float]) -> np.ndarray:
    """``[T, J, 2]`` joints seen from the side: along the travel, and up from the ground.

    The horizontal coordinate is the joint's distance ahead of the root along the
    direction the root travels over :data:`HEADING_SPAN` seconds around the instant
    (the whole clip's travel when it stands still there; the first axis when it never
    moves); the vertical one its height over the clip's lowest joint.

    Args:
        figure: The character (any units).
        times: Instants, seconds.

    Returns:
        The projected joints, in the figure's units.
    """
    times = np.asarray(times, dtype=np.float64)
    pos = figure.sample(times)
    ground = float(figure.z_up()[..., 2].min())
    ahead = figure.sample(times + HEADING_SPAN / 2)[:, 0, :2]
    behind = figure.sample(times - HEADING_SPAN / 2)[:, 0, :2]
    travel = ahead - behind
    whole = figure.z_up()[-1, 0, :2] - figure.z_up()[0, 0, :2]
    fallback = whole if np.linalg.norm(whole) > 1e-9 else np.array([1.0, 0.0])
    small = np.linalg.norm(travel, axis=1) <= 1e-6 * max(np.ptp(pos[..., 2]), 1e-9)
    travel[small] = fallback
    heading = travel / np.linalg.norm(travel, axis=1, keepdims=True)
    local = pos[..., :2] - pos[:, :1, :2]
    x = np.einsum("tjk,tk->tj", local, heading)
    return np.stack([x, pos[..., 2] - ground], axis=-1)


def _draw_pose(ax: Any, figure: StickFigure, xy: np.ndarray) -> None:
    """One pose: bones coloured by body group, joints as dots, the ground line."""
    for parent, child in figure.bones:
        ax.plot(
            xy[[parent, child], 0],
            xy[[parent, child], 1],
            color=BODY_GROUP_COLORS[figure.groups[child]],
            lw=2.6,
            solid_capstyle="round",
        )
    ax.scatter(xy[:, 0], xy[:, 1], s=7, color="#212121", zorder=3)


def _limits(views: Sequence[np.ndarray], aspect: float) -> tuple[tuple[float, float], ...]:
    """Axis limits holding every pose of ``views`` at one scale, width / height = ``aspect``."""
    points = np.concatenate([v.reshape(-1, 2) for v in views])
    lo, hi = points.min(0), points.max(0)
    height = max(hi[1], 1e-9) * 1.12
    width = max(hi[0] - lo[0], 1e-9) * 1.15
    height = max(height, width / aspect)
    width = height * aspect
    centre = (lo[0] + hi[0]) / 2
    return (centre - width / 2, centre + width / 2), (-0.06 * height, 0.94 * height)


def _scale_bar(ax: Any, xlim: tuple[float, float], ylim: tuple[float, float]) -> None:
    """A bar of a round length (metres) in the panel's lower right corner."""
    span = xlim[1] - xlim[0]
    length = next(v for v in (0.1, 0.2, 0.25, 0.5, 1.0, 2.0, 5.0) if v >= span / 6)
    x1 = xlim[1] - 0.04 * span
    y = ylim[0] + 0.5 * (0 - ylim[0])
    ax.plot([x1 - length, x1], [y, y], color="#455a64", lw=3)
    label = f"{length * 100:g} cm" if length < 1 else f"{length:g} m"
    ax.text(x1 - length / 2, y, label, ha="center", va="bottom", fontsize=10, color="#455a64")


#: The events :func:`plot_transfer` can draw on its timelines: what each marks, per foot.
EVENTS = {
    "touchdown": "touch-downs (the foot's height reaching its local low)",
    "swing": "forward swings (the foot passing under the body, forwards: once per stride)",
}


def _events(motion: Motion, events: str) -> list[np.ndarray]:
    """Per foot (:func:`~skelagnostic.analysis.foot_joints`), event times in frames."""
    return motion_onsets(motion) if events == "touchdown" else forward_swings(motion)


def _instants(source: Motion, instants: Sequence[float] | None) -> list[float]:
    """The instants to draw (default: two, a third of a second apart), checked in the clip."""
    duration = (source.num_frames - 1) / source.fps
    if instants is None:
        start = min(1.0, duration / 3)
        instants = [start, min(start + 1 / 3, duration)]
    instants = [float(t) for t in instants]
    if not instants or any(not 0 <= t <= duration for t in instants):
        raise RenderError(
            f"instants: every instant must lie within 0-{duration:.2f} s of the source"
        )
    return instants


def _draw_header(fig: Figure, title: str, wrapped: Sequence[str], height: float) -> None:
    """The figure's title and its note lines (``height``: the figure's, inches)."""
    fig.suptitle(
        title,
        fontsize=17,
        fontweight="bold",
        y=1 - 0.2 / height,
        va="top",
    )
    for k, line in enumerate(wrapped):
        fig.text(
            0.5,
            1 - (0.62 + 0.25 * k) / height,
            line,
            ha="center",
            va="top",
            fontsize=12,
            color="#37474f",
        )


def _draw_poses(
    fig: Figure,
    grid: Any,
    figures: Sequence[StickFigure],
    views: Sequence[np.ndarray],
    instants: Sequence[float],
    labels: Sequence[str],
) -> None:
    """The pose grid: one row per instant, the source's column first, then each output's."""
    rows = len(instants)
    source_lim = _limits(views[:1], 1.0)
    target_lim = _limits(views[1:], 1.0)
    for r, t in enumerate(instants):
        for c, (figure, view) in enumerate(zip(figures, views, strict=True)):
            ax = fig.add_subplot(grid[r, c])
            color = "#212121" if c == 0 else METHOD_COLORS[(c - 1) % len(METHOD_COLORS)]
            xlim, ylim = source_lim if c == 0 else target_lim
            ax.axhspan(ylim[0], 0, color="#eceff1", zorder=0)
            _draw_pose(ax, figure, view[r])
            ax.set_xlim(*xlim)
            ax.set_ylim(*ylim)
            ax.set_aspect("equal", adjustable="box")
            ax.set_xticks([])
            ax.set_yticks([])
            for side in ("top", "right", "left", "bottom"):
                ax.spines[side].set_color("#b0bec5" if c == 0 else color)
                ax.spines[side].set_linewidth(1 if c == 0 else 2)
            if r == 0:
                ax.set_title(labels[c], fontsize=13, color=color, fontweight="bold")
            ax.text(
                0.03,
                0.95,
                f"t = {t:.2f} s",
                transform=ax.transAxes,
                fontsize=11,
                va="top",
                color="#455a64",
            )
            if r == rows - 1 and c in (0, 1):
                _scale_bar(ax, xlim, ylim)


class _Lanes:
    """The feet's timelines: the source's events beside one output's, and their rates."""

    def __init__(self, source: Motion, events: str, source_label: str, target_label: str) -> None:
        self.source, self.events = source, events
        self.source_label, self.target_label = source_label, target_label
        self.source_events = _events(source, events)
        self.source_rate = onset_rate(self.source_events, source.fps)
        self.source_feet = [source.skeleton.joint_names[j] for j in foot_joints(source)]
        self.reference = next(
            (np.sort(o) / source.fps for o in self.source_events if len(o)), np.zeros(0)
        )
        self.unit = "touch-downs" if events == "touchdown" else "strides"

    def draw(
        self, ax: Any, label: str, motion: Motion, color: str, instants: Sequence[float]
    ) -> None:
        """One output's timeline on ``ax``, titled ``label``, with its rate against the source's."""
        source, source_events = self.source, self.source_events
        source_label, target_label = self.source_label, self.target_label
        duration = (source.num_frames - 1) / source.fps
        marks = _events(motion, self.events)
        feet = [motion.skeleton.joint_names[j] for j in foot_joints(motion)]
        lanes = [o / source.fps for o in source_events] + [o / motion.fps for o in marks]
        names = [f"{source_label} {n}" for n in self.source_feet] + [
            f"{target_label} {n}" for n in feet
        ]
        offsets = list(range(len(lanes)))[::-1]
        colors = ["#212121"] * len(source_events) + [color] * len(marks)
        for t in self.reference:
            ax.axvline(t, color="#9e9e9e", lw=0.8, ls=(0, (3, 3)), zorder=0)
        ax.eventplot(lanes, lineoffsets=offsets, linelengths=0.8, linewidths=2.4, colors=colors)
        ax.set_yticks(offsets, names)
        ax.tick_params(axis="y", labelsize=9)
        for tick, c in zip(ax.get_yticklabels(), colors, strict=True):
            tick.set_color(c)
        ax.set_xlim(0, duration)
        ax.set_ylim(-0.7, len(lanes) - 0.3)
        for t in instants:
            ax.axvspan(t - 0.02, t + 0.02, color="#ffca28", alpha=0.6, zorder=0)
        rate = onset_rate(marks, motion.fps)
        source_rate = self.source_rate
        error = abs(rate / source_rate - 1) * 100 if source_rate > 0 else math.nan
        ax.set_title(
            label.replace("\n", " "), loc="left", fontsize=12, color=color, fontweight="bold"
        )
        ax.text(
            1.015,
            0.5,
            f"{self.unit}\nper second and foot:\n{source_label} {source_rate:.2f}\n"
            f"{target_label} {rate:.2f} ({error:.1f} % off)",
            transform=ax.transAxes,
            fontsize=11,
            va="center",
            color=color,
        )


def _draw_codes(
    ax: Any, codes: Sequence[tuple[np.ndarray, float]], labels: Sequence[str], duration: float
) -> None:
    """One row per motion: its codebook index per frame, one colour per code, numbered."""
    from matplotlib import colormaps

    palette = colormaps["tab10"]  # ten clearly different colours (tab20 pairs close shades)
    rows = len(codes)
    for r, (code, fps) in enumerate(codes):
        y = rows - 1 - r
        code = np.asarray(code).reshape(-1)
        starts = np.flatnonzero(np.r_[True, code[1:] != code[:-1]])
        ends = np.r_[starts[1:], len(code)]
        for a, b in zip(starts, ends, strict=True):
            t0, t1 = a / fps, min(b / fps, duration)
            ax.broken_barh([(t0, t1 - t0)], (y - 0.4, 0.8), color=palette(int(code[a]) % 10))
            if t1 - t0 > 0.25:
                ax.text((t0 + t1) / 2, y, str(int(code[a])), ha="center", va="center", fontsize=9)
    # the outputs' first line without the target's name ("VQ-PAE"), in their colours
    short = [labels[0]] + [label.split("\n")[0].split(": ", 1)[-1] for label in labels[1:]]
    ax.set_yticks(range(rows)[::-1], short)
    ax.tick_params(axis="y", labelsize=9)
    for k, tick in enumerate(ax.get_yticklabels()[1:]):
        tick.set_color(METHOD_COLORS[k % len(METHOD_COLORS)])
    ax.set_xlim(0, duration)
    ax.set_ylim(-0.5, rows - 0.5)
    ax.set_xticklabels([])
    ax.set_title(
        "codebook index per frame: the source's, and of the target frames each method "
        "replays (same colour and number = same code, a shared part of the phase manifold)",
        loc="left",
        fontsize=11,
        fontweight="bold",
    )


def plot_transfer(
    source: Motion,
    outputs: Mapping[str, Motion],
    *,
    instants: Sequence[float] | None = None,
    title: str | None = None,
    notes: Sequence[str] = (),
    source_label: str = "source",
    target_label: str = "target",
    events: str = "touchdown",
    codes: Sequence[tuple[np.ndarray, float]] | None = None,
    out: str | Path | None = None,
) -> Figure:
    """The source clip and its transfers: poses at one scale and the feet's rhythm.

    Args:
        source: The source clip (e.g. a held-out human walk).
        outputs: ``label -> motion`` of the target character made from ``source``
            (the model first, then the baselines), each as long as the source; the
            labels title the columns and timelines (a newline splits a long one).
        instants: Seconds at which the poses are drawn, one row each (default: two
            instants a third of a second apart, one second into the clip).
        title: The figure's title (default: what is compared, with the clip's name).
        notes: Paragraphs printed under the title (e.g. the run and its shared codes).
        source_label: The source character's name on the timelines' lanes.
        target_label: The target character's name on the timelines' lanes.
        events: What the timelines mark per foot (:data:`EVENTS`): ``"touchdown"``
            (:func:`~skelagnostic.analysis.motion_onsets`, the rule of the
            rhythm figures) or ``"swing"``
            (:func:`~skelagnostic.analysis.forward_swings`, the events of the
            gait frequency; for characters whose feet touch down more than once per
            stride, such as the procedural generator's).
        codes: Optional, per motion (the source first, then the outputs): its codebook
            index per frame and their frame rate, drawn as a strip of coloured rows
            above the timelines, so shared codes show at a glance.
        out: Optional image path (``.png``).

    Returns:
        The figure (Agg canvas). Its axes: the pose grid row by row (the source's
        column first), the code strip (with ``codes``), then one timeline per output.

    Raises:
        RenderError: No output, an instant outside the source clip, unknown events, or
            ``codes`` not one per motion.

    Example:
        >>> from skelagnostic import procedural
        >>> human, _ = procedural.generate("biped22", "walk", seconds=3.0, seed=0)
        >>> dog, _ = procedural.generate("quadruped", "walk", seconds=3.0, seed=1)
        >>> fig = plot_transfer(human, {"dog": dog})
        >>> len(fig.axes)  # 2 rows x (source + 1 output), 1 timeline
        5
    """
    import textwrap

    if not outputs:
        raise RenderError("outputs: no transferred motion to draw")
    if events not in EVENTS:
        raise RenderError(f"events: one of {', '.join(EVENTS)}, got {events!r}")
    instants = _instants(source, instants)
    motions = [source, *outputs.values()]
    if codes is not None and len(codes) != len(motions):
        raise RenderError(f"codes: one per motion ({len(motions)}), got {len(codes)}")
    strip = CODE_ROW_INCHES * len(motions) + 0.5 if codes is not None else 0.0
    labels = [
        f"{source_label}: {source.name}" if getattr(source, "name", None) else source_label,
        *outputs,
    ]
    figures = [StickFigure.from_motion(m.to_metres()) for m in motions]
    views = [side_view(f, instants) for f in figures]
    columns, rows = len(motions), len(instants)
    width = PANEL_INCHES * columns
    wrapped = [line for note in notes for line in textwrap.wrap(note, int(width * 11))]
    header = 0.75 + 0.25 * len(wrapped) + (0.25 if any("\n" in x for x in labels) else 0)
    height = header + PANEL_INCHES * rows + strip + TIMELINE_INCHES * len(outputs) + 0.7
    fig = _figure(width, height)
    top = 1 - header / height
    poses_bottom = top - PANEL_INCHES * rows / height
    grid = fig.add_gridspec(
        rows,
        columns,
        left=0.01,
        right=0.99,
        top=top - 0.25 / height,
        bottom=poses_bottom,
        wspace=0.03,
        hspace=0.12,
    )
    _draw_poses(fig, grid, figures, views, instants, labels)
    timeline = fig.add_gridspec(
        len(outputs) + (codes is not None),
        1,
        left=0.1,
        right=0.84,
        top=poses_bottom - 0.6 / height,
        bottom=0.5 / height,
        hspace=0.55,
        height_ratios=([strip - 0.5] if codes is not None else [])
        + [TIMELINE_INCHES] * len(outputs),
    )
    if codes is not None:
        duration = (source.num_frames - 1) / source.fps
        _draw_codes(fig.add_subplot(timeline[0, 0]), codes, labels, duration)
    lanes = _Lanes(source, events, source_label, target_label)
    for i, (label, motion) in enumerate(outputs.items()):
        ax = fig.add_subplot(timeline[i + (codes is not None), 0])
        lanes.draw(ax, label, motion, METHOD_COLORS[i % len(METHOD_COLORS)], instants)
        if i == len(outputs) - 1:
            ax.set_xlabel(
                f"time (s). Ticks: each foot's {EVENTS[events]}; black: {source_label}, "
                f"colour: {target_label}. Dashed lines: the {source_label}'s first foot; "
                "yellow: the instants drawn above.",
                fontsize=11,
            )
        else:
            ax.set_xticklabels([])
    _draw_header(
        fig,
        title or f"Held-out clip {source.name!r} re-enacted by another character",
        wrapped,
        height,
    )
    if out is not None:
        path = Path(out)
        path.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path)
    return fig
