"""BVH reading and writing.

Supported: any rotation channel order per joint, position channels on any
joint (Bandai-style files translate non-root joints), End Sites, CRLF, LF or
CR-only line endings, tabs or spaces, and UTF-8 text with or without a byte
order mark (other encodings are an error naming the first byte that is not
UTF-8). Local quaternions are made sign-continuous
along time (``q`` and ``-q`` are the same rotation). Position channels
*replace* the joint's OFFSET for that frame (the convention of the CMU, LaFAN1
and Bandai tools); a root without position channels stays at its OFFSET.

Every problem raises :class:`~skelagnostic.BVHError` with the file and the
1-based line at fault; nothing half-built is returned. A last motion line
without a line end is read with a :class:`BVHWarning` (the file may be cut).
Writing goes through :func:`~skelagnostic.io.atomic.atomic_write`: a temporary
file replaces the target only when complete, with the permissions the umask
allows, and a symbolic link is written through.
"""

from __future__ import annotations

import io
import math
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from skelagnostic.core import quaternion as Q
from skelagnostic.core.motion import Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.errors import BVHError, SkeletonError, printable
from skelagnostic.io.atomic import atomic_write

__all__ = ["BVHWarning", "parse_bvh", "read_bvh", "write_bvh"]


class BVHWarning(UserWarning):
    """A BVH file that reads but looks damaged (its last motion line has no line end)."""


_ROT = {"Xrotation": "X", "Yrotation": "Y", "Zrotation": "Z"}
_POS = {"Xposition": 0, "Yposition": 1, "Zposition": 2}
_DEFAULT_ROOT = ["Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation"]
_DEFAULT_JOINT = ["Zrotation", "Yrotation", "Xrotation"]
#: Indentation stops growing at this depth (a 10,000-level chain would otherwise
#: write 50 million tabs).
_MAX_INDENT = 32
_BOM = b"\xef\xbb\xbf"
_MOTION = re.compile(r"^[ \t]*MOTION[ \t]*\r?$", re.MULTILINE)
_MOTION_BYTES = re.compile(rb"^[ \t]*MOTION[ \t]*\r?$", re.MULTILINE)


def _head(raw: bytes) -> bytes:
    """``raw`` up to the end of the second non-blank line after ``MOTION``.

    Only this part is decoded to text: the motion lines go to numpy as bytes.
    Without a ``MOTION`` line the whole file is returned (for the error message).
    """
    match = _MOTION_BYTES.search(raw)
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
class _Joint:
    name: str
    parent: int
    offset: list[float]
    channels: list[str] = field(default_factory=list)
    end_sites: list[list[float]] = field(default_factory=list)


class _Tokens:
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


def _parse_hierarchy(tokens: _Tokens) -> list[_Joint]:
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
    joints: list[_Joint] = []
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
        joint = _Joint(name, parent, offset)
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
                if ch not in _ROT and ch not in _POS:
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


