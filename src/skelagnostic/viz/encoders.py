"""Animation encoders of :mod:`skelagnostic.viz.render`: a streaming GIF writer and ffmpeg MP4.

Both take frames one at a time, so memory stays flat in the clip length.
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from skelagnostic.viz.stick import RenderError

__all__ = [
    "GIF_MAX_TICKS",
    "check_gif_rate",
    "find_ffmpeg",
    "gif_palette",
    "palette_frames",
    "write_gif",
    "write_mp4",
]

#: Longest delay a GIF frame can hold, in 1/100 s (a 16-bit field).
GIF_MAX_TICKS = 65535


def palette_frames(count: int) -> np.ndarray:
    """Indices of up to eight evenly spaced frames (the GIF palette is fitted on them)."""
    return np.unique(np.linspace(0, count - 1, min(8, count)).astype(int))


def check_gif_rate(fps: float) -> None:
    """Refuse a GIF frame rate above 50 (its delays are whole 1/100 s)."""
    if fps > 50.0:
        raise RenderError(
            f"fps: a GIF plays at most 50 frames per second, got {fps:g}; lower fps or write .mp4"
        )


def gif_palette(sample: Iterable[np.ndarray]) -> Any:
    """One 256-colour palette image fitted on a few frames, shared by every frame."""
    from PIL import Image

    return Image.fromarray(np.concatenate(list(sample), axis=0)).quantize(
        colors=256, method=Image.Quantize.MEDIANCUT
    )


def write_gif(frames: Iterator[np.ndarray], fps: float, fh: Any, palette: Any) -> None:
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
        delay, tick = min(following - tick, GIF_MAX_TICKS) * 10, following
        if previous is None:
            header, _ = GifImagePlugin.getheader(image, None, {"loop": 0, "optimize": False})
            for block in header:
                fh.write(block)
            pending = (image, (0, 0), delay)
        else:
            box = ImageChops.difference(previous, image).getbbox()
            if box is None and pending is not None:  # unchanged: the last frame stays longer
                pending = (pending[0], pending[1], min(pending[2] + delay, GIF_MAX_TICKS * 10))
                continue
            flush()
            box = box or (0, 0, 1, 1)
            pending = (image.crop(box), box[:2], delay)
        previous = image
    flush()
    fh.write(b";")


def find_ffmpeg() -> str:
    """The ffmpeg executable matplotlib is configured with, or a clear :class:`RenderError`."""
    import matplotlib

    exe = shutil.which(matplotlib.rcParams["animation.ffmpeg_path"])
    if exe is None:
        raise RenderError(
            "out: writing .mp4 needs ffmpeg, which was not found "
            f"(matplotlib rcParams['animation.ffmpeg_path'] = "
            f"{matplotlib.rcParams['animation.ffmpeg_path']!r}); install ffmpeg or write .gif"
        )
    return exe


def write_mp4(
    frames: Iterator[np.ndarray],
    fps: float,
    shape: tuple[int, int],
    path: Path,
    out: Path,
    key: str,
) -> None:
    """Pipe frames one at a time to ffmpeg, which writes an MP4 at ``path``."""
    exe = find_ffmpeg()
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
