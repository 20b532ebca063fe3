"""A self-contained interactive 3D viewer: motions to one HTML file.

:func:`to_html` writes a single HTML page that plays one or several clips with
three.js (shipped inside the package with its license, inlined into the page,
so nothing is fetched at view time): orbit/zoom camera, play/pause, frame
scrubber, speed, loop, a camera that follows the roots or stays fixed, clips
side by side or overlaid, a floor grid in metres, one colour per clip and body
group, joint names on hover and keyframes / transitions marked on the timeline.

Positions are converted to metres and to a y-up frame, then stored as 16-bit
integers per axis and clip (``value = origin + q * step``); decoding in the
page (or with :func:`decode_payload`) is exact to ``step / 2``.
"""

from __future__ import annotations

import base64
import colorsys
import json
import math
import re
from collections.abc import Mapping, Sequence
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from skelagnostic.viz.stick import FigureLike, RenderError, StickFigure, to_stick_figures

__all__ = [
    "CLIP_HUES",
    "THREE_VERSION",
    "build_payload",
    "clip_colors",
    "decode_payload",
    "guess_units",
    "to_html",
]

#: Version of the three.js build shipped in ``skelagnostic/viz/assets``.
THREE_VERSION = "0.147.0"

#: Hue (0..1) of each clip in turn; the body groups are shades around it.
CLIP_HUES = (0.58, 0.02, 0.33, 0.78, 0.11, 0.48, 0.90, 0.22, 0.66, 0.40)

#: Per body group: (hue shift, saturation, lightness) around the clip's hue.
_GROUP_SHADES: dict[str, tuple[float, float, float]] = {
    "spine": (0.0, 0.80, 0.30),
    "left_arm": (0.04, 0.85, 0.60),
    "right_arm": (-0.04, 0.85, 0.60),
    "left_leg": (0.04, 0.75, 0.45),
    "right_leg": (-0.04, 0.75, 0.45),
    "tail": (0.0, 0.45, 0.70),
    "other": (0.0, 0.20, 0.55),
}

#: Typical standing height in metres, to guess the length unit of a clip.
_LEVELS = 65535
_MODES = ("side", "overlay")
_ASSETS = "assets"
_DATA_ID = "skelagnostic-data"


def _hex(rgb: tuple[float, float, float]) -> str:
    return "#" + "".join(f"{round(255 * min(max(c, 0.0), 1.0)):02x}" for c in rgb)


def clip_colors(index: int) -> dict[str, str]:
    """Colours of clip number ``index``: one ``#rrggbb`` per body group.

    Args:
        index: Position of the clip in the viewer (colours cycle after
            ``len(CLIP_HUES)`` clips).

    Returns:
        Body group -> colour; the ``"spine"`` colour is the clip's own colour
        (joints, legend and timeline marks).

    Examples:
        >>> clip_colors(0)["spine"]
        '#0f4f8a'
    """
    hue = CLIP_HUES[index % len(CLIP_HUES)]
    return {
        group: _hex(colorsys.hls_to_rgb((hue + dh) % 1.0, light, sat))
        for group, (dh, sat, light) in _GROUP_SHADES.items()
    }


def guess_units(figure: StickFigure) -> str:
    """Guess the length unit of a clip from the height of its first pose.

    The guess is the unit of :data:`skelagnostic.core.UNITS` that brings the
    height closest (in ratio) to a typical standing height: 1.7 m for bipeds,
    0.5 m for characters with a tail (quadrupeds). Give the units explicitly
    (``Motion.units`` or ``units=``) when they are known.

    Args:
        figure: The clip.

    Returns:
        A key of :data:`skelagnostic.core.UNITS`.

    Examples:
        >>> import numpy as np
        >>> pose = np.array([[[0.0, 90.0, 0.0], [0.0, 170.0, 0.0], [0.0, 0.0, 0.0]]])
        >>> guess_units(StickFigure(pose, parents=[-1, 0, 0]))
        'cm'
    """
    from skelagnostic.core.units import HUMAN_HEIGHT, QUADRUPED_HEIGHT, units_for_height

    up = "xyz".index(figure.up_axis)
    height = float(np.ptp(figure.positions[0, :, up]))
    if not height > 0:
        return "m"
    tailed = "tail" in figure.groups  # type: ignore[operator]
    return units_for_height(height, QUADRUPED_HEIGHT if tailed else HUMAN_HEIGHT)


def _y_up(positions: np.ndarray, up_axis: str) -> np.ndarray:
    """Rotate positions so that ``up_axis`` becomes +y (a proper rotation)."""
    x, y, z = positions[..., 0], positions[..., 1], positions[..., 2]
    if up_axis == "z":
        return np.stack([x, z, -y], axis=-1)
    if up_axis == "x":
        return np.stack([-y, x, z], axis=-1)
    return positions


