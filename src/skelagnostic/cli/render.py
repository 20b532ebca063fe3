"""``skelagnostic render``: draw BVH clips to a GIF/MP4, a contact sheet or a 3D viewer page.

Usage::

    skelagnostic render a.bvh [b.bvh ...] out=anim.gif [mode=side|overlay] [fps=30]
        [sheet=frames.png] [html=view.html] [frames=8] [columns=4] [max_frames=N]
        [start=S] [end=S] [size=WxH] [elev=DEG] [azim=DEG] [trajectory=true]
        [follow=true] [labels=a,b]

``out=view.html`` (or ``html=view.html`` next to another output) writes the
interactive viewer of :func:`skelagnostic.viz.to_html`. Other verbs that
produce motion reuse :func:`render_from_options` so that ``render=out.gif`` /
``sheet=out.png`` / ``html=view.html`` work the same way everywhere.
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from skelagnostic.core.paths import expand_path
from skelagnostic.errors import SkelagnosticError, error_line, printable

__all__ = [
    "RENDER_OPTIONS",
    "apply_threads",
    "check_render_outputs",
    "check_threads",
    "main",
    "max_threads",
    "parse_arguments",
    "render_from_options",
    "split_end_of_options",
    "wants_help",
]

#: Rendering options understood by :func:`render_from_options`, with their help.
RENDER_OPTIONS: dict[str, str] = {
    "mode": "side (one panel per clip) or overlay (one panel, one camera); default side",
    "fps": "output frame rate; default: highest input rate, at most 30",
    "sheet": "also write a PNG contact sheet to this path",
    "html": "also write an interactive 3D viewer (one self-contained .html page) to this path",
    "frames": "frames on a contact sheet; default 8",
    "columns": "columns of a contact sheet; default 4",
    "max_frames": "keep at most N animation frames (playback stays real time)",
    "start": "start time in seconds (each clip is cut); default 0",
    "end": "end time in seconds (each clip is cut); default: the end",
    "size": "panel size in pixels, WxH or N; default 320x320",
    "elev": "camera elevation in degrees; default 15",
    "azim": "camera azimuth in degrees; default: three-quarter view across the motion",
    "trajectory": "true to draw the root path on the floor",
    "follow": "true for a camera that travels with the characters (long clips)",
    "labels": "comma-separated labels, one per clip; default: file names",
}

_USAGE = """usage: skelagnostic render A.bvh [B.glb ...] [out=render.gif] [key=value ...]

Draw BVH or glTF (.glb, .gltf) clips as stick figures (bones coloured by body group) to an animated
GIF (.gif), an MP4 (.mp4, needs ffmpeg), a PNG contact sheet (.png) or an
interactive 3D viewer page (.html: orbit, scrub, speed, overlay; no network).