def _diagnose_rows(
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


def snap_rate(fps: float) -> float:
    """A frame rate within 0.1 % of a whole number, as that number (1/30 s written as 0.0333333)."""
    nearest = round(fps)
    return float(nearest) if nearest > 0 and abs(fps - nearest) <= 1e-3 * fps else fps


def _snap_fps(frame_time: float) -> float:
    return snap_rate(1.0 / frame_time)


def _format_frame_time(seconds: float) -> str:
    """8 decimals (``0.03333333``), or all digits when those would lose the value."""
    text = f"{seconds:.8f}"
    return text if abs(float(text) - seconds) <= 1e-6 * seconds else repr(seconds)


def parse_bvh(
    data: bytes | str,
    path: str | Path | None = None,
    dtype: torch.dtype = torch.float64,
    name: str | None = None,
) -> Motion:
    """Parse BVH text (the work behind :func:`read_bvh`, for in-memory data).

    Args:
        data: The file content.
        path: Only used in error messages.
        dtype: Float dtype of the returned tensors.
        name: Label of the motion.

    Returns:
        The motion.

    Raises:
        BVHError: On any malformed input, naming the line.
    """
    path = None if path is None else Path(path)
    raw = data if isinstance(data, bytes) else data.encode("utf-8")
    skipped = 0  # bytes of a UTF-8 byte order mark, for the offsets in messages
    if raw.startswith(_BOM):
        raw, skipped = raw[len(_BOM) :], len(_BOM)
    if b"\n" not in raw and b"\r" in raw:  # CR-only line ends (classic Mac OS)
        raw = raw.replace(b"\r", b"\n")
    head = _head(raw)
    try:
        text = head.decode("utf-8")
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
    match = _MOTION.search(text)
    lines = (text if match is None else text[: match.start()]).splitlines()
    if match is None and not any(line.strip() for line in lines):
        raise BVHError("the file is empty", path, 1)
    tokens = _Tokens(lines, path)
    joints = _parse_hierarchy(tokens)
    if match is None:
        raise BVHError("no MOTION section (truncated file?)", path, len(lines))
    # the 'Frames:' and 'Frame Time:' lines, scanned without splitting the data
    pos, line_no = match.end(), len(lines) + 1
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
    num_channels = sum(len(j.channels) for j in joints)
    first_data_line = line_no + 1
    offset = len(text[: pos + 1].encode("utf-8"))
    body = raw[offset:]
    values = None
    if num_channels:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # "input contained no data": diagnosed below
                values = np.loadtxt(io.BytesIO(body), dtype=np.float64, ndmin=2)
        except ValueError:
            values = None
    if (
        values is None
        or values.shape != (num_frames, num_channels)
        or not np.isfinite(values).all()
    ):
        raise _diagnose_rows(
            body.decode("utf-8", errors="replace").splitlines(),
            first_data_line,
            num_frames,
            num_channels,
            header["frames"][1],
            path,
        )
    _warn_if_cut(body, first_data_line, path)
    return _build_motion(joints, values, frame_time, path, dtype, name)


def _warn_if_cut(body: bytes, first_line: int, path: Path | None) -> None:
    """Warn when the last motion line has no line end (its last number may be cut)."""
    end = len(body)
    while end and body[end - 1] in b" \t":
        end -= 1
    if not end or body[end - 1] in b"\r\n":
        return
    start = body.rfind(b"\n", 0, end) + 1
    last = body[start:end].split()[-1].decode("utf-8", errors="replace")
    line = first_line + body.count(b"\n", 0, end)
    where = f"{printable(path) if path is not None else '<bvh text>'}:{line}"
    warnings.warn(
        f"{where}: the last motion line has no line end, so the file may be truncated "
        f"(its last value read as {last!r})",
        BVHWarning,
        stacklevel=3,
    )


#: Largest change over the clip of a channel that still counts as static (file units).
_STATIC_TOLERANCE = 1e-9


def _carrier_child(joints: list[_Joint], values: np.ndarray) -> int | None:
    """The body root under a static trajectory-carrier root, or ``None`` for ordinary files.

    The rule: the file root's channels (if any) keep one value over the whole
    clip, the root has exactly one child joint, and that child has all three
    position channels. The child then carries the world trajectory (Bandai-Namco,
    MotionBuilder exports) and is the body's root (:attr:`Skeleton.body_root`).
    """
    children = [k for k, joint in enumerate(joints) if joint.parent == 0]
    if len(children) != 1 or not set(_POS) <= set(joints[children[0]].channels):
        return None
    root_columns = values[:, : len(joints[0].channels)]
    if root_columns.size and float(np.ptp(root_columns, axis=0).max()) > _STATIC_TOLERANCE:
        return None
    return children[0]


def _build_motion(
    joints: list[_Joint],
    values: np.ndarray,
    frame_time: float,
    path: Path | None,
    dtype: torch.dtype,
    name: str | None,
) -> Motion:
    num_frames, num_joints = values.shape[0], len(joints)
    offsets = np.array([j.offset for j in joints], dtype=np.float64)
    # where each channel goes: rotation slot (joint, i) or position (joint, axis)
    orders: list[str] = []
    rot: list[tuple[int, int, int]] = []  # (column, joint, Euler slot)
    pos: list[tuple[int, int, int]] = []  # (column, joint, axis)
    col = 0
    for k, joint in enumerate(joints):
        order = ""
        for ch in joint.channels:
            if ch in _ROT:
                rot.append((col, k, len(order)))
                order += _ROT[ch]
            else:
                pos.append((col, k, _POS[ch]))
            col += 1
        orders.append(order)
    rot_cols, rot_joint, rot_slot = (list(v) for v in zip(*rot, strict=True)) if rot else ([],) * 3
    pos_cols, pos_joint, pos_axis = (list(v) for v in zip(*pos, strict=True)) if pos else ([],) * 3
    root_positions = np.repeat(offsets[None, 0], num_frames, axis=0)
    translations = None
    if pos_cols:
        local = np.repeat(offsets[None], num_frames, axis=0)
        local[:, pos_joint, pos_axis] = values[:, pos_cols]
        root_positions = local[:, 0]
        # position channels of non-root joints that only repeat their OFFSETs (six
        # channels on every joint) animate nothing: the motion is then the ordinary one
        moved = [(c, k, a) for c, k, a in pos if k > 0]
        if moved and any(not np.all(values[:, c] == offsets[k, a]) for c, k, a in moved):
            translations = local
    by_order: dict[str, list[int]] = {}
    for k, order in enumerate(orders):
        if order:
            by_order.setdefault(order, []).append(k)

    def rotations() -> torch.Tensor:
        # Euler -> quaternions runs on first use of Motion.rotations, not while reading:
        # the angles are finite (checked above), so the result is finite and unit.
        euler = np.zeros((num_frames, num_joints, 3))
        euler[:, rot_joint, rot_slot] = values[:, rot_cols]
        angles = torch.from_numpy(euler)
        quats = torch.zeros(num_frames, num_joints, 4, dtype=torch.float64)
        quats[..., 0] = 1.0
        for order, ks in by_order.items():
            if len(ks) == num_joints:  # the usual case: one order for every joint
                quats = Q.euler_to_quat(angles[..., : len(order)], order)
            else:
                quats[:, ks] = Q.euler_to_quat(angles[:, ks, : len(order)], order)
        return Q.continuity(quats, dim=0).to(dtype)

    try:
        skeleton = Skeleton(
            [j.name for j in joints],
            [j.parent for j in joints],
            offsets,
            end_sites={k: j.end_sites for k, j in enumerate(joints) if j.end_sites},
            channels=[j.channels for j in joints],
            name=name,
            body_root=_carrier_child(joints, values),
        )
    except SkeletonError as exc:
        raise BVHError(str(exc), path) from None
    return Motion._deferred(
        skeleton,
        rotations,
        torch.from_numpy(np.ascontiguousarray(root_positions)).to(dtype),
        _snap_fps(frame_time),
        translations=None
        if translations is None
        else torch.from_numpy(np.ascontiguousarray(translations)).to(dtype),
        name=name,
    )


def read_bvh(path: str | Path, dtype: torch.dtype = torch.float64) -> Motion:
    """Read a BVH file.

    Args:
        path: The ``.bvh`` file.
        dtype: Float dtype of the tensors (float64 keeps the file's precision for
            round trips; call :meth:`Motion.float` for training).

    Returns:
        The :class:`~skelagnostic.Motion`, its skeleton named after the file stem
        and carrying the file's channel layout (used by :func:`write_bvh`).

    Raises:
        BVHError: If the file is missing, unreadable or malformed; the message names
            the file and line.

    Examples:
        >>> import skelagnostic as sa, tempfile, os
        >>> motion, _ = sa.procedural.generate("biped22", "walk", seconds=0.5, fps=30)
        >>> path = os.path.join(tempfile.mkdtemp(), "walk.bvh")
        >>> sa.write_bvh(motion, path)
        >>> sa.read_bvh(path).num_frames
        16
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise BVHError("no such file", path) from None
    except IsADirectoryError:
        raise BVHError("is a directory, not a BVH file", path) from None
    except OSError as exc:
        raise BVHError(f"cannot read: {exc.strerror}", path) from None
    return parse_bvh(data, path=path, dtype=dtype, name=path.stem)


def _channels_for(motion: Motion) -> list[list[str]]:
    """Channel layout to write: the file's own where it can express the motion."""
    sk = motion.skeleton
    offsets = sk.offsets.to(motion.dtype)
    translated = {0} if bool((motion.root_positions - offsets[0]).abs().max() > 1e-9) else set()
    if motion.translations is not None:
        diff = (motion.translations - offsets).abs().amax(dim=(0, 2))
        translated |= {int(j) for j in (diff > 1e-9).nonzero().flatten()}
    channels = []
    for k in range(sk.num_joints):
        if sk.channels is not None:
            layout = list(sk.channels[k])
        else:
            layout = list(_DEFAULT_ROOT if k == 0 else _DEFAULT_JOINT)
        pos = [c for c in layout if c in _POS]
        rot = [c for c in layout if c in _ROT]
        if len(rot) != 3:  # 0-2 rotation axes cannot carry an arbitrary rotation
            rot = list(_DEFAULT_JOINT)
            layout = pos + rot
        if k in translated and len(pos) != 3:
            layout = _DEFAULT_ROOT[:3] + rot
        channels.append(layout)
    return channels


def write_bvh(motion: Motion, path: str | Path, precision: int = 6) -> None:
    """Write a motion as a BVH file (atomically: the file appears only when complete).

    The channel layout read from a BVH file is kept; other motions get position
    channels on the root (and on any joint with animated translations) and
    ``Zrotation Yrotation Xrotation`` on every joint. Euler angles are unwrapped
    along time so curves stay continuous.

    A new file gets the permissions the umask allows (``0o644`` under umask
    ``022``), an existing one keeps its own; a symbolic link is written through
    (the file it points to is replaced, the link stays).

    Args:
        motion: The motion.
        path: Target file.
        precision: Decimals written for every value.

    Raises:
        BVHError: If the file cannot be written (missing or read-only directory, full
            disk, symbolic link loop, ...); the target is then left untouched.
    """
    path = Path(path)
    sk = motion.skeleton
    m = motion.double()
    channels = _channels_for(m)
    offsets = sk.offsets.double().numpy()
    fmt = f"%.{precision}f"
    out: list[str] = ["HIERARCHY"]
    children: dict[int, list[int]] = {}
    for c, p in enumerate(sk.parents):
        children.setdefault(p, []).append(c)

    # depth-first with an explicit stack (no recursion: any depth can be written);
    # an entry (joint, depth, False) opens the joint, (joint, depth, True) closes it
    stack: list[tuple[int, int, bool]] = [(0, 0, False)]
    while stack:
        j, depth, closing = stack.pop()
        pad = "\t" * min(depth, _MAX_INDENT)
        if closing:
            for site in sk.end_sites.get(j, []):
                out.append(f"{pad}\tEnd Site")
                out.append(f"{pad}\t{{")
                out.append(f"{pad}\t\tOFFSET " + " ".join(fmt % v for v in site))
                out.append(f"{pad}\t}}")
            out.append(f"{pad}}}")
            continue
        out.append(f"{pad}{'ROOT' if j == 0 else 'JOINT'} {sk.joint_names[j]}")
        out.append(f"{pad}{{")
        out.append(f"{pad}\tOFFSET " + " ".join(fmt % v for v in offsets[j]))
        out.append(f"{pad}\tCHANNELS {len(channels[j])} " + " ".join(channels[j]))
        stack.append((j, depth, True))
        stack.extend((c, depth + 1, False) for c in reversed(children.get(j, [])))
    num_frames = m.num_frames
    out.append("MOTION")
    out.append(f"Frames: {num_frames}")
    out.append(f"Frame Time: {_format_frame_time(1.0 / m.fps)}")
    columns: list[np.ndarray] = []
    root = m.root_positions.numpy()
    trans = None if m.translations is None else m.translations.numpy()
    eulers: dict[int, np.ndarray] = {}
    by_order: dict[str, list[int]] = {}
    for k, layout in enumerate(channels):
        order = "".join(_ROT[c] for c in layout if c in _ROT)
        by_order.setdefault(order, []).append(k)
    for order, ks in by_order.items():
        ang = Q.quat_to_euler(m.rotations[:, ks], order).numpy()
        ang = np.unwrap(ang, period=360.0, axis=0)
        for i, k in enumerate(ks):
            eulers[k] = ang[:, i]
    for k, layout in enumerate(channels):
        r = 0
        for ch in layout:
            if ch in _ROT:
                columns.append(eulers[k][:, r])
                r += 1
            else:
                axis = _POS[ch]
                if k == 0:
                    columns.append(root[:, axis])
                elif trans is not None:
                    columns.append(trans[:, k, axis])
                else:
                    columns.append(np.full(num_frames, offsets[k, axis]))
    table = np.stack(columns, axis=1) if columns else np.zeros((num_frames, 0))
    table = np.where(np.abs(table) < 0.5 * 10.0**-precision, 0.0, table)  # no "-0.000000"
    row_fmt = " ".join([fmt] * table.shape[1])
    out.extend(row_fmt % tuple(row) for row in table.tolist())
    text = "\n".join(out) + "\n"
    try:
        atomic_write(path, text.encode("utf-8"))
    except OSError as exc:
        raise BVHError(f"cannot write: {exc.strerror or exc}", path) from None
