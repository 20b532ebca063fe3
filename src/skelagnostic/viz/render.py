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
"""

from __future__ import annotations

import math
import shutil
import subprocess
import tempfile
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from skelagnostic.io.outputs import output_path, write_output
from skelagnostic.viz.camera import Camera, auto_azimuth
from skelagnostic.viz.stick import (
    FigureLike,
    RenderError,
    StickFigure,
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
_MODES = ("side", "overlay")
_MARGIN = 0.08

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
#: Longest delay a GIF frame can hold, in 1/100 s (a 16-bit field).
_GIF_MAX_TICKS = 65535
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
) -> _Scene:
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
    scene = _Scene(figures, groups, clock, (width, height), options)
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
        _ffmpeg()  # fail before rendering when ffmpeg is missing
    scene = _prepare(motions, **options)
    try:
        if suffix == ".gif":
            _check_gif_rate(scene.rate)
            palette = _gif_palette(scene.draw_frame(i)[0] for i in _sample(len(scene.times)))
        frames = _with_progress(
            (frame for frame, _ in scene.iter_frames()), len(scene.times), progress, out.name
        )
        if suffix == ".gif":
            write_output(out, lambda fh: _write_gif(frames, scene.rate, fh, palette), key)
        else:
            width, height = scene.canvas.get_width_height()
            with output_path(out, key) as tmp:
                _write_mp4(frames, scene.rate, (height, width), tmp, out, key)
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
        _check_gif_rate(rendering.fps)
        frames = rendering.frames
        palette = _gif_palette(frames[i] for i in _sample(len(frames)))
        write_output(out, lambda fh: _write_gif(iter(frames), rendering.fps, fh, palette), "out")
    elif suffix == ".mp4":
        _, h, w, _ = rendering.frames.shape
        with output_path(out, "out") as tmp:
            _write_mp4(iter(rendering.frames), rendering.fps, (h, w), tmp, out, "out")
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


def _sample(count: int) -> np.ndarray:
    """Indices of up to eight evenly spaced frames (the GIF palette is fitted on them)."""
    return np.unique(np.linspace(0, count - 1, min(8, count)).astype(int))


def _check_gif_rate(fps: float) -> None:
    if fps > 50.0:
        raise RenderError(
            f"fps: a GIF plays at most 50 frames per second, got {fps:g}; lower fps or write .mp4"
        )


def _gif_palette(sample: Iterable[np.ndarray]) -> Any:
    """One 256-colour palette image fitted on a few frames, shared by every frame."""
    from PIL import Image

    return Image.fromarray(np.concatenate(list(sample), axis=0)).quantize(
        colors=256, method=Image.Quantize.MEDIANCUT
    )


def _write_gif(frames: Iterator[np.ndarray], fps: float, fh: Any, palette: Any) -> None:
    """Encode frames one at a time into an animated GIF (looping, real-time delays).

    Pillow's ``save(save_all=True)`` holds every frame until the end; this writes
    each frame as it comes with Pillow's GIF block writers (``getheader`` /
    ``getdata``): the first frame whole, the next ones cropped to what changed
    (as Pillow does), and an unchanged frame extends the previous one's delay.
    Only the previous frame is kept in memory.
    """
    from PIL import GifImagePlugin, Image, ImageChops

    previous: Any = None
    pending: tuple[Any, tuple[int, int], int] | None = None  # (image, offset, delay ms)
    tick = 0  # delays in 1/100 s, rounded on the cumulative clock: playback stays real time

    def flush() -> None:
        if pending is not None:
            image, offset, delay = pending
            for block in GifImagePlugin.getdata(image, offset, duration=delay):
                fh.write(block)

    for f, frame in enumerate(frames):
        image = Image.fromarray(frame).quantize(palette=palette, dither=Image.Dither.NONE)
        following = round((f + 1) * 100.0 / fps)
        delay, tick = min(following - tick, _GIF_MAX_TICKS) * 10, following
        if previous is None:
            header, _ = GifImagePlugin.getheader(image, None, {"loop": 0, "optimize": False})
            for block in header:
                fh.write(block)
            pending = (image, (0, 0), delay)
        else:
            box = ImageChops.difference(previous, image).getbbox()
            if box is None and pending is not None:  # unchanged: the last frame stays longer
                pending = (pending[0], pending[1], min(pending[2] + delay, _GIF_MAX_TICKS * 10))
                continue
            flush()
            box = box or (0, 0, 1, 1)
            pending = (image.crop(box), box[:2], delay)
        previous = image
    flush()
    fh.write(b";")


def _ffmpeg() -> str:
    import matplotlib

    exe = shutil.which(matplotlib.rcParams["animation.ffmpeg_path"])
    if exe is None:
        raise RenderError(
            "out: writing .mp4 needs ffmpeg, which was not found "
            f"(matplotlib rcParams['animation.ffmpeg_path'] = "
            f"{matplotlib.rcParams['animation.ffmpeg_path']!r}); install ffmpeg or write .gif"
        )
    return exe


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


def _write_mp4(
    frames: Iterator[np.ndarray],
    fps: float,
    shape: tuple[int, int],
    path: Path,
    out: Path,
    key: str,
) -> None:
    """Pipe frames one at a time to ffmpeg, which writes an MP4 at ``path``."""
    exe = _ffmpeg()
    h, w = shape
    # yuv420p (playable everywhere) needs even dimensions: pad by one white row/column.
    pad_h, pad_w = h % 2, w % 2
    command = [
        exe,
        "-y",
        "-loglevel",
        "error",
        "-f",
        "rawvideo",
        "-pix_fmt",
        "rgb24",
        "-s",
        f"{w + pad_w}x{h + pad_h}",
        "-r",
        f"{fps:g}",
        "-i",
        "-",
        "-an",
        "-pix_fmt",
        "yuv420p",
        "-f",
        "mp4",
        str(path),
    ]
    with tempfile.TemporaryFile() as log:
        process = subprocess.Popen(
            command, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=log
        )
        assert process.stdin is not None
        try:
            for frame in frames:
                if pad_h or pad_w:
                    frame = np.pad(frame, ((0, pad_h), (0, pad_w), (0, 0)), constant_values=255)
                process.stdin.write(np.ascontiguousarray(frame).tobytes())
        except BrokenPipeError:
            pass  # ffmpeg stopped: its exit code and message tell why
        except BaseException:
            process.kill()
            process.wait()
            raise
        finally:
            try:
                process.stdin.close()
            except BrokenPipeError:
                pass
        code = process.wait()
        if code != 0:
            log.seek(0)
            message = " ".join(log.read().decode(errors="replace").split())
            raise RenderError(f"{key}: ffmpeg failed writing {out} (exit {code}): {message}")


def _nice_step(extent: float) -> float:
    """A 1/2/5 x 10^k grid spacing giving about eight cells over ``extent``."""
    raw = max(extent, 1e-9) / 8.0
    base = 10.0 ** math.floor(math.log10(raw))
    return base * min((m for m in (1.0, 2.0, 5.0, 10.0) if m * base >= raw), default=10.0)


class _Panel:
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


class _Scene:
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
        #: Playback rate of the frames (set by :func:`_prepare`).
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
        self.panels: list[_Panel] = []
        self.panel_of: dict[int, _Panel] = {}
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

    def _build_panel(self, ax: Any, members: list[int], options: dict[str, Any]) -> _Panel:
        from matplotlib.collections import LineCollection
        from matplotlib.lines import Line2D
        from matplotlib.patches import Polygon

        world = [self.world[k] for k in members]
        azim = options["azim"]
        camera = Camera(auto_azimuth(world) if azim is None else float(azim), options["elev"])
        ground = min(float(p[..., 2].min()) for p in world)
        shift = np.zeros((len(self.times), 3))
        if options["follow"]:
            shift[:, :2] = np.mean([p[:, 0, :2] for p in world], axis=0)
        panel = _Panel(ax, members, camera, shift)
        local = np.concatenate([(p - shift[:, None]).reshape(-1, 3) for p in world])
        paths = {k: self._root_path(k, ground) for k in members} if options["trajectory"] else {}
        framed = [local] if options["follow"] else [local, *paths.values()]
        panel.framed = camera.project(np.concatenate(framed))[0]

        # Floor: the horizontal footprint of what is drawn, with a margin.
        reach = max(float(np.ptp(local[:, 2])), 1e-6)
        footprint = np.concatenate([local[:, :2], *(q[:, :2] for q in framed[1:])])
        lo = footprint.min(axis=0) - 0.25 * reach
        hi = footprint.max(axis=0) + 0.25 * reach
        step = _nice_step(float((hi - lo).max()))
        lo, hi = np.floor(lo / step) * step, np.ceil(hi / step) * step
        corners = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
        floor_uv, _ = camera.project(np.column_stack([corners, np.full(4, ground)]))
        floor = Polygon(floor_uv, closed=True, facecolor=_FLOOR, edgecolor="none", zorder=0)
        ax.add_patch(floor)
        if options["follow"]:  # one extra cell each side: the grid slides under the figures
            lo, hi = lo - step, hi + step
        xs = np.arange(lo[0], hi[0] + step / 2, step)
        ys = np.arange(lo[1], hi[1] + step / 2, step)
        lines = [[(x, lo[1]), (x, hi[1])] for x in xs] + [[(lo[0], y), (hi[0], y)] for y in ys]
        grid_lines = np.concatenate(
            [np.asarray(lines), np.full((len(lines), 2, 1), ground)], axis=-1
        )
        grid = LineCollection(
            list(camera.project(grid_lines)[0]),
            colors=_GRID,
            linewidths=0.8,
            zorder=1,
            animated=options["follow"],
        )
        grid.set_clip_path(floor)
        grid.set_clip_box(ax.bbox)  # the floor may reach past the panel: never into the next
        ax.add_collection(grid)
        if options["follow"]:
            panel.grid, panel.grid_step = (grid, grid_lines), step

        overlay = len(members) > 1
        handles = []
        for rank, k in enumerate(members):
            figure = self.figures[k]
            joint_color = _OVERLAY_JOINTS[rank % len(_OVERLAY_JOINTS)] if overlay else "#263238"
            style: Any = _OVERLAY_STYLES[rank % len(_OVERLAY_STYLES)] if overlay else "solid"
            if k in paths:
                segments = np.stack([paths[k][:-1], paths[k][1:]], axis=1)
                path = LineCollection(
                    list(camera.project(segments)[0]),
                    colors=joint_color,
                    alpha=0.6,
                    linewidths=1.5 * self.scale,
                    zorder=2,
                    animated=options["follow"],
                )
                path.set_clip_path(floor)
                path.set_clip_box(ax.bbox)
                ax.add_collection(path)
                if options["follow"]:
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
            handles.append(
                Line2D(
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
            )
        if overlay:
            ax.legend(handles=handles, loc="upper left", fontsize=8 * self.scale, frameon=False)
        elif self.figures[members[0]].name:
            name = self.figures[members[0]].name
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
        return panel

    def _root_path(self, k: int, ground: float) -> np.ndarray:
        """Root of figure ``k`` on the floor, at all its frames within the drawn time span."""
        figure = self.figures[k]
        first = math.floor(float(self.times.min()) * figure.fps)
        last = math.ceil(float(self.times.max()) * figure.fps)
        root = figure.z_up()[max(first, 0) : max(last, 0) + 1, 0].copy()
        root[:, 2] = ground
        return root if len(root) > 1 else np.concatenate([root, root])

    def _framing(self, panel: _Panel) -> tuple[np.ndarray, np.ndarray]:
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


def _rgba(color: str) -> tuple[float, float, float, float]:
    from matplotlib.colors import to_rgba

    return to_rgba(color)