options:
  out         output path (.gif, .mp4, .png or .html); default render.gif
{options}"""


def _usage() -> str:
    lines = [
        f"  {key:<11} {text}" for key, text in {**RENDER_OPTIONS, "threads": THREADS_HELP}.items()
    ]
    return _USAGE.format(options="\n".join(lines)) + "\n\n" + END_OF_OPTIONS_HELP


#: Options of the file verbs that name a path (``~`` and ``$VARS`` are expanded).
PATH_OPTIONS = frozenset({"out", "ckpt", "render", "sheet", "html", "ckpt_path"})


#: The word that ends the options of the file verbs: every word after it is an input path.
END_OF_OPTIONS = "--"
#: The help line on :data:`END_OF_OPTIONS`, at the end of the file verbs' ``--help``.
END_OF_OPTIONS_HELP = (
    "A -- ends the options: the words after it are input files, taken as they are\n"
    "(e.g. a file named out=x.bvh or --help)."
)
#: Words that ask a verb for its help (before :data:`END_OF_OPTIONS`).
HELP_WORDS = frozenset({"-h", "--help", "help"})


def split_end_of_options(argv: Sequence[str]) -> tuple[list[str], list[str]]:
    """The words before the first ``--`` and those after it (``--`` itself dropped).

    Examples:
        >>> split_end_of_options(["out=a.gif", "--", "out=x.bvh", "--"])
        (['out=a.gif'], ['out=x.bvh', '--'])
    """
    words = list(argv)
    if END_OF_OPTIONS not in words:
        return words, []
    end = words.index(END_OF_OPTIONS)
    return words[:end], words[end + 1 :]


def wants_help(argv: Sequence[str]) -> bool:
    """Whether a word before ``--`` asks for help (``-h``, ``--help``, ``help``).

    After ``--`` such a word is a file name: ``render -- help`` draws the file ``help``.
    """
    return any(word in HELP_WORDS for word in split_end_of_options(argv)[0])


def parse_arguments(argv: Sequence[str]) -> tuple[list[str], dict[str, str]]:
    """Split command-line words into positional arguments and ``key=value`` options.

    Positional arguments (input files) and the values of :data:`PATH_OPTIONS`
    get ``~`` and ``$VARS`` expanded (:func:`~skelagnostic.core.paths.expand_path`):
    a shell does not expand ``~`` after ``out=``. A ``--`` word ends the
    options: every word after it is a positional argument taken as it is (no
    ``key=value``, no expansion), so a file named ``out=x.bvh`` or ``--help``
    can be given.

    Args:
        argv: The words after the verb.

    Returns:
        ``(positional, options)``: the positional arguments before ``--``, then
        those after it.

    Raises:
        SkelagnosticError: If an option is given twice.

    Examples:
        >>> parse_arguments(["a.bvh", "out=x.gif", "mode=overlay"])
        (['a.bvh'], {'out': 'x.gif', 'mode': 'overlay'})
        >>> parse_arguments(["out=x.gif", "--", "out=y.bvh"])
        (['out=y.bvh'], {'out': 'x.gif'})
    """
    words, literal = split_end_of_options(argv)
    positional, options = [], {}
    for word in words:
        key, sep, value = word.partition("=")
        if sep and key.isidentifier():
            if key in options:
                raise SkelagnosticError(f"option {key}= is given twice")
            options[key] = str(expand_path(value)) if key in PATH_OPTIONS and value else value
        else:
            positional.append(str(expand_path(word)))
    return positional + literal, options


#: Suffixes of the main render output and of ``sheet=`` / ``html=``.
_OUT_SUFFIXES = (".gif", ".mp4", ".png", ".html", ".htm")


def check_render_outputs(options: Mapping[str, str], out_key: str = "out") -> None:
    """Check every output the rendering options name, before anything is drawn or written.

    Verbs that write other files first (``retarget out=...``) call this before
    writing any, so an unusable ``render=`` or ``html=`` path never leaves half
    of the outputs behind.

    Args:
        options: The verb's options.
        out_key: Option holding the main render output.

    Raises:
        SkelagnosticError: A wrong suffix, or a path that cannot be written (a
            directory, under a regular file, a read-only directory): one line
            naming the option and the cause.
    """
    from skelagnostic.io.outputs import check_output_file

    wanted = {out_key: _OUT_SUFFIXES, "sheet": (".png",), "html": (".html", ".htm")}
    for key, suffixes in wanted.items():
        if key not in options:
            continue
        path = Path(options[key])
        if path.suffix.lower() not in suffixes:
            raise SkelagnosticError(
                f"option {key}={options[key]!r}: unsupported format {path.suffix!r}; "
                f"use {', '.join(suffixes)}"
            )
        check_output_file(path, key)


def render_from_options(
    motions: Sequence[Any],
    options: Mapping[str, str],
    *,
    out_key: str = "out",
    keyframes: Mapping[int, Sequence[int]] | None = None,
    transitions: Mapping[int, Sequence[int]] | None = None,
) -> list[Path]:
    """Render motions as the ``key=value`` options ask; the shared back end of all verbs.

    Writes the animation, sheet or viewer page (``.html``) named by
    ``options[out_key]`` (if present), the contact sheet named by
    ``options["sheet"]`` and the viewer page named by ``options["html"]`` (if
    present).

    Args:
        motions: Motions (or BVH paths / stick figures) to draw.
        options: Options as strings; only :data:`RENDER_OPTIONS` and ``out_key``
            are read, others are ignored so that verbs can pass all their options.
        out_key: Option holding the main output path (``"render"`` in verbs
            whose ``out=`` is a BVH file).
        keyframes: Clip index -> keyframe indices, marked on the viewer's timeline.
        transitions: Clip index -> frames where a matched window starts, marked
            on the viewer's timeline.

    Returns:
        The written paths (empty when neither output was asked for).

    Raises:
        SkelagnosticError: On a malformed option value; the message names the option.
    """
    from skelagnostic.viz import render_contact_sheet, render_motion

    check_render_outputs(options, out_key)
    common: dict[str, Any] = {}
    if "mode" in options:
        common["mode"] = options["mode"]
    if "fps" in options:
        common["fps"] = _number(options, "fps", float)
    if "elev" in options:
        common["elev"] = _number(options, "elev", float)
    if "azim" in options:
        common["azim"] = _number(options, "azim", float)
    if "size" in options:
        common["size"] = _size(options["size"])
    if "max_frames" in options:
        common["max_frames"] = _number(options, "max_frames", int)
    for flag in ("trajectory", "follow"):
        if flag in options:
            common[flag] = _flag(options, flag)
    if "labels" in options:
        common["labels"] = [label.strip() for label in options["labels"].split(",")]
    sheet = {
        "frames": _number(options, "frames", int) if "frames" in options else 8,
        "columns": _number(options, "columns", int) if "columns" in options else 4,
    }
    firsts = _first_frames(motions, options)
    motions = _cut(motions, options)
    marks = {
        name: _shift_marks(given, firsts, motions)
        for name, given in (("keyframes", keyframes), ("transitions", transitions))
    }
    written = []
    html_paths = [
        options[key]
        for key in (out_key, "html")
        if key in options and Path(options[key]).suffix.lower() in (".html", ".htm")
    ]
    if "html" in options and options["html"] not in html_paths:
        raise SkelagnosticError(f"option html={options['html']!r}: must be an .html path")
    for key in (out_key, "html"):
        if key in options and options[key] in html_paths and Path(options[key]) not in written:
            written.append(_write_html(motions, options[key], common, marks, key))
    if out_key in options and options[out_key] not in html_paths:
        written.append(
            render_motion(
                motions,
                options[out_key],
                sheet_frames=sheet["frames"],
                columns=sheet["columns"],
                progress=True,
                key=out_key,
                **common,
            )
        )
    if "sheet" in options:
        written.append(
            render_contact_sheet(motions, options["sheet"], **sheet, key="sheet", **common)
        )
    return written


#: Help of the ``threads=`` option every file verb takes.
THREADS_HELP = (
    "torch intra-op threads (a positive integer, at most 4 per CPU core); "
    "default: torch's (one per core)"
)


def max_threads() -> int:
    """The most intra-op threads ``threads=`` may ask for: 4 per CPU core of this machine."""
    return 4 * (os.cpu_count() or 1)


def check_threads(value: object, key: str = "threads") -> int:
    """Check a ``threads=`` value against this machine, before torch is given it.

    Far more threads than cores only slows torch down, and a huge count makes
    its thread pool crash the process (``threads=99999`` segfaults), so values
    above :func:`max_threads` are refused.

    Args:
        value: The value (an ``int``, or the text of a command-line option).
        key: The option or config key, for the message.

    Returns:
        The number of threads.

    Raises:
        SkelagnosticError: Not a positive integer, or above :func:`max_threads`.
    """
    text = str(value)
    if isinstance(value, bool) or not text.isdigit() or int(text) < 1:
        raise SkelagnosticError(f"{key}={value!r}: must be a positive integer")
    if len(text) > 9 or int(text) > max_threads():
        raise SkelagnosticError(
            f"{key}={text}: at most {max_threads()} (4 per CPU core; this machine has "
            f"{os.cpu_count() or 1})"
        )
    return int(text)


def apply_threads(options: dict[str, str]) -> None:
    """Take ``threads=N`` out of ``options`` and set torch's intra-op threads to it.

    The Hydra verbs take ``threads=`` as a config key; the file verbs take it
    here, so ``threads=1`` works the same on every verb.

    Raises:
        SkelagnosticError: Not a positive integer, or more than :func:`max_threads`.
    """
    value = options.pop("threads", None)
    if value is None:
        return
    count = check_threads(value, "option threads")
    import torch

    torch.set_num_threads(count)


def main(argv: list[str]) -> int:
    """Run ``skelagnostic render``.

    Args:
        argv: Words after the verb: BVH paths and ``key=value`` options.

    Returns:
        0 on success, 2 on bad arguments or unreadable input.
    """
    if not argv or wants_help(argv):
        print(_usage())
        return 0 if argv else 2
    try:
        paths, options = parse_arguments(argv)
        apply_threads(options)
        unknown = sorted(set(options) - set(RENDER_OPTIONS) - {"out"})
        if unknown:
            raise SkelagnosticError(
                f"unknown option(s) {', '.join(k + '=' for k in unknown)}; "
                "see 'skelagnostic render --help'"
            )
        if not paths:
            raise SkelagnosticError("no input: give at least one BVH or glTF file")
        options.setdefault("out", "render.gif")
        check_render_outputs(options)  # before the (possibly long) clips are read
        from skelagnostic.io.motion_files import read_motion

        motions = [read_motion(path, other="bvh") for path in paths]
        for path in render_from_options(motions, options):
            print(printable(path))
    except SkelagnosticError as error:
        print(error_line("skelagnostic render", error), file=sys.stderr)
        return 2
    return 0


def _write_html(
    motions: Sequence[Any],
    path: str,
    common: Mapping[str, Any],
    marks: Mapping[str, dict[int, list[int]]],
    key: str,
) -> Path:
    """Write the viewer page with the options it understands (mode, follow, labels)."""
    from skelagnostic.io.outputs import write_output
    from skelagnostic.viz import to_html

    extra = {key: common[key] for key in ("mode", "follow") if key in common}
    page = to_html(motions, names=common.get("labels"), **marks, **extra)
    write_output(path, page, key)
    return Path(path)


def _seconds(options: Mapping[str, str], key: str, motions: Sequence[Any]) -> float:
    """``start=`` / ``end=`` in seconds: a finite number, at least 0, at most the longest clip."""
    value = _number(options, key, float)
    longest = max((m.duration for m in motions if hasattr(m, "duration")), default=math.inf)
    if not math.isfinite(value) or value < 0:
        raise SkelagnosticError(f"option {key}={options[key]}: must be a number of seconds >= 0")
    if key == "start" and value >= longest:
        raise SkelagnosticError(
            f"option start={options[key]}: past the end of every clip "
            f"(the longest lasts {longest:.2f} s)"
        )
    return min(value, longest)


def _first_frames(motions: Sequence[Any], options: Mapping[str, str]) -> list[int]:
    """First frame kept of every clip by ``start=`` (0 without it)."""
    if "start" not in options:
        return [0] * len(motions)
    start = _seconds(options, "start", motions)
    return [max(0, round(start * m.fps)) if hasattr(m, "fps") else 0 for m in motions]


def _shift_marks(
    marks: Mapping[int, Sequence[int]] | None, firsts: Sequence[int], motions: Sequence[Any]
) -> dict[int, list[int]]:
    """Frame marks moved to the cut clips; marks outside the cut are dropped."""
    out: dict[int, list[int]] = {}
    for clip, frames in (marks or {}).items():
        length = getattr(motions[clip], "num_frames", None)
        kept = [f - firsts[clip] for f in frames if f >= firsts[clip]]
        out[clip] = [f for f in kept if length is None or f < length]
    return out


def _number(options: Mapping[str, str], key: str, kind: type) -> Any:
    try:
        return kind(options[key])
    except ValueError:
        raise SkelagnosticError(
            f"option {key}={options[key]!r} is not {'an integer' if kind is int else 'a number'}"
        ) from None


def _flag(options: Mapping[str, str], key: str) -> bool:
    value = options[key].strip().lower()
    if value in ("1", "true", "yes", "on"):
        return True
    if value in ("0", "false", "no", "off"):
        return False
    raise SkelagnosticError(f"option {key}={options[key]!r} is not true/false")


def _size(text: str) -> tuple[int, int]:
    parts = text.lower().split("x")
    try:
        values = [int(p) for p in parts]
    except ValueError:
        values = []
    if len(values) not in (1, 2):
        raise SkelagnosticError(f"option size={text!r} is not WxH or N pixels")
    return (values[0], values[-1])


def _cut(motions: Sequence[Any], options: Mapping[str, str]) -> list[Any]:
    """Apply ``start=`` / ``end=`` (seconds) to every Motion."""
    if "start" not in options and "end" not in options:
        return list(motions)
    start = _seconds(options, "start", motions) if "start" in options else 0.0
    end = _seconds(options, "end", motions) if "end" in options else None
    if start < 0 or (end is not None and end <= start):
        raise SkelagnosticError(f"options start={start} end={end}: need 0 <= start < end")
    cut = []
    for motion in motions:
        first = round(start * motion.fps)
        last = motion.num_frames if end is None else round(end * motion.fps) + 1
        if first >= motion.num_frames:
            raise SkelagnosticError(
                f"option start={start}: past the end of {motion.name or 'a clip'} "
                f"({motion.duration:.2f} s)"
            )
        cut.append(motion[first:last])
    return cut