def _as_marks(marks: Any, count: int, name: str) -> list[list[int]]:
    """Frame marks per clip: ``None``, one flat list for every clip, or one list per clip."""
    if marks is None:
        return [[] for _ in range(count)]
    if isinstance(marks, Mapping):
        out: list[list[int]] = [[] for _ in range(count)]
        for key, frames in marks.items():
            if not 0 <= int(key) < count:
                raise RenderError(f"{name}: clip index {key} is out of range (0..{count - 1})")
            out[int(key)] = sorted({int(f) for f in frames})
        return out
    marks = list(marks)
    if all(isinstance(m, (int, np.integer)) for m in marks):
        return [sorted({int(f) for f in marks}) for _ in range(count)]
    if len(marks) != count:
        raise RenderError(f"{name}: got {len(marks)} lists for {count} clips")
    return [[] if m is None else sorted({int(f) for f in m}) for m in marks]


def _quantise(positions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``uint16`` codes, per-axis origin and step of ``[T, J, 3]`` positions."""
    lo = positions.reshape(-1, 3).min(axis=0)
    hi = positions.reshape(-1, 3).max(axis=0)
    step = (hi - lo) / _LEVELS
    step[step <= 0] = 1e-9
    codes = np.clip(np.rint((positions - lo) / step), 0, _LEVELS).astype("<u2")
    return codes, lo, step


def _lanes(roots: list[np.ndarray], spacing: float) -> tuple[int, list[list[float]]]:
    """Axis (0 = x, 2 = z) of the lanes and each clip's offset for the side-by-side layout.

    Every clip starts at the origin of its lane (its first root position moved
    there on the floor); lanes are ``spacing`` apart along the horizontal axis
    along which the root paths move least, so walks that go along x are lined
    up side by side along z.
    """
    spread = np.zeros(3)
    for path in roots:
        spread += np.ptp(path - path[:1], axis=0)
    axis = 0 if spread[0] <= spread[2] else 2
    offsets = []
    for k, path in enumerate(roots):
        offset = [-float(path[0, 0]), 0.0, -float(path[0, 2])]
        offset[axis] += (k - (len(roots) - 1) / 2.0) * spacing
        offsets.append(offset)
    return axis, offsets


def _clip_units(
    items: list[FigureLike], units: str | Sequence[str | None] | None, count: int
) -> list[str | None]:
    """The unit of every clip: given, else the motion's own (``None``: guess later).

    Raises:
        RenderError: A unit list of the wrong length or an unknown unit.
    """
    from skelagnostic.core.motion import UNITS

    if units is None or isinstance(units, str):
        unit_list: list[str | None] = [units] * count
    else:
        unit_list = list(units)
        if len(unit_list) != count:
            raise RenderError(f"units: got {len(unit_list)} units for {count} clips")
    # A Motion knows its units; a StickFigure does not.
    for k, item in enumerate(items):
        if unit_list[k] is None:
            unit_list[k] = getattr(item, "units", None)
    for unit in unit_list:
        if unit is not None and unit not in UNITS:
            raise RenderError(f"units: unknown unit {unit!r}; known: {', '.join(UNITS)}")
    return unit_list


def _clip_entry(
    k: int, figure: StickFigure, unit: str | None, keys: list[int], switches: list[int]
) -> tuple[dict[str, Any], np.ndarray]:
    """The payload entry of clip ``k`` (without its lane offsets) and its ``[T, J, 3]`` metres.

    Raises:
        RenderError: A key frame or transition outside the clip.
    """
    from skelagnostic.core.motion import UNITS

    unit = unit or guess_units(figure)
    metres = _y_up(figure.positions, figure.up_axis) * UNITS[unit]
    codes, origin, step = _quantise(metres)
    joint_names = getattr(figure, "joint_names", None)
    if joint_names is None:
        joint_names = [f"joint {j}" for j in range(figure.num_joints)]
    for label, marks in (("keyframes", keys), ("transitions", switches)):
        bad = [f for f in marks if not 0 <= f < figure.num_frames]
        if bad:
            raise RenderError(
                f"{label}: frame(s) {bad} are outside clip {figure.name!r} "
                f"(0..{figure.num_frames - 1})"
            )
    colours = clip_colors(k)
    clip = {
        "name": figure.name or f"clip {k}",
        "fps": figure.fps,
        "frames": figure.num_frames,
        "units": unit,
        "height": float(np.ptp(metres[0, :, 1])),
        "joints": list(joint_names),
        "parents": list(figure.parents),
        "groups": list(figure.groups),  # type: ignore[arg-type]
        "color": colours["spine"],
        "groupColors": colours,
        "origin": [float(v) for v in origin],
        "step": [float(v) for v in step],
        "positions": base64.b64encode(codes.tobytes()).decode("ascii"),
        "keyframes": keys,
        "transitions": switches,
    }
    return clip, metres


def build_payload(
    motions: FigureLike | Sequence[FigureLike],
    names: Sequence[str] | None = None,
    *,
    units: str | Sequence[str | None] | None = None,
    mode: str = "side",
    follow: bool = True,
    loop: bool = True,
    speed: float = 1.0,
    keyframes: Any = None,
    transitions: Any = None,
    title: str = "skelagnostic viewer",
) -> dict[str, Any]:
    """The data the viewer page plays: clips in metres, y-up, quantised to 16 bits.

    Args:
        motions: What :func:`to_html` shows.
        names: One label per clip.
        units: See :func:`to_html`.
        mode: See :func:`to_html`.
        follow: See :func:`to_html`.
        loop: See :func:`to_html`.
        speed: See :func:`to_html`.
        keyframes: See :func:`to_html`.
        transitions: See :func:`to_html`.
        title: See :func:`to_html`.

    Returns:
        A JSON-serialisable mapping (see :func:`decode_payload`).

    Raises:
        RenderError: On bad arguments; the message names the argument.
    """
    items = motions if isinstance(motions, Sequence) and not isinstance(motions, str) else [motions]
    figures = to_stick_figures(items, names)  # type: ignore[arg-type]
    if mode not in _MODES:
        raise RenderError(f"mode must be one of {_MODES}, got {mode!r}")
    if not (math.isfinite(speed) and speed > 0):
        raise RenderError(f"speed must be a positive number, got {speed}")
    count = len(figures)
    unit_list = _clip_units(list(items), units, count)  # type: ignore[arg-type]
    keys = _as_marks(keyframes, count, "keyframes")
    switches = _as_marks(transitions, count, "transitions")

    clips, lowest, heights, roots = [], [], [], []
    for k, figure in enumerate(figures):
        clip, metres = _clip_entry(k, figure, unit_list[k], keys[k], switches[k])
        clips.append(clip)
        lowest.append(float(metres[..., 1].min()))
        roots.append(metres[:, 0])
        heights.append(clip["height"])
    tallest = max(max(heights), 0.1)
    axis, offsets = _lanes(roots, spacing=max(1.0, 1.1 * tallest + 0.2))
    for clip, offset, path in zip(clips, offsets, roots, strict=True):
        clip["sideOffset"] = offset
        clip["overlayOffset"] = [-float(path[0, 0]), 0.0, -float(path[0, 2])]
    return {
        "title": title,
        "version": 1,
        "mode": mode,
        "follow": bool(follow),
        "loop": bool(loop),
        "speed": float(speed),
        "fps": max(f.fps for f in figures),
        "duration": max(f.duration for f in figures),
        "floor": min(lowest),
        "laneAxis": axis,
        "height": tallest,
        "clips": clips,
    }


def decode_payload(payload: Mapping[str, Any] | str) -> list[np.ndarray]:
    """Positions ``[T, J, 3]`` (metres, y-up) of every clip of a viewer payload or page.

    This is what the page decodes; tests use it to compare with forward kinematics.

    Args:
        payload: The mapping of :func:`build_payload`, or the text of a page
            written by :func:`to_html`.

    Returns:
        One float64 array per clip.

    Raises:
        RenderError: If a page holds no viewer data.
    """
    if isinstance(payload, str):
        start_tag = f'<script type="application/json" id="{_DATA_ID}">'
        start = payload.find(start_tag)
        if start < 0:
            raise RenderError("the page holds no skelagnostic viewer data")
        start += len(start_tag)
        end = payload.index("</script>", start)
        payload = json.loads(payload[start:end])
    out = []
    for clip in payload["clips"]:  # type: ignore[index]
        codes = np.frombuffer(base64.b64decode(clip["positions"]), dtype="<u2")
        codes = codes.reshape(clip["frames"], len(clip["joints"]), 3).astype(np.float64)
        out.append(np.asarray(clip["origin"]) + codes * np.asarray(clip["step"]))
    return out


def _asset(name: str) -> str:
    return resources.files("skelagnostic.viz").joinpath(_ASSETS, name).read_text("utf-8")


#: What :func:`_script_json` writes instead of each character that could end or change a
#: ``<script>`` element (``</script>``, ``<!--``), an HTML entity (``&``) or a JavaScript line.
_SCRIPT_JSON_ESCAPES = str.maketrans(
    {
        "<": "\\u003c",
        ">": "\\u003e",
        "&": "\\u0026",
        "\u2028": "\\u2028",
        "\u2029": "\\u2029",
    }
)


def _script_json(value: Any) -> str:
    r"""JSON text of ``value`` that is safe as the content of an HTML ``<script>`` element.

    ``<``, ``>``, ``&``, U+2028 and U+2029 are written as JSON escapes
    (``\u003c`` ...), so no name (a joint, file or label such as
    ``<!--<script>`` or ``</script><img src=x onerror=...>``) can close the
    element, open an HTML comment in it or split a line of script; the text
    parses back to ``value`` with any JSON reader.

    Args:
        value: A JSON-serialisable value.

    Returns:
        Compact ASCII JSON without ``<``, ``>`` or ``&``.

    Examples:
        >>> _script_json({"name": "</script><!--"})
        '{"name":"\\u003c/script\\u003e\\u003c!--"}'
    """
    return json.dumps(value, separators=(",", ":")).translate(_SCRIPT_JSON_ESCAPES)


def _inline(text: str) -> str:
    """Make script text safe inside a ``<script>`` element (no closing tag, no comment)."""
    text = re.sub(r"</(script)", r"<\\/\1", text, flags=re.IGNORECASE)
    return text.replace("<!--", "<\\!--")


def to_html(
    motions: FigureLike | Sequence[FigureLike],
    names: Sequence[str] | None = None,
    out: str | Path | None = None,
    *,
    units: str | Sequence[str | None] | None = None,
    mode: str = "side",
    follow: bool = True,
    loop: bool = True,
    speed: float = 1.0,
    keyframes: Any = None,
    transitions: Any = None,
    title: str = "skelagnostic viewer",
) -> str:
    """Write an interactive 3D viewer of the motions as one self-contained HTML file.

    The page needs no network: three.js (MIT, license in
    ``skelagnostic/viz/assets/three.LICENSE``) is inlined. Every clip is shown
    in metres on a shared scale with a 1 m floor grid, on a common clock (each
    clip at its own frame rate).

    Args:
        motions: A :class:`~skelagnostic.Motion`, BVH path or
            :class:`~skelagnostic.viz.StickFigure`, or a sequence of them.
        names: One label per clip (default: file stem or motion name).
        out: Where to write the page (``.html``); ``None`` only returns it.
        units: Length unit of the clips (one for all, or one per clip; keys of
            :data:`skelagnostic.core.UNITS`). ``None`` uses ``Motion.units``
            and otherwise guesses it from the height (:func:`guess_units`).
        mode: ``"side"`` (clips side by side, in lanes across their main
            direction of travel) or ``"overlay"`` (one on top of the other); the
            page can switch. Both layouts move each clip on the floor so that
            it starts at the origin of its lane (heights are kept).
        follow: Start with the camera following the roots (default; else a fixed
            camera framing every frame of every clip).
        loop: Start with looping on.
        speed: Initial playback speed factor.
        keyframes: Frames to mark on the timeline: a list of frame indices for
            every clip, one list (or ``None``) per clip, or a mapping clip
            index -> frames.
        transitions: Matching transitions to mark, in the same forms.
        title: Page title.

    Returns:
        The HTML text.

    Raises:
        RenderError: On bad arguments, or when ``out`` does not end in ``.html``/``.htm``.
        OutputError: ``out`` cannot be written (full disk, ...); a previous page is unchanged.

    Examples:
        >>> import numpy as np
        >>> from skelagnostic.viz import StickFigure, to_html
        >>> pos = np.zeros((3, 2, 3)) + [0.0, 1.0, 0.0]
        >>> page = to_html(StickFigure(pos, parents=[-1, 0]), units="m")
        >>> page.startswith("<!DOCTYPE html>"), "three.js" in page
        (True, True)
    """
    if out is not None and Path(out).suffix.lower() not in (".html", ".htm"):
        raise RenderError(f"out: a viewer page is an .html file, got {Path(out).name!r}")
    payload = build_payload(
        motions,
        names,
        units=units,
        mode=mode,
        follow=follow,
        loop=loop,
        speed=speed,
        keyframes=keyframes,
        transitions=transitions,
        title=title,
    )
    page = _asset("viewer.html")
    parts = {
        "__TITLE__": _html_escape(title),
        "__STYLE__": _asset("viewer.css"),
        "__THREE__": _inline(_asset("three.min.js")),
        "__ORBIT__": _inline(_asset("OrbitControls.js")),
        "__DATA__": _script_json(payload),
        "__VIEWER__": _inline(_asset("viewer.js")),
    }
    for key, value in parts.items():
        head, sep, tail = page.partition("/*" + key + "*/")
        if not sep:
            raise RuntimeError(f"viewer.html lacks the {key} slot")  # pragma: no cover
        page = head + value + tail
    if out is not None:  # atomically: a failed write leaves the previous page as it was
        from skelagnostic.io.outputs import write_output

        write_output(out, page, "out")
    return page


def _html_escape(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
