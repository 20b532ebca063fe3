"""The syntax of a BVH file: its hierarchy, its MOTION header and its rows of numbers.

The lexical half of :func:`skelagnostic.io.bvh.parse_bvh`: it turns text into joints
(names, parents, offsets, channels) and a ``[frames, channels]`` array, raising
:class:`~skelagnostic.BVHError` with the 1-based line at fault. Building the
:class:`~skelagnostic.Motion` from them (rotation orders, quaternions, units) is
:mod:`skelagnostic.io.bvh`'s.
"""

from __future__ import annotations

import io
import math
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from skelagnostic.errors import BVHError

ROTATIONS = {"Xrotation": "X", "Yrotation": "Y", "Zrotation": "Z"}
POSITIONS = {"Xposition": 0, "Yposition": 1, "Zposition": 2}
BOM = b"\xef\xbb\xbf"
MOTION = re.compile(r"^[ \t]*MOTION[ \t]*\r?$", re.MULTILINE)
MOTION_BYTES = re.compile(rb"^[ \t]*MOTION[ \t]*\r?$", re.MULTILINE)


def text_head(raw: bytes) -> bytes:
    """``raw`` up to the end of the second non-blank line after ``MOTION``.

    Only this part is decoded to text: the motion lines go to numpy as bytes.
    Without a ``MOTION`` line the whole file is returned (for the error message).
    """
    match = MOTION_BYTES.search(raw)
    if match is None:
        return raw
    pos, found = match.end(), 0
    while found < 2 and pos < len(raw):
        end = raw.find(b"\n", pos)
        end = len(raw) if end < 0 else end
        found += bool(raw[pos:end].strip()) and pos > match.end()
        pos = end + 1
    return raw[:pos]


@dataclass
class Joint:
    name: str
    parent: int
    offset: list[float]
    channels: list[str] = field(default_factory=list)
    end_sites: list[list[float]] = field(default_factory=list)


class Tokens:
    """Whitespace tokens of the hierarchy section (the lines before MOTION), with 1-based lines."""

    def __init__(self, lines: list[str], path: Path | None):
        self.items: list[tuple[str, int]] = [
            (w, i) for i, line in enumerate(lines, start=1) for w in line.split()
        ]
        self.path = path
        self.pos = 0
        self.last_line = len(lines)

    def error(self, reason: str, line: int | None = None) -> BVHError:
        if line is None:
            line = self.items[self.pos][1] if self.pos < len(self.items) else self.last_line
        return BVHError(reason, self.path, line)

    def next(self, what: str) -> tuple[str, int]:
        if self.pos >= len(self.items):
            raise self.error(f"unexpected end of the hierarchy, expected {what}")
        tok = self.items[self.pos]
        self.pos += 1
        return tok

    def expect(self, word: str) -> int:
        tok, line = self.next(repr(word))
        if tok != word:
            raise self.error(f"expected {word!r}, found {tok!r}", line)
        return line

    def floats(self, n: int, what: str) -> list[float]:
        out = []
        for _ in range(n):
            tok, line = self.next(what)
            try:
                v = float(tok)
            except ValueError:
                raise self.error(f"{what}: {tok!r} is not a number", line) from None
            if not math.isfinite(v):
                raise self.error(f"{what}: value {tok!r} is not finite", line)
            out.append(v)
        return out

    def peek(self) -> str | None:
        return self.items[self.pos][0] if self.pos < len(self.items) else None


