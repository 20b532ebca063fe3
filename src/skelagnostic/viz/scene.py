"""The matplotlib scene behind :mod:`skelagnostic.viz.render`: panels, cameras, artists.

A :class:`Scene` lays out one panel per group of characters (side by side, or
several overlaid in one), each with its camera, floor, grid, root paths and
stick-figure artists, and draws frame after frame by blitting the moving artists
on the saved background.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import numpy as np

from skelagnostic.viz.camera import Camera, auto_azimuth
from skelagnostic.viz.stick import StickFigure

__all__ = ["BODY_GROUP_COLORS", "Panel", "Scene"]

#: Bone colour of each body group (left side cool, right side warm).
BODY_GROUP_COLORS: dict[str, str] = {
    "spine": "#37474f",
    "left_arm": "#1e88e5",
    "right_arm": "#e53935",
    "left_leg": "#43a047",
    "right_leg": "#fb8c00",
    "tail": "#8e24aa",
    "other": "#9e9e9e",
}

_BACKGROUND = "#ffffff"
_FLOOR = "#eceff1"
_GRID = "#cfd8dc"
#: Joint colour and bone line style per character in overlay mode.
_OVERLAY_JOINTS = ("#212121", "#6a1b9a", "#00838f", "#c62828", "#2e7d32")
_OVERLAY_STYLES: tuple[Any, ...] = ("solid", (0, (4, 2)), (0, (1, 1.5)))
_MARGIN = 0.08


def _nice_step(extent: float) -> float:
    """A 1/2/5 x 10^k grid spacing giving about eight cells over ``extent``."""
    raw = max(extent, 1e-9) / 8.0
    base = 10.0 ** math.floor(math.log10(raw))
    return base * min((m for m in (1.0, 2.0, 5.0, 10.0) if m * base >= raw), default=10.0)


class Panel:
    """One axes: its camera, floor, and the per-frame horizontal shift of the follow camera."""

    def __init__(self, ax: Any, members: list[int], camera: Camera, shift: np.ndarray) -> None:
        self.ax = ax
        self.members = members
        self.camera = camera
        self.shift = shift  # [F, 3] subtracted from world positions (zeros: fixed camera)
        #: Follow camera only: (LineCollection, [N, 2, 3] world lines) of the sliding grid
        #: and of the root paths, re-projected every frame.
        self.grid: tuple[Any, np.ndarray] | None = None
        self.grid_step = 0.0
        self.paths: list[tuple[Any, np.ndarray]] = []
        #: ``[N, 2]`` projected points the panel's view must hold (its framing).
        self.framed = np.zeros((0, 2))
        #: Share of the panel's height kept free at the top (for its label).
        self.top = 0.0


class Scene:
    """Figure, artists and cameras for one rendering; draws frame after frame."""

    def __init__(
        self,
        figures: list[StickFigure],
        groups: list[list[int]],
        times: np.ndarray,
        size: tuple[int, int],
        options: dict[str, Any],
    ) -> None:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        self.figures = figures
        self.size = size
        self.times = times
        #: Playback rate of the frames (set by :func:`skelagnostic.viz.render.render_frames`).
        self.rate = 0.0
        self.background: Any = None
        self.projected: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self.world = [f.sample(times) for f in figures]  # [F, J, 3] z-up
        width, height = size
        dpi = 100.0
        self.figure = Figure(figsize=(width * len(groups) / dpi, height / dpi), dpi=dpi)
        self.figure.patch.set_facecolor(_BACKGROUND)
        self.canvas = FigureCanvasAgg(self.figure)
        self.scale = height / 320.0
        self.panels: list[Panel] = []
        self.panel_of: dict[int, Panel] = {}
        self.bone_artists: dict[int, Any] = {}
        self.joint_artists: dict[int, Any] = {}
        self.bone_colors: dict[int, np.ndarray] = {}
        for p, members in enumerate(groups):
            ax = self.figure.add_axes((p / len(groups), 0.0, 1.0 / len(groups), 1.0))
            ax.set_axis_off()
            panel = self._build_panel(ax, members, options)
            self.panels.append(panel)
            self.panel_of.update(dict.fromkeys(members, panel))
        self._frame_panels(options["same_scale"])
        self.clock = None
        if options["time_label"]:
            ax = self.panels[-1].ax
            self.clock = ax.text(
                0.97,
                0.97,
                "",
                transform=ax.transAxes,
                ha="right",
                va="top",
                fontsize=9 * self.scale,
                color="#455a64",
                family="monospace",
                animated=True,
            )

    def _build_panel(self, ax: Any, members: list[int], options: dict[str, Any]) -> Panel:
        """The panel of the characters ``members``: camera, floor, grid, paths, artists, label."""
        world = [self.world[k] for k in members]
        azim = options["azim"]
        camera = Camera(auto_azimuth(world) if azim is None else float(azim), options["elev"])
        ground = min(float(p[..., 2].min()) for p in world)
        shift = np.zeros((len(self.times), 3))
        if options["follow"]:
            shift[:, :2] = np.mean([p[:, 0, :2] for p in world], axis=0)
        panel = Panel(ax, members, camera, shift)
        local = np.concatenate([(p - shift[:, None]).reshape(-1, 3) for p in world])
        paths = {k: self._root_path(k, ground) for k in members} if options["trajectory"] else {}
        framed = [local] if options["follow"] else [local, *paths.values()]
        panel.framed = camera.project(np.concatenate(framed))[0]
        floor = _add_floor(panel, local, framed[1:], ground, options["follow"])
        overlay = len(members) > 1
        handles = [
            self._add_figure(panel, k, rank, overlay, paths.get(k), floor, options["follow"])
            for rank, k in enumerate(members)
        ]
        self._add_label(panel, handles, overlay)
        return panel

    def _add_figure(
        self,
        panel: Panel,
        k: int,
        rank: int,
        overlay: bool,
        root_path: np.ndarray | None,
        floor: Any,
        follow: bool,
    ) -> Any:
        """Add character ``k``'s root path, bones and joints to its panel; return its legend handle.

        Args:
            panel: The character's panel.
            k: The character.
            rank: Its place in the panel (its colour and line style in overlay mode).
            overlay: The panel holds several characters.
            root_path: ``[N, 3]`` root on the floor to draw, or ``None``.
            floor: The floor polygon (the path is clipped to it).
            follow: The camera follows the characters (the path moves every frame).
        """
        from matplotlib.collections import LineCollection
        from matplotlib.lines import Line2D

        ax, camera = panel.ax, panel.camera
        figure = self.figures[k]
        joint_color = _OVERLAY_JOINTS[rank % len(_OVERLAY_JOINTS)] if overlay else "#263238"
        style: Any = _OVERLAY_STYLES[rank % len(_OVERLAY_STYLES)] if overlay else "solid"
        if root_path is not None:
            segments = np.stack([root_path[:-1], root_path[1:]], axis=1)
            path = LineCollection(
                list(camera.project(segments)[0]),
                colors=joint_color,
                alpha=0.6,
                linewidths=1.5 * self.scale,
                zorder=2,
                animated=follow,
            )
            path.set_clip_path(floor)
            path.set_clip_box(ax.bbox)
            ax.add_collection(path)
            if follow:
                panel.paths.append((path, segments))
        groups = list(figure.groups or ())
        bone_colors = np.array(
            [_rgba(BODY_GROUP_COLORS[groups[c]]) for _, c in figure.bones]
        ).reshape(-1, 4)
        bones = LineCollection(
            [],
            linewidths=2.2 * self.scale,
            linestyles=style,
            capstyle="round",
            animated=True,
            zorder=3,
        )
        ax.add_collection(bones)
        joints = Line2D(
            [],
            [],
            linestyle="none",
            marker="o",
            markersize=2.6 * self.scale,
            color=joint_color,
            animated=True,
            zorder=4,
        )
        ax.add_line(joints)
        self.bone_artists[k], self.joint_artists[k] = bones, joints
        self.bone_colors[k] = bone_colors
        return Line2D(
            [],
            [],
            color=BODY_GROUP_COLORS["spine"],
            linestyle=style,
            marker="o",
            markersize=3 * self.scale,
            markerfacecolor=joint_color,
            markeredgecolor=joint_color,
            label=figure.name,
        )

    def _add_label(self, panel: Panel, handles: list[Any], overlay: bool) -> None:
        """A legend of the characters (overlay mode) or the one character's name."""
        ax = panel.ax
        if overlay:
            ax.legend(handles=handles, loc="upper left", fontsize=8 * self.scale, frameon=False)
        elif self.figures[panel.members[0]].name:
            name = self.figures[panel.members[0]].name
            fontsize = 9 * self.scale
            ax.text(
                0.03,
                0.97,
                name,
                transform=ax.transAxes,
                ha="left",
                va="top",
                fontsize=fontsize,
                color="#263238",
            )
            # the label's lines (points at 100 dpi, with line spacing) stay above the figures
            lines = name.count("\n") + 1
            panel.top = min(0.03 + (lines * 1.25 * fontsize * 100 / 72 + 4) / self.size[1], 0.5)

    def _root_path(self, k: int, ground: float) -> np.ndarray:
        """Root of figure ``k`` on the floor, at all its frames within the drawn time span."""
        figure = self.figures[k]
        first = math.floor(float(self.times.min()) * figure.fps)
        last = math.ceil(float(self.times.max()) * figure.fps)
        root = figure.z_up()[max(first, 0) : max(last, 0) + 1, 0].copy()
        root[:, 2] = ground
        return root if len(root) > 1 else np.concatenate([root, root])

    def _framing(self, panel: Panel) -> tuple[np.ndarray, np.ndarray]:
        """Centre and extent of a view of the panel's points with its aspect, under its label.

        The points fill the panel's height but the top ``panel.top``, with a margin;
        the extent is that of the whole panel (its aspect).
        """
        uv = panel.framed
        lo, hi = uv.min(axis=0), uv.max(axis=0)
        centre = (lo + hi) / 2.0
        extent = np.maximum(hi - lo, 1e-6) * (1.0 + 2.0 * _MARGIN)
        aspect = self.size[0] / (self.size[1] * (1.0 - panel.top))
        if extent[0] / extent[1] < aspect:
            extent[0] = extent[1] * aspect
        else:
            extent[1] = extent[0] / aspect
        extent[1] /= 1.0 - panel.top
        return centre, extent

    def _frame_panels(self, shared: list[int]) -> None:
        """Set every panel's fixed limits; the panels of ``shared`` get the largest extent.

        Every extent has the panel's aspect, so the element-wise largest one does too:
        the shared panels show the same length per pixel, each figure centred in the
        part of its panel under its label.
        """
        views = [self._framing(panel) for panel in self.panels]
        if shared:
            largest = np.max([views[k][1] for k in shared], axis=0)
            for k in shared:
                views[k] = (views[k][0], largest)
        for panel, (centre, extent) in zip(self.panels, views, strict=True):
            bottom = centre[1] - extent[1] * (1.0 - panel.top) / 2.0
            panel.ax.set_xlim(centre[0] - extent[0] / 2.0, centre[0] + extent[0] / 2.0)
            panel.ax.set_ylim(bottom, bottom + extent[1])
            panel.ax.set_aspect("auto")

    def panel_scales(self) -> np.ndarray:
        """Pixels per unit of length of the panel of each character (vertical = horizontal)."""
        height = self.size[1]
        scales = np.zeros(len(self.figures))
        for panel in self.panels:
            low, high = panel.ax.get_ylim()
            scales[panel.members] = height / (high - low)
        return scales

    def panel_rects(self) -> np.ndarray:
        """Pixel rectangle of the panel of each character."""
        width, height = self.size
        rects = np.zeros((len(self.figures), 4))
        for p, panel in enumerate(self.panels):
            for k in panel.members:
                rects[k] = (p * width, 0, (p + 1) * width, height)
        return rects

    def draw_all(self) -> tuple[np.ndarray, np.ndarray]:
        """Draw every frame; returns ``[F, H, W, 3]`` frames and ``[F, C, 4]`` boxes."""
        frames, boxes = [], []
        for frame, box in self.iter_frames():
            frames.append(frame)
            boxes.append(box)
        return np.stack(frames), np.stack(boxes)

    def iter_frames(self) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """Draw the frames one after the other: ``([H, W, 3]`` image, ``[C, 4]`` boxes)."""
        for f in range(len(self.times)):
            yield self.draw_frame(f)

    def draw_frame(self, f: int) -> tuple[np.ndarray, np.ndarray]:
        """Draw frame ``f``: its ``[H, W, 3]`` image and the ``[C, 4]`` character boxes."""
        if self.background is None:
            self.canvas.draw()
            self.background = self.canvas.copy_from_bbox(self.figure.bbox)
            for k, world in enumerate(self.world):
                panel = self.panel_of[k]
                self.projected[k] = panel.camera.project(world - panel.shift[:, None])
        projected = self.projected
        total_height = self.canvas.get_width_height()[1]
        boxes = np.zeros((len(self.figures), 4))
        t = self.times[f]
        self.canvas.restore_region(self.background)
        for panel in self.panels:
            if panel.grid is not None:  # slides by the shift modulo one cell
                grid, lines = panel.grid
                offset = np.mod(panel.shift[f], panel.grid_step)
                grid.set_segments(panel.camera.project(lines - offset)[0])
                panel.ax.draw_artist(grid)
            for path, segments in panel.paths:
                path.set_segments(panel.camera.project(segments - panel.shift[f])[0])
                panel.ax.draw_artist(path)
        for k, figure in enumerate(self.figures):
            uv, depth = projected[k][0][f], projected[k][1][f]
            ax = self.panel_of[k].ax
            bones = self.bone_artists[k]
            if len(figure.bones):
                order = np.argsort(depth[figure.bones].mean(axis=1))
                bones.set_segments(uv[figure.bones[order]])
                bones.set_color(self.bone_colors[k][order])
                ax.draw_artist(bones)
            self.joint_artists[k].set_data(uv[:, 0], uv[:, 1])
            ax.draw_artist(self.joint_artists[k])
            pixels = ax.transData.transform(uv)
            boxes[k] = (
                pixels[:, 0].min(),
                total_height - pixels[:, 1].max(),
                pixels[:, 0].max(),
                total_height - pixels[:, 1].min(),
            )
        if self.clock is not None:
            self.clock.set_text(f"{t:6.2f} s")
            self.clock.axes.draw_artist(self.clock)
        return np.asarray(self.canvas.buffer_rgba())[..., :3].copy(), boxes

    def close(self) -> None:
        """Release the figure."""
        self.figure.clear()


