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

The file's syntax (tokens, hierarchy, MOTION header, rows and their diagnosis) is
read by :mod:`skelagnostic.io._bvh_syntax`; this module turns it into a motion.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import torch

from skelagnostic.core import quaternion as Q
from skelagnostic.core.axes import from_canonical, to_canonical
from skelagnostic.core.motion import Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.errors import BVHError, SkeletonError, printable
from skelagnostic.io import _bvh_syntax as syntax
from skelagnostic.io.atomic import atomic_write

__all__ = ["BVHWarning", "parse_bvh", "read_bvh", "write_bvh"]


class BVHWarning(UserWarning):
    """A BVH file that reads but looks damaged (its last motion line has no line end)."""


_DEFAULT_ROOT = ["Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation"]
_DEFAULT_JOINT = ["Zrotation", "Yrotation", "Xrotation"]
#: Indentation stops growing at this depth (a 10,000-level chain would otherwise
#: write 50 million tabs).
_MAX_INDENT = 32


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
    raw, text = syntax.decode(data, path)
    match = syntax.MOTION.search(text)
    lines = (text if match is None else text[: match.start()]).splitlines()
    if match is None and not any(line.strip() for line in lines):
        raise BVHError("the file is empty", path, 1)
    tokens = syntax.Tokens(lines, path)
    joints = syntax.parse_hierarchy(tokens)
    if match is None:
        raise BVHError("no MOTION section (truncated file?)", path, len(lines))
    header, pos, line_no = syntax.motion_header(text, match.end(), len(lines) + 1, path)
    num_frames = syntax.parse_frame_count(header, path)
    frame_time = syntax.parse_frame_time(header, path)
    num_channels = sum(len(j.channels) for j in joints)
    first_data_line = line_no + 1
    offset = len(text[: pos + 1].encode("utf-8"))
    body = raw[offset:]
    values = syntax.read_values(body, num_channels)
    if (
        values is None
        or values.shape != (num_frames, num_channels)
        or not np.isfinite(values).all()
    ):
        raise syntax.diagnose_rows(
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


def _carrier_child(joints: list[syntax.Joint], values: np.ndarray) -> int | None:
    """The body root under a static trajectory-carrier root, or ``None`` for ordinary files.

    The rule: the file root's channels (if any) keep one value over the whole
    clip, the root has exactly one child joint, and that child has all three
    position channels. The child then carries the world trajectory (Bandai-Namco,
    MotionBuilder exports) and is the body's root (:attr:`Skeleton.body_root`).
    """
    children = [k for k, joint in enumerate(joints) if joint.parent == 0]
    if len(children) != 1 or not set(syntax.POSITIONS) <= set(joints[children[0]].channels):
        return None
    root_columns = values[:, : len(joints[0].channels)]
    if root_columns.size and float(np.ptp(root_columns, axis=0).max()) > _STATIC_TOLERANCE:
        return None
    return children[0]


def _build_motion(
    joints: list[syntax.Joint],
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
            if ch in syntax.ROTATIONS:
                rot.append((col, k, len(order)))
                order += syntax.ROTATIONS[ch]
            else:
                pos.append((col, k, syntax.POSITIONS[ch]))
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


def read_bvh(
    path: str | Path,
    dtype: torch.dtype = torch.float64,
    up: str | None = None,
    forward: str | None = None,
) -> Motion:
    """Read a BVH file.

    Args:
        path: The ``.bvh`` file.
        dtype: Float dtype of the tensors (float64 keeps the file's precision for
            round trips; call :meth:`Motion.float` for training).
        up: The file's up axis (``x, y, z, -x, -y, -z``; ``"auto"`` detects it from
            the motion); the motion is turned into the canonical frame (+Y up,
            facing +Z). ``None``: ``"y"``, as BVH files usually are
            (:mod:`skelagnostic.core.axes`).
        forward: The file's forward axis, or ``"auto"``; ``None``: the usual one
            for ``up`` (``"z"`` for Y up, ``"-y"`` for Blender's Z up).

    Returns:
        The :class:`~skelagnostic.Motion`, its skeleton named after the file stem
        and carrying the file's channel layout (used by :func:`write_bvh`).

    Raises:
        BVHError: If the file is missing, unreadable or malformed; the message names
            the file and line.
        AxesError: A bad ``up``/``forward``, or axes ``"auto"`` cannot tell; the
            message names the file and the argument.

    Examples:
        >>> import skelagnostic as sa, tempfile, os
        >>> motion, _ = sa.procedural.generate("biped22", "walk", seconds=0.5, fps=30)
        >>> path = os.path.join(tempfile.mkdtemp(), "walk.bvh")
        >>> sa.write_bvh(motion, path)
        >>> sa.read_bvh(path).num_frames
        16
        >>> sa.write_bvh(motion, path, up="z")  # Blender's frame: Z up, facing -Y
        >>> z_up = sa.read_bvh(path, up="z")
        >>> bool((z_up.global_positions() - motion.global_positions()).abs().max() < 1e-5)
        True
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
    motion = parse_bvh(data, path=path, dtype=dtype, name=path.stem)
    return to_canonical(motion, up, forward, where=path)[0]


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
        pos = [c for c in layout if c in syntax.POSITIONS]
        rot = [c for c in layout if c in syntax.ROTATIONS]
        if len(rot) != 3:  # 0-2 rotation axes cannot carry an arbitrary rotation
            rot = list(_DEFAULT_JOINT)
            layout = pos + rot
        if k in translated and len(pos) != 3:
            layout = _DEFAULT_ROOT[:3] + rot
        channels.append(layout)
    return channels


def write_bvh(
    motion: Motion,
    path: str | Path,
    precision: int = 6,
    up: str | None = None,
    forward: str | None = None,
) -> None:
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
        up: The file's up axis (``x, y, z, -x, -y, -z``; ``None``: ``"y"``): the
            motion is turned from the canonical frame into the file's
            (:func:`~skelagnostic.core.axes.from_canonical`).
        forward: The file's forward axis (``None``: the usual one for ``up``).

    Raises:
        BVHError: If the file cannot be written (missing or read-only directory, full
            disk, symbolic link loop, ...); the target is then left untouched.
        AxesError: A bad ``up``/``forward`` (nothing is written).
    """
    path = Path(path)
    m = from_canonical(motion, up, forward).double()
    sk = m.skeleton
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
        order = "".join(syntax.ROTATIONS[c] for c in layout if c in syntax.ROTATIONS)
        by_order.setdefault(order, []).append(k)
    for order, ks in by_order.items():
        ang = Q.quat_to_euler(m.rotations[:, ks], order).numpy()
        ang = np.unwrap(ang, period=360.0, axis=0)
        for i, k in enumerate(ks):
            eulers[k] = ang[:, i]
    for k, layout in enumerate(channels):
        r = 0
        for ch in layout:
            if ch in syntax.ROTATIONS:
                columns.append(eulers[k][:, r])
                r += 1
            else:
                axis = syntax.POSITIONS[ch]
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