def parse_hierarchy(tokens: Tokens) -> list[Joint]:
    """The joints of the hierarchy, parents before children.

    The nesting is followed with an explicit stack of open joints (no recursion), so
    the depth of the hierarchy is limited only by memory.
    """
    tok, line = tokens.next("'HIERARCHY'")
    if tok.upper() != "HIERARCHY":
        raise tokens.error(f"a BVH file starts with 'HIERARCHY', found {tok!r}", line)
    tok, line = tokens.next("'ROOT'")
    if tok.upper() != "ROOT":
        raise tokens.error(f"expected 'ROOT', found {tok!r}", line)
    joints: list[Joint] = []
    names: dict[str, int] = {}

    def open_joint(parent: int) -> int:
        """Read a joint's name, '{', OFFSET and CHANNELS; returns its index."""
        name, line = tokens.next("a joint name")
        if name in {"{", "}"}:
            raise tokens.error("missing joint name", line)
        if name in names:
            raise tokens.error(f"duplicate joint name {name!r}", line)
        tokens.expect("{")
        tokens.expect("OFFSET")
        offset = tokens.floats(3, f"OFFSET of joint {name!r}")
        index = len(joints)
        joint = Joint(name, parent, offset)
        names[name] = index
        joints.append(joint)
        if tokens.peek() == "CHANNELS":
            tokens.next("CHANNELS")
            tok, cline = tokens.next("the channel count")
            try:
                count = int(tok)
            except ValueError:
                raise tokens.error(
                    f"channel count {tok!r} of joint {name!r} is not an integer", cline
                ) from None
            if count < 0 or count > 6:
                raise tokens.error(
                    f"joint {name!r} declares {count} channels (0 to 6 allowed)", cline
                )
            for _ in range(count):
                ch, chl = tokens.next(f"a channel name of joint {name!r}")
                if ch not in ROTATIONS and ch not in POSITIONS:
                    if ch in {"}", "JOINT", "End", "{", "OFFSET"}:
                        raise tokens.error(
                            f"joint {name!r} declares {count} channels but lists "
                            f"{len(joint.channels)}",
                            chl,
                        )
                    raise tokens.error(f"unknown channel {ch!r} on joint {name!r}", chl)
                if ch in joint.channels:
                    raise tokens.error(f"channel {ch!r} repeated on joint {name!r}", chl)
                joint.channels.append(ch)
        return index

    open_joints = [open_joint(-1)]  # the joints whose closing '}' is still to come
    while open_joints:
        joint = joints[open_joints[-1]]
        name = joint.name
        tok, tline = tokens.next(f"'JOINT', 'End Site' or '}}' in joint {name!r}")
        if tok == "}":
            open_joints.pop()
        elif tok == "JOINT":
            open_joints.append(open_joint(open_joints[-1]))
        elif tok == "End":
            site, sline = tokens.next("'Site'")
            if site != "Site":
                raise tokens.error(f"expected 'End Site', found 'End {site}'", sline)
            tokens.expect("{")
            tokens.expect("OFFSET")
            joint.end_sites.append(tokens.floats(3, f"End Site OFFSET of joint {name!r}"))
            tokens.expect("}")
        elif tok == "CHANNELS":
            raise tokens.error(f"CHANNELS of joint {name!r} must follow its OFFSET", tline)
        else:
            raise tokens.error(f"unexpected {tok!r} in joint {name!r}", tline)
    if tokens.pos < len(tokens.items):
        tok, line = tokens.items[tokens.pos]
        if tok.upper() == "MOTION":  # e.g. "} MOTION", or a lone CR before MOTION
            raise tokens.error(
                "'MOTION' must stand alone on its line (a line ending in LF or CR LF)", line
            )
        raise tokens.error(f"unexpected {tok!r} after the root joint (a second ROOT?)", line)
    return joints


def diagnose_rows(
    lines: list[str],
    first: int,
    num_frames: int,
    num_channels: int,
    frames_line: int,
    path: Path | None,
) -> BVHError:
    """Find the first bad motion line (slow path, only used after a failure)."""
    rows = [k for k, line in enumerate(lines) if line.strip()]
    if len(rows) != num_frames:
        return BVHError(
            f"the file declares {num_frames} frames but has {len(rows)} motion lines"
            + (" (truncated?)" if len(rows) < num_frames else ""),
            path,
            first + rows[-1] if rows else frames_line,
        )
    for k in rows:
        words = lines[k].split()
        if len(words) != num_channels:
            return BVHError(
                f"motion line has {len(words)} values, the hierarchy declares {num_channels} "
                "channels",
                path,
                first + k,
            )
        for w in words:
            try:
                v = float(w)
            except ValueError:
                return BVHError(f"motion value {w!r} is not a number", path, first + k)
            if not math.isfinite(v):
                return BVHError(f"motion value {w!r} is not finite (NaN/inf)", path, first + k)
    return BVHError("motion data could not be read", path, first)