def _add_floor(
    panel: Panel, local: np.ndarray, paths: list[np.ndarray], ground: float, follow: bool
) -> Any:
    """Draw the floor and its grid under what the panel shows; return the floor polygon.

    Args:
        panel: The panel (its grid is kept when the camera follows).
        local: ``[N, 3]`` the characters' points in the panel's (shifted) frame.
        paths: ``[M, 3]`` root paths drawn on the floor.
        ground: Height of the floor.
        follow: The camera follows the characters (the grid slides every frame).
    """
    from matplotlib.collections import LineCollection
    from matplotlib.patches import Polygon

    ax, camera = panel.ax, panel.camera
    # Floor: the horizontal footprint of what is drawn, with a margin.
    reach = max(float(np.ptp(local[:, 2])), 1e-6)
    footprint = np.concatenate([local[:, :2], *(q[:, :2] for q in paths)])
    lo = footprint.min(axis=0) - 0.25 * reach
    hi = footprint.max(axis=0) + 0.25 * reach
    step = _nice_step(float((hi - lo).max()))
    lo, hi = np.floor(lo / step) * step, np.ceil(hi / step) * step
    corners = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
    floor_uv, _ = camera.project(np.column_stack([corners, np.full(4, ground)]))
    floor = Polygon(floor_uv, closed=True, facecolor=_FLOOR, edgecolor="none", zorder=0)
    ax.add_patch(floor)
    if follow:  # one extra cell each side: the grid slides under the figures
        lo, hi = lo - step, hi + step
    xs = np.arange(lo[0], hi[0] + step / 2, step)
    ys = np.arange(lo[1], hi[1] + step / 2, step)
    lines = [[(x, lo[1]), (x, hi[1])] for x in xs] + [[(lo[0], y), (hi[0], y)] for y in ys]
    grid_lines = np.concatenate([np.asarray(lines), np.full((len(lines), 2, 1), ground)], axis=-1)
    grid = LineCollection(
        list(camera.project(grid_lines)[0]),
        colors=_GRID,
        linewidths=0.8,
        zorder=1,
        animated=follow,
    )
    grid.set_clip_path(floor)
    grid.set_clip_box(ax.bbox)  # the floor may reach past the panel: never into the next
    ax.add_collection(grid)
    if follow:
        panel.grid, panel.grid_step = (grid, grid_lines), step
    return floor


def _rgba(color: str) -> tuple[float, float, float, float]:
    from matplotlib.colors import to_rgba

    return to_rgba(color)
