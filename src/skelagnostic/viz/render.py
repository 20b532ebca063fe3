"""Render stick figures to frames, animated GIF / MP4 and contact-sheet PNG.

Everything is drawn headless on a private matplotlib Agg canvas (no pyplot, no
display) through an orthographic camera, fixed or travelling with the
characters. Static parts (floor, labels, and with a fixed camera the grid and
trajectories) are drawn once; per frame only the moving artists are redrawn on
top of the saved background (blitting).

Files are written frame by frame (:func:`render_motion` streams frames to the GIF or
MP4 encoder, so memory stays flat in the clip length) and atomically
(:mod:`skelagnostic.io.outputs`: a failed write leaves the previous file as it was).
Sizes that cannot fit are refused before anything is drawn (:data:`MAX_PANEL_SIDE`,
:data:`MAX_FRAME_PIXELS`, :data:`MAX_FPS`, :data:`MAX_SHEET_PIXELS`).

The drawing itself is :mod:`skelagnostic.viz.scene`'s; the GIF and MP4 encoders are
:mod:`skelagnostic.viz.encoders`'.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from skelagnostic.io.outputs import output_path, write_output
from skelagnostic.viz.encoders import (
    check_gif_rate,
    find_ffmpeg,
    gif_palette,
    palette_frames,
    write_gif,
    write_mp4,
)
from skelagnostic.viz.scene import BODY_GROUP_COLORS, Scene
from skelagnostic.viz.stick import (
    FigureLike,
    RenderError,
    synchronise,
    to_stick_figures,
)

__all__ = [
    "BODY_GROUP_COLORS",
    "MAX_FPS",
    "MAX_FRAME_PIXELS",
    "MAX_PANEL_SIDE",
    "MAX_SHEET_PIXELS",
    "MIN_FPS",
    "Rendering",
    "contact_sheet",
    "render_contact_sheet",
    "render_frames",
    "render_motion",
    "write_animation",
    "write_contact_sheet",
]

_MODES = ("side", "overlay")

#: Largest width or height of one panel, in pixels.
MAX_PANEL_SIDE = 4096
#: Largest frame (all panels side by side), in pixels.
MAX_FRAME_PIXELS = 4096 * 4096
#: Highest output frame rate.
MAX_FPS = 240.0
#: Lowest output frame rate of an animation (``fps=``).
MIN_FPS = 1.0
#: Largest contact sheet, in pixels.
MAX_SHEET_PIXELS = 8192 * 8192
#: Renders of at least this many frames show a progress bar (when asked and on a terminal).
PROGRESS_FRAMES = 100


@dataclass
class Rendering:
    """Rendered frames plus where each character was drawn.

    Attributes:
        frames: ``[F, H, W, 3]`` uint8 RGB images.
        times: ``[F]`` time of each frame in seconds (the common clock).
        fps: Playback rate that keeps the frames in real time.
        boxes: ``[F, C, 4]`` pixel bounding box ``(x0, y0, x1, y1)`` of the joints
            of each character in each frame (origin top left, y down).
        panels: ``[C, 4]`` pixel rectangle ``(x0, y0, x1, y1)`` of the panel each
            character is drawn in (all the same in overlay mode).
        names: Label of each character.
        scales: ``[C]`` pixels per unit of length (the character's own units) of the
            panel each character is drawn in: equal for the panels of ``same_scale``.
    """

    frames: np.ndarray
    times: np.ndarray
    fps: float
    boxes: np.ndarray
    panels: np.ndarray
    names: list[str]
    scales: np.ndarray


def render_frames(
    motions: FigureLike | Sequence[FigureLike],
    *,
    mode: str = "side",
    labels: Sequence[str] | None = None,
    fps: float | None = None,
    max_frames: int | None = None,
    times: Sequence[float] | np.ndarray | None = None,
    size: tuple[int, int] = (320, 320),
    elev: float = 15.0,
    azim: float | None = None,
    trajectory: bool = False,
    follow: bool = False,
    time_label: bool = True,
    same_scale: bool | Sequence[int] = False,
) -> Rendering:
    """Render one or several motions to in-memory frames.

    Motions with different frame rates are drawn on a common clock (see
    :func:`~skelagnostic.viz.stick.synchronise`); each is interpolated
    linearly between its frames and holds its last pose once it ends.

    Args:
        motions: A :class:`~skelagnostic.Motion`, BVH path or
            :class:`~skelagnostic.viz.StickFigure`, or a sequence of them.
        mode: ``"side"`` draws each character in its own panel, left to right,
            each framed on its own (skeletons in different units are fine);
            ``"overlay"`` draws all of them in one panel with one camera (source
            vs result vs ground truth), told apart by line style and joint colour.
        labels: One label per motion (default: file stem or ``motion k``).
        fps: Output frame rate (default: highest input rate, at most 30).
        max_frames: Keep at most this many frames by subsampling the clock
            (playback stays real time).
        times: Explicit times in seconds to draw, instead of ``fps``/``max_frames``.
        size: ``(width, height)`` of one panel in pixels.
        elev: Camera elevation in degrees.
        azim: Camera azimuth in degrees; ``None`` picks a three-quarter view
            across the main direction of each panel's motion.
        trajectory: Draw the root's path on the floor.
        follow: Let the camera travel with the characters (the mean horizontal
            root position of each panel stays put and the floor grid slides
            under them), instead of a fixed camera framing the whole clip.
            Keeps characters large in long clips that travel far.
        time_label: Draw the clock in the top-right corner.
        same_scale: In ``"side"`` mode, draw panels at one scale (the same pixels
            per unit of length) instead of each framed on its own: ``True`` for
            every panel, or the indices of the motions whose panels share it (the
            others keep their own framing). The shared panels are all framed as
            large as the one needing the most room, so sizes compare across them
            (a dog beside a dog); their motions must be in the same units
            (:meth:`~skelagnostic.Motion.to_metres`). ``"overlay"`` mode has one
            camera, hence one scale, anyway.

    Returns:
        The frames with their times, playback rate, character boxes and panel scales.

    Raises:
        RenderError: On bad arguments (the message names the argument).

    Examples:
        >>> import numpy as np
        >>> from skelagnostic.viz import StickFigure, render_frames
        >>> t = np.linspace(0, 1, 31)[:, None]
        >>> pos = np.stack([np.hstack([t, 0 * t + 1, 0 * t]), np.hstack([t, 0 * t, 0 * t])], 1)
        >>> out = render_frames(StickFigure(pos, parents=[-1, 0], fps=30.0), size=(64, 48))
        >>> out.frames.shape, out.fps
        ((31, 48, 64, 3), 30.0)
    """
    scene = _prepare(
        motions,
        mode=mode,
        labels=labels,
        fps=fps,
        max_frames=max_frames,
        times=times,
        size=size,
        elev=elev,
        azim=azim,
        trajectory=trajectory,
        follow=follow,
        time_label=time_label,
        same_scale=same_scale,
    )
    try:
        frames, boxes = scene.draw_all()
        scales = scene.panel_scales()
    finally:
        scene.close()
    return Rendering(
        frames=frames,
        times=scene.times,
        fps=scene.rate,
        boxes=boxes,
        panels=scene.panel_rects(),
        names=[f.name for f in scene.figures],
        scales=scales,
    )


def _prepare(
    motions: FigureLike | Sequence[FigureLike],
    *,
    mode: str = "side",
    labels: Sequence[str] | None = None,
    fps: float | None = None,
    max_frames: int | None = None,
    times: Sequence[float] | np.ndarray | None = None,
    size: tuple[int, int] = (320, 320),
    elev: float = 15.0,
    azim: float | None = None,
    trajectory: bool = False,
    follow: bool = False,
    time_label: bool = True,
    same_scale: bool | Sequence[int] = False,
) -> Scene:
    """Check the arguments of :func:`render_frames` and build the scene (nothing drawn yet)."""
    figures = to_stick_figures(motions, labels)
    if mode not in _MODES:
        raise RenderError(f"mode must be one of {_MODES}, got {mode!r}")
    width, height = (int(v) for v in size)
    if width < 16 or height < 16:
        raise RenderError(f"size must be at least 16x16 pixels, got {size}")
    if max(width, height) > MAX_PANEL_SIDE:
        raise RenderError(
            f"size={width}x{height}: a panel is at most {MAX_PANEL_SIDE} pixels a side"
        )
    panels = len(figures) if mode == "side" else 1
    if width * panels * height > MAX_FRAME_PIXELS:
        raise RenderError(
            f"size={width}x{height}: {panels} panels side by side make a frame of "
            f"{width * panels}x{height} pixels, more than the limit of {MAX_FRAME_PIXELS:,} "
            "pixels; lower size= or use mode=overlay"
        )
    if fps is not None and math.isfinite(fps) and fps > MAX_FPS:
        raise RenderError(f"fps={fps:g}: at most {MAX_FPS:g} frames per second")
    if fps is not None and math.isfinite(fps) and fps < MIN_FPS:  # GIF delays end at 655 s
        raise RenderError(f"fps={fps:g}: at least {MIN_FPS:g} frame per second")
    if not math.isfinite(elev) or not -90.0 <= elev <= 90.0:
        raise RenderError(f"elev must be within [-90, 90] degrees, got {elev}")
    if azim is not None and not math.isfinite(azim):
        raise RenderError(f"azim must be a finite angle in degrees, got {azim}")
    if times is None:
        clock, rate = synchronise(figures, fps, max_frames)
    else:
        clock = np.asarray(times, dtype=np.float64).reshape(-1)
        if clock.size == 0 or not np.isfinite(clock).all():
            raise RenderError("times must be a non-empty sequence of finite seconds")
        rate = synchronise(figures, fps)[1]
    groups = [[k] for k in range(len(figures))] if mode == "side" else [list(range(len(figures)))]
    shared = _shared_panels(same_scale, len(figures)) if mode == "side" else []
    options = {
        "elev": elev,
        "azim": azim,
        "trajectory": trajectory,
        "follow": follow,
        "time_label": time_label,
        "same_scale": shared,
    }
    scene = Scene(figures, groups, clock, (width, height), options)
    scene.rate = rate
    return scene


def _shared_panels(same_scale: Any, count: int) -> list[int]:
    """The side-mode panels of ``same_scale`` (see :func:`render_frames`), checked."""
    if isinstance(same_scale, (bool, np.bool_)):
        return list(range(count)) if same_scale else []
    if isinstance(same_scale, (str, bytes)) or not isinstance(same_scale, Iterable):
        raise RenderError(
            f"same_scale: True, False or motion indices, got {type(same_scale).__name__}"
        )
    chosen = list(same_scale)
    if not all(isinstance(k, (int, np.integer)) and not isinstance(k, bool) for k in chosen):
        raise RenderError(f"same_scale: motion indices are integers, got {chosen!r}")
    if any(not 0 <= k < count for k in chosen):
        raise RenderError(f"same_scale: indices must lie in 0-{count - 1}, got {chosen!r}")
    return sorted({int(k) for k in chosen})


def render_motion(
    motions: FigureLike | Sequence[FigureLike],
    out: str | Path,
    *,
    sheet_frames: int = 8,
    columns: int = 4,
    progress: bool = False,
    key: str = "out",
    **options: Any,
) -> Path:
    """Render motions to a file: ``.gif`` / ``.mp4`` animation or ``.png`` contact sheet.

    Frames go to the encoder as they are drawn (memory does not grow with the
    clip length) and the file is written atomically: on any failure the
    previous file at ``out`` is left as it was.

    Args:
        motions: What to draw (see :func:`render_frames`).
        out: Output path; the suffix picks the format.
        sheet_frames: Number of frames on a ``.png`` contact sheet.
        columns: Columns of a ``.png`` contact sheet.
        progress: Show a progress bar on stderr for animations of at least
            :data:`PROGRESS_FRAMES` frames, when stderr is a terminal.
        key: The option naming ``out``, for error messages.
        **options: Passed to :func:`render_frames` (``mode``, ``labels``,
            ``fps``, ``max_frames``, ``size``, ``elev``, ``azim``, ``trajectory``,
            ``follow``, ``same_scale``, ...).

    Returns:
        The written path.

    Raises:
        RenderError: On bad arguments, an unknown suffix, or MP4 without ffmpeg.
        OutputError: The file cannot be written (full disk, ...); ``out`` is unchanged.

    Examples:
        >>> import tempfile, pathlib
        >>> from skelagnostic.viz import StickFigure, render_motion
        >>> fig = StickFigure(np.array([[[0.0, 0, 0], [0, 1, 0]]] * 5), parents=[-1, 0])
        >>> out = pathlib.Path(tempfile.mkdtemp()) / "still.gif"
        >>> render_motion(fig, out, size=(48, 48)).exists()
        True
    """
    out = Path(out)
    suffix = out.suffix.lower()
    if suffix == ".png":
        return render_contact_sheet(
            motions, out, frames=sheet_frames, columns=columns, key=key, **options
        )
    if suffix not in (".gif", ".mp4"):
        raise RenderError(f"{key}: unsupported format {out.suffix!r}; use .gif, .mp4 or .png")
    if suffix == ".mp4":
        find_ffmpeg()  # fail before rendering when ffmpeg is missing
    scene = _prepare(motions, **options)
    try:
        if suffix == ".gif":
            check_gif_rate(scene.rate)
            palette = gif_palette(scene.draw_frame(i)[0] for i in palette_frames(len(scene.times)))
        frames = _with_progress(
            (frame for frame, _ in scene.iter_frames()), len(scene.times), progress, out.name
        )
        if suffix == ".gif":
            write_output(out, lambda fh: write_gif(frames, scene.rate, fh, palette), key)
        else:
            width, height = scene.canvas.get_width_height()
            with output_path(out, key) as tmp:
                write_mp4(frames, scene.rate, (height, width), tmp, out, key)
    finally:
        scene.close()
    return out


def render_contact_sheet(
    motions: FigureLike | Sequence[FigureLike],
    out: str | Path,
    *,
    frames: int = 8,
    columns: int = 4,
    key: str = "out",
    **options: Any,
) -> Path:
    """Render a PNG contact sheet: ``frames`` evenly spaced instants in a grid.

    Only the frames on the sheet are drawn, each straight into its tile, so this
    is cheap for long clips. The file is written atomically.

    Args:
        motions: What to draw (see :func:`render_frames`).
        out: Output ``.png`` path.
        frames: Number of instants, first and last included.
        columns: Number of columns of the grid.
        key: The option naming ``out``, for error messages.
        **options: Passed to :func:`render_frames` (``times`` is computed here).

    Returns:
        The written path.

    Raises:
        RenderError: On bad arguments, or a sheet larger than :data:`MAX_SHEET_PIXELS`.
        OutputError: The file cannot be written; ``out`` is unchanged.
    """
    if frames < 1 or columns < 1:
        raise RenderError(f"frames and columns must be at least 1, got {frames} and {columns}")
    if "times" in options:
        raise RenderError("times: a contact sheet picks its own times; pass frames= instead")
    out = Path(out)
    if out.suffix.lower() != ".png":
        raise RenderError(f"{key}: a contact sheet is a .png file, got {out.name!r}")
    figures = to_stick_figures(motions, options.pop("labels", None))
    width, height = (int(v) for v in options.get("size", (320, 320)))
    panels = len(figures) if options.get("mode", "side") == "side" else 1
    columns = min(columns, frames)
    rows = math.ceil(frames / columns)
    pixels = (columns * (width * panels + 4)) * (rows * (height + 4))
    if pixels > MAX_SHEET_PIXELS:
        raise RenderError(
            f"frames={frames}: a contact sheet of {columns}x{rows} frames of "
            f"{width * panels}x{height} pixels is more than the limit of "
            f"{MAX_SHEET_PIXELS:,} pixels; lower frames= or size="
        )
    duration = max(f.duration for f in figures)
    times = np.linspace(0.0, duration, frames) if frames > 1 else np.zeros(1)
    scene = _prepare(figures, times=times, **options)
    try:
        tiles = (frame for frame, _ in scene.iter_frames())
        sheet = _tile(tiles, len(times), np.arange(len(times)), columns, 4)
    finally:
        scene.close()
    return _save_png(sheet, out, key)


def write_animation(rendering: Rendering, out: str | Path) -> Path:
    """Write rendered frames as an animated ``.gif`` (Pillow) or ``.mp4`` (ffmpeg).

    GIF timing is stored in hundredths of a second; the per-frame delays are
    rounded so that the total stays in real time. GIF viewers cannot play more
    than 50 frames per second, so faster playback rates are refused.

    Args:
        rendering: Output of :func:`render_frames`.
        out: Output path ending in ``.gif`` or ``.mp4``.

    Returns:
        The written path.

    Raises:
        RenderError: If the suffix is unknown, a GIF would play faster than
            50 fps, or ffmpeg is missing or fails for MP4.
    """
    out = Path(out)
    suffix = out.suffix.lower()
    if suffix == ".gif":
        check_gif_rate(rendering.fps)
        frames = rendering.frames
        palette = gif_palette(frames[i] for i in palette_frames(len(frames)))
        write_output(out, lambda fh: write_gif(iter(frames), rendering.fps, fh, palette), "out")
    elif suffix == ".mp4":
        _, h, w, _ = rendering.frames.shape
        with output_path(out, "out") as tmp:
            write_mp4(iter(rendering.frames), rendering.fps, (h, w), tmp, out, "out")
    else:
        raise RenderError(f"out: unsupported animation format {out.suffix!r}; use .gif or .mp4")
    return out


def write_contact_sheet(
    rendering: Rendering, out: str | Path, *, frames: int = 8, columns: int = 4
) -> Path:
    """Write a PNG grid of evenly spaced frames of a rendering.

    Args:
        rendering: Output of :func:`render_frames`.
        out: Output ``.png`` path.
        frames: Number of frames to show (at most the number rendered).
        columns: Number of columns of the grid.

    Returns:
        The written path.

    Raises:
        RenderError: If ``frames`` or ``columns`` is not positive or ``out`` is not a PNG.
    """
    out = Path(out)
    if out.suffix.lower() != ".png":
        raise RenderError(f"out: a contact sheet is a .png file, got {out.name!r}")
    return _save_png(contact_sheet(rendering, frames=frames, columns=columns), out, "out")


def _save_png(image: np.ndarray, out: Path, key: str) -> Path:
    """Write an RGB image as PNG, atomically."""
    from PIL import Image

    picture = Image.fromarray(image)
    write_output(out, lambda fh: picture.save(fh, format="PNG"), key)
    return out


def contact_sheet(
    rendering: Rendering, *, frames: int = 8, columns: int = 4, gap: int = 4
) -> np.ndarray:
    """Tile evenly spaced frames of a rendering into one image, row by row.

    Args:
        rendering: Output of :func:`render_frames`.
        frames: Number of frames to show (at most the number rendered).
        columns: Number of columns of the grid.
        gap: Grey gap between tiles in pixels.

    Returns:
        ``[H', W', 3]`` uint8 image.

    Raises:
        RenderError: If ``frames`` or ``columns`` is not positive.
    """
    if frames < 1 or columns < 1:
        raise RenderError(f"frames and columns must be at least 1, got {frames} and {columns}")
    images = rendering.frames
    count = images.shape[0]
    index = np.unique(np.round(np.linspace(0, count - 1, min(frames, count))).astype(int))
    return _tile(iter(images[index]), len(index), np.arange(len(index)), columns, gap)


def _tile(
    images: Iterable[np.ndarray], count: int, slots: np.ndarray, columns: int, gap: int
) -> np.ndarray:
    """Fill a grid of ``count`` tiles row by row from images arriving one at a time."""
    columns = min(columns, count)
    rows = math.ceil(count / columns)
    sheet: np.ndarray | None = None
    for k, image in zip(slots, images, strict=False):
        h, w, _ = image.shape
        if sheet is None:
            shape = (rows * h + (rows - 1) * gap, columns * w + (columns - 1) * gap, 3)
            sheet = np.full(shape, 176, np.uint8)
        r, c = divmod(int(k), columns)
        sheet[r * (h + gap) : r * (h + gap) + h, c * (w + gap) : c * (w + gap) + w] = image
    assert sheet is not None
    return sheet


def _with_progress(
    frames: Iterator[np.ndarray], count: int, progress: bool, name: str
) -> Iterator[np.ndarray]:
    """``frames``, with a Rich progress bar on stderr for long renders on a terminal."""
    if not progress or count < PROGRESS_FRAMES:
        yield from frames
        return
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeRemainingColumn

    console = Console(stderr=True)
    if not console.is_terminal:
        yield from frames
        return
    columns = (
        "{task.description}",
        BarColumn(),
        MofNCompleteColumn(),
        TimeRemainingColumn(),
    )
    with Progress(*columns, console=console, transient=True) as bar:
        task = bar.add_task(f"render {name}", total=count)
        for frame in frames:
            yield frame
            bar.advance(task)