def decode(data: bytes | str, path: Path | None) -> tuple[bytes, str]:
    """The file's bytes (byte order mark dropped, CR-only line ends made LF) and its text head.

    The head is the text up to the motion data (see :func:`head`); the data stays bytes.

    Raises:
        BVHError: The head of a BVH file is not valid UTF-8.
    """
    raw = data if isinstance(data, bytes) else data.encode("utf-8")
    skipped = 0  # bytes of a UTF-8 byte order mark, for the offsets in messages
    if raw.startswith(BOM):
        raw, skipped = raw[len(BOM) :], len(BOM)
    if b"\n" not in raw and b"\r" in raw:  # CR-only line ends (classic Mac OS)
        raw = raw.replace(b"\r", b"\n")
    head = text_head(raw)
    try:
        return raw, head.decode("utf-8")
    except UnicodeDecodeError as exc:
        text = head.decode("utf-8", errors="replace")
        if text.split(None, 1)[0].upper() == "HIERARCHY":  # else: not BVH, said below
            raise BVHError(
                f"invalid UTF-8 at byte offset {exc.start + skipped} "
                f"(0x{head[exc.start]:02x}); BVH files are read as UTF-8, re-save this "
                "one in that encoding",
                path,
                head.count(b"\n", 0, exc.start) + 1,
            ) from None
        return raw, text


def motion_header(
    text: str, pos: int, line_no: int, path: Path | None
) -> tuple[dict[str, tuple[str, int]], int, int]:
    """The 'Frames:' and 'Frame Time:' lines after MOTION, scanned without splitting the data.

    Args:
        text: The file's text head.
        pos: Offset in ``text`` just after the MOTION keyword.
        line_no: The number of the MOTION line.
        path: Only used in error messages.

    Returns:
        ``{"frames" | "frame time": (value text, line number)}``, the offset of the
        end of the last header line and that line's number.
    """
    header: dict[str, tuple[str, int]] = {}
    while len(header) < 2:
        if pos >= len(text):
            missing = "Frames" if "frames" not in header else "Frame Time"
            raise BVHError(f"missing '{missing}:' line after MOTION", path, line_no)
        end = text.find("\n", pos + 1)
        end = len(text) if end < 0 else end
        line = text[pos:end].strip()
        pos = end
        line_no += 1
        if not line:
            continue
        key, _, value = line.partition(":")
        key = " ".join(key.split()).lower()
        if key not in {"frames", "frame time"}:
            raise BVHError(f"expected 'Frames:' and 'Frame Time:', found {line!r}", path, line_no)
        header[key] = (value.strip(), line_no)
    return header, pos, line_no


def parse_frame_count(header: dict[str, tuple[str, int]], path: Path | None) -> int:
    """The positive whole number of the 'Frames:' line."""
    try:
        num_frames = int(header["frames"][0])
    except ValueError:
        raise BVHError(
            f"Frames: {header['frames'][0]!r} is not an integer", path, header["frames"][1]
        ) from None
    if num_frames <= 0:
        raise BVHError(
            f"the file declares {num_frames} frames; a motion needs at least one",
            path,
            header["frames"][1],
        )
    return num_frames


def parse_frame_time(header: dict[str, tuple[str, int]], path: Path | None) -> float:
    """The seconds of the 'Frame Time:' line: finite, positive, with a finite inverse."""
    try:
        frame_time = float(header["frame time"][0])
    except ValueError:
        raise BVHError(
            f"Frame Time: {header['frame time'][0]!r} is not a number",
            path,
            header["frame time"][1],
        ) from None
    if not math.isfinite(frame_time):
        raise BVHError(
            f"Frame Time must be a finite number of seconds, got {frame_time}",
            path,
            header["frame time"][1],
        )
    if frame_time <= 0:
        raise BVHError(
            f"Frame Time must be positive, got {frame_time}", path, header["frame time"][1]
        )
    if not math.isfinite(1.0 / frame_time):
        raise BVHError(
            f"Frame Time {header['frame time'][0]} is too small: the frame rate "
            "1 / Frame Time is not a finite number",
            path,
            header["frame time"][1],
        )
    return frame_time


def read_values(body: bytes, num_channels: int) -> np.ndarray | None:
    """The motion lines as a ``[frames, channels]`` array, or ``None`` if numpy cannot read them."""
    if not num_channels:
        return None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "input contained no data": diagnosed by the caller
            return np.loadtxt(io.BytesIO(body), dtype=np.float64, ndmin=2)
    except ValueError:
        return None
