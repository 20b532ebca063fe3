"""A motion file's up and forward axes: parsing, detection and the change to the canonical frame.

The package works in one canonical frame: **+Y up, the character facing +Z, its
left +X** (right-handed; the frame of BVH files and of glTF). A file written in
another frame (Blender's Z up, a Z-up mocap export) is described by two signed
axes, ``up`` and ``forward``, each one of ``x, y, z, -x, -y, -z``; the third axis,
the character's left, is ``up x forward``. :func:`to_canonical` turns such a
motion into the canonical frame by a change of basis (rest offsets, End Sites,
root path, animated translations and every local rotation), so that forward
kinematics, templates, metrics and the plugins see the same upright character
whatever the file's frame; :func:`from_canonical` is its inverse, for writers.

``"auto"`` asks the motion: :func:`detect_up` takes the mean direction from the
feet to the spine over the clip, :func:`detect_forward` the direction the rest
pose faces (the left-to-right vector of hips and shoulders crossed with up).
Either raises :class:`AxesError` explaining why when the answer is ambiguous.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import torch

from skelagnostic.core.motion import Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.errors import SkelagnosticError, printable

__all__ = [
    "AXES",
    "CANONICAL_FORWARD",
    "CANONICAL_UP",
    "AxesError",
    "FileAxes",
    "axes_matrix",
    "default_forward",
    "detect_forward",
    "detect_up",
    "from_canonical",
    "parse_axis",
    "resolve_axes",
    "to_canonical",
]

#: The signed axis names an ``up=`` or ``forward=`` argument accepts (``"+x"`` is ``"x"``).
AXES = ("x", "y", "z", "-x", "-y", "-z")
#: The package's up and forward axes.
CANONICAL_UP, CANONICAL_FORWARD = "y", "z"
#: The forward axis of each up axis when ``forward`` is not given: canonical +Z carried
#: by the smallest rotation taking +Y to that up (Blender's Z up gives -Y forward).
_DEFAULT_FORWARD = {"y": "z", "-y": "z", "z": "-y", "-z": "y", "x": "z", "-x": "z"}
#: Largest angle (degrees) between a detected direction and the axis it is snapped to.
MAX_DETECTION_ANGLE = 30.0


class AxesError(SkelagnosticError, ValueError):
    """A bad ``up=``/``forward=`` value, or axes that cannot be detected from the motion."""


@dataclass(frozen=True)
class FileAxes:
    """The axes of a file and how they were found.

    Attributes:
        up: The file's up axis (a name of :data:`AXES`).
        forward: The file's forward axis.
        how: How each was found, by argument name: ``"given"``, ``"default"``
            or a sentence on the detection (``"detected: ..."``).
    """

    up: str
    forward: str
    how: tuple[tuple[str, str], ...] = ()

    @property
    def detected(self) -> bool:
        """Whether either axis was detected from the motion."""
        return any(h.startswith("detected") for _, h in self.how)

    def describe(self) -> str:
        """One line: ``"up z, forward -y (up detected: ...)"``."""
        text = f"up {self.up}, forward {self.forward}"
        notes = [f"{name} {h}" for name, h in self.how if h.startswith("detected")]
        return f"{text} ({'; '.join(notes)})" if notes else text


def parse_axis(value: object, argument: str, auto: bool = False) -> str:
    """A signed axis name, checked: ``"x"``, ``"-y"``, ... (``"+z"`` and any case accepted).

    Args:
        value: The value given.
        argument: The argument's name for the message (``"up"``, ``"data.forward"``).
        auto: Whether ``"auto"`` is accepted (readers), or not (writers).

    Raises:
        AxesError: ``value`` names no axis; the message names ``argument``.

    Examples:
        >>> parse_axis("+Z", "up"), parse_axis("-y", "forward")
        ('z', '-y')
    """
    text = value.strip().lower() if isinstance(value, str) else value
    if isinstance(text, str) and text.startswith("+"):
        text = text[1:]
    if text in AXES or (auto and text == "auto"):
        return str(text)
    accepted = ", ".join(AXES) + (" or auto" if auto else "")
    raise AxesError(f"{argument}={value!r} is not an axis; accepted: {accepted}")


def default_forward(up: str) -> str:
    """The forward axis assumed when none is given: ``"z"`` for Y up, ``"-y"`` for Z up."""
    return _DEFAULT_FORWARD[parse_axis(up, "up")]


def _vector(axis: str) -> torch.Tensor:
    v = torch.zeros(3, dtype=torch.float64)
    v["xyz".index(axis[-1])] = -1.0 if axis.startswith("-") else 1.0
    return v


def _name(v: torch.Tensor) -> str:
    i = int(v.abs().argmax())
    return ("-" if v[i] < 0 else "") + "xyz"[i]


def axes_matrix(up: str, forward: str) -> torch.Tensor:
    """``[3, 3]`` rotation taking vectors of a file with these axes to the canonical frame.

    Its rows are the file's left (``up x forward``), up and forward axes, so
    ``R @ up`` is +Y and ``R @ forward`` is +Z. A signed permutation: exact in floats.

    Raises:
        AxesError: A name is not in :data:`AXES`, or ``up`` and ``forward`` share an axis.
    """
    up, forward = parse_axis(up, "up"), parse_axis(forward, "forward")
    if up[-1] == forward[-1]:
        raise AxesError(
            f"up={up!r} and forward={forward!r} lie on the same axis; forward must be "
            "perpendicular to up"
        )
    u, f = _vector(up), _vector(forward)
    return torch.stack([torch.linalg.cross(u, f), u, f])


def _change_basis(motion: Motion, matrix: torch.Tensor, up_axis: str, regroup: bool) -> Motion:
    """``motion`` with every vector multiplied by ``matrix`` (a rotation) and rotations conjugated.

    ``regroup`` infers the body groups again (the file frame's left/right guess was
    made with the wrong lateral axis); otherwise they are kept.
    """
    sk = motion.skeleton
    r = matrix.to(dtype=sk.offsets.dtype, device=sk.offsets.device)
    end_sites = {
        j: (torch.tensor(v, dtype=torch.float64) @ matrix.T).tolist()
        for j, v in sk.end_sites.items()
    }
    skeleton = Skeleton(
        sk.joint_names,
        sk.parents,
        sk.offsets @ r.T,
        end_sites=end_sites,
        body_groups=None if regroup else sk.body_groups,
        up_axis=up_axis,
        name=sk.name,
        morphology=sk.morphology,
        channels=sk.channels,
        body_root=sk.body_root,
    )
    m = matrix.to(dtype=motion.dtype, device=motion.device)
    rot = motion.rotations
    # R q R^-1 of a unit quaternion (w, v) is (w, R v)
    rotations = torch.cat([rot[..., :1], rot[..., 1:] @ m.T], dim=-1)
    trans = motion.translations
    return motion._replace(
        skeleton=skeleton,
        rotations=rotations,
        root_positions=motion.root_positions @ m.T,
        translations=None if trans is None else trans @ m.T,
    )


def _feet_and_spine(skeleton: Skeleton) -> tuple[list[int], list[int]]:
    """The feet (leg end effectors; a quadruped's arm ones too) and the spine joints."""
    groups = skeleton.body_groups
    legs = {"left_leg", "right_leg"}
    if skeleton.morphology == "quadruped":
        legs |= {"left_arm", "right_arm"}
    feet = [j for j in skeleton.end_effectors() if groups[j] in legs]
    spine = [j for j, g in enumerate(groups) if g == "spine"]
    return feet, spine


def _snap(v: torch.Tensor, what: str, argument: str, hint: str) -> tuple[str, float]:
    """The signed axis nearest ``v`` and the angle to it, or :class:`AxesError` past the limit."""
    import math

    n = float(v.norm())
    if not math.isfinite(n) or n < 1e-9:
        raise AxesError(f"{argument}='auto': {what} has no direction (zero length); {hint}")
    unit = v / n
    axis = _name(unit)
    angle = math.degrees(math.acos(min(1.0, float(unit.abs().max()))))
    if angle > MAX_DETECTION_ANGLE:
        shown = ", ".join(f"{c:.2f}" for c in unit.tolist())
        raise AxesError(
            f"{argument}='auto': ambiguous: {what} is ({shown}), {angle:.0f} degrees from the "
            f"nearest axis {axis} (at most {MAX_DETECTION_ANGLE:g} accepted); {hint}"
        )
    return axis, angle


def detect_up(motion: Motion) -> tuple[str, str]:
    """The up axis of ``motion``'s frame: where the spine is above the feet on average.

    The mean over frames of the vector from the mean foot position (the end
    effectors of the legs; a quadruped's front paws too) to the mean of the spine
    joints, snapped to the nearest signed axis.

    Returns:
        The axis name and a sentence on how it was found.

    Raises:
        AxesError: No feet or spine joints, or the direction is more than
            :data:`MAX_DETECTION_ANGLE` degrees from every axis (a clip lying or
            crawling on the ground); the message shows the direction.
    """
    hint = "pass up= (one of x, y, z, -x, -y, -z)"
    feet, spine = _feet_and_spine(motion.skeleton)
    if not feet or not spine:
        raise AxesError(
            f"up='auto': the skeleton {motion.skeleton!r} has no "
            f"{'leg end joints' if not feet else 'spine joints'} to tell up from; {hint}"
        )
    pos = motion.global_positions().detach().double().cpu()
    v = (pos[:, spine].mean(1) - pos[:, feet].mean(1)).mean(0)
    axis, angle = _snap(v, "the mean direction from the feet to the spine", "up", hint)
    return axis, f"detected: the spine above the feet, {angle:.0f} degrees off"


def detect_forward(motion: Motion, up: str) -> tuple[str, str]:
    """The forward axis of ``motion``'s file: the direction its rest pose faces.

    The rest pose's left-to-right vector (left minus right hip, plus left minus
    right shoulder: the first joint of each limb group) crossed with ``up``,
    snapped to the nearest axis perpendicular to ``up``. The rest pose is the
    file's own convention (a T-pose faces the file's forward); a file whose rest
    pose faces elsewhere (LaFAN1's and the MANN dog's face -X) gives that
    direction, so pass ``forward=`` for those.

    Returns:
        The axis name and a sentence on how it was found.

    Raises:
        AxesError: No left/right limb pairs, or the facing direction is more than
            :data:`MAX_DETECTION_ANGLE` degrees from every axis.
    """
    hint = "pass forward= (an axis perpendicular to up)"
    sk = motion.skeleton
    rest = sk.rest_positions().detach().double().cpu()
    lengths = sk.bone_lengths()
    starts: dict[str, int] = {}
    for j, g in enumerate(sk.body_groups):
        if g not in starts and g.startswith(("left_", "right_")) and lengths[j] > 0:
            starts[g] = j
    across = torch.zeros(3, dtype=torch.float64)
    for limb in ("arm", "leg"):
        left, right = starts.get(f"left_{limb}"), starts.get(f"right_{limb}")
        if left is not None and right is not None:
            across = across + rest[left] - rest[right]
    u = _vector(parse_axis(up, "up"))
    across = across - across.dot(u) * u
    if float(across.norm()) < 1e-9:
        raise AxesError(
            f"forward='auto': the rest pose of {sk!r} has no left/right hips or shoulders "
            f"apart across the up axis {up}; {hint}"
        )
    axis, angle = _snap(torch.linalg.cross(across, u), "the rest pose's facing", "forward", hint)
    return axis, f"detected: the rest pose's hips and shoulders, {angle:.0f} degrees off"


def resolve_axes(
    motion: Motion,
    up: str | None = None,
    forward: str | None = None,
    prefix: str = "",
    where: str | Path | None = None,
) -> FileAxes:
    """The file axes ``up`` and ``forward`` name, detecting ``"auto"`` ones from ``motion``.

    Args:
        motion: The motion as read, in the file's frame.
        up: An axis of :data:`AXES`, ``"auto"``, or ``None`` for the skeleton's
            recorded ``up_axis`` (``"y"`` for every BVH file).
        forward: An axis, ``"auto"``, or ``None`` for :func:`default_forward` of ``up``.
        prefix: Prefix of the argument names in messages (``"data."``).
        where: The file, named first in messages.

    Raises:
        AxesError: A bad value, ``up`` and ``forward`` on one axis, or a detection
            that fails (see :func:`detect_up`, :func:`detect_forward`).
    """
    how: list[tuple[str, str]] = []
    try:
        up_arg = parse_axis(up, f"{prefix}up", auto=True) if up is not None else None
        fwd_arg = (
            parse_axis(forward, f"{prefix}forward", auto=True) if forward is not None else None
        )
        if up_arg == "auto":
            up_axis, note = detect_up(motion)
        else:
            up_axis = up_arg or motion.skeleton.up_axis
            note = "given" if up_arg else "default"
        how.append(("up", note))
        if fwd_arg == "auto":
            fwd_axis, note = detect_forward(motion, up_axis)
        else:
            fwd_axis = fwd_arg or default_forward(up_axis)
            note = "given" if fwd_arg else "default"
        how.append(("forward", note))
        axes_matrix(up_axis, fwd_axis)
    except AxesError as exc:
        text = str(exc)
        text = prefix + text if prefix and not text.startswith(prefix) else text
        raise AxesError(f"{printable(where)}: {text}" if where is not None else text) from None
    return FileAxes(up_axis, fwd_axis, tuple(how))


def to_canonical(
    motion: Motion,
    up: str | None = None,
    forward: str | None = None,
    prefix: str = "",
    where: str | Path | None = None,
) -> tuple[Motion, FileAxes]:
    """``motion`` (in its file's frame) turned into the canonical frame, and the file's axes.

    Args:
        motion: A motion as read from a file.
        up: The file's up axis, ``"auto"`` or ``None`` (see :func:`resolve_axes`).
        forward: The file's forward axis, ``"auto"`` or ``None``.
        prefix: Prefix of the argument names in messages.
        where: The file, named first in messages.

    Returns:
        The motion in the canonical frame (its skeleton's ``up_axis`` is ``"y"``; the
        body groups are inferred again in that frame) and the :class:`FileAxes`.
        A file already in the canonical frame is returned as it is.

    Raises:
        AxesError: See :func:`resolve_axes`.

    Examples:
        >>> from skelagnostic import procedural
        >>> motion, _ = procedural.generate("biped22", "walk", seconds=0.5, fps=30)
        >>> z_up = from_canonical(motion, up="z", forward="y")
        >>> back, axes = to_canonical(z_up, up="auto", forward="auto")
        >>> axes.up, axes.forward
        ('z', 'y')
        >>> bool((back.global_positions() - motion.global_positions()).abs().max() < 1e-9)
        True
    """
    axes = resolve_axes(motion, up, forward, prefix, where)
    if (axes.up, axes.forward) == (CANONICAL_UP, CANONICAL_FORWARD):
        if motion.skeleton.up_axis == CANONICAL_UP:
            return motion, axes
    return _change_basis(motion, axes_matrix(axes.up, axes.forward), CANONICAL_UP, True), axes


def from_canonical(motion: Motion, up: str | None = None, forward: str | None = None) -> Motion:
    """``motion`` (in the canonical frame) expressed in a file frame with these axes.

    The inverse of :func:`to_canonical`: writing with ``up="z"`` and reading the
    file back with ``up="z"`` gives the motion back. A motion whose skeleton
    records another ``up_axis`` is taken to be in that frame (with
    :func:`default_forward`).

    Args:
        motion: The motion.
        up: The file's up axis (``None``: ``"y"``); ``"auto"`` is not accepted.
        forward: The file's forward axis (``None``: :func:`default_forward` of ``up``).

    Returns:
        The motion in the file's frame; its skeleton's ``up_axis`` is the letter of
        ``up`` (``"y"`` for a negative up, which the skeleton cannot record).

    Raises:
        AxesError: A bad or ``"auto"`` value, or ``up`` and ``forward`` on one axis.
    """
    up = parse_axis(up, "up") if up is not None else CANONICAL_UP
    forward = parse_axis(forward, "forward") if forward is not None else default_forward(up)
    target = axes_matrix(up, forward)
    current = motion.skeleton.up_axis
    source = axes_matrix(current, default_forward(current))
    matrix = target.T @ source
    if torch.equal(matrix, torch.eye(3, dtype=matrix.dtype)):
        return motion
    return _change_basis(motion, matrix, up if len(up) == 1 else CANONICAL_UP, False)
