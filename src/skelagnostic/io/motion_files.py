"""Motion files by suffix: BVH (``.bvh``) or glTF 2.0 (``.glb``, ``.gltf``).

:mod:`skelagnostic.io.bvh` reads and writes the first, :mod:`skelagnostic.io.gltf`
the others.

The verbs that read or write motion (``retarget``, ``interpolate``, ``transfer``,
``demo``) go through :func:`read_motion` and :func:`write_motion`, so that every
one of them takes the same formats.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from skelagnostic.errors import SkelagnosticError, printable

if TYPE_CHECKING:
    import torch

    from skelagnostic.core.motion import Motion

__all__ = ["MOTION_SUFFIXES", "motion_format", "read_motion", "write_motion"]

#: Suffixes of the motion files skelagnostic reads and writes.
MOTION_SUFFIXES = (".bvh", ".glb", ".gltf")


def motion_format(path: str | Path, other: str | None = None) -> str:
    """The format of a motion file from its suffix (any case).

    Args:
        path: The file name.
        other: ``"bvh"`` or ``"gltf"``: the format of a file with any other suffix
            (``None``: such a file is an error).

    Returns:
        ``"bvh"`` or ``"gltf"``.

    Raises:
        SkelagnosticError: If the suffix is none of :data:`MOTION_SUFFIXES`.

    Examples:
        >>> motion_format("walk.BVH"), motion_format("walk.glb"), motion_format("a.gltf")
        ('bvh', 'gltf', 'gltf')
    """
    suffix = Path(path).suffix.lower()
    if suffix not in MOTION_SUFFIXES and other is not None:
        return other
    if suffix not in MOTION_SUFFIXES:
        raise SkelagnosticError(
            f"{printable(path)}: a motion file ends in .bvh (BVH) or .glb/.gltf (glTF 2.0), "
            f"not {printable(Path(path).suffix or 'nothing')!r}"
        )
    return "bvh" if suffix == ".bvh" else "gltf"


def read_motion(
    path: str | Path,
    dtype: torch.dtype | None = None,
    other: str | None = None,
    up: str | None = None,
    forward: str | None = None,
) -> Motion:
    """Read a ``.bvh``, ``.glb`` or ``.gltf`` file.

    :func:`~skelagnostic.read_bvh` or :func:`~skelagnostic.read_gltf` does the work.

    Args:
        path: The file.
        dtype: Float dtype of the tensors (default float64).
        other: ``"bvh"`` or ``"gltf"``: how to read a file with any other suffix
            (``None``: such a file is an error). The renderers read any name that
            is not ``.glb``/``.gltf`` as BVH, as they always have.
        up: The file's up axis (``x, y, z, -x, -y, -z`` or ``"auto"``; ``None``: the
            reader's default); the motion comes in the canonical frame, +Y up,
            facing +Z (:mod:`skelagnostic.core.axes`).
        forward: The file's forward axis, ``"auto"`` or ``None``.

    Returns:
        The motion.

    Raises:
        SkelagnosticError: An unknown suffix, or the reader's ``BVHError`` /
            ``GLTFError`` / ``AxesError``.
    """
    import torch

    dtype = torch.float64 if dtype is None else dtype
    if motion_format(path, other) == "bvh":
        from skelagnostic.io.bvh import read_bvh

        return read_bvh(path, dtype=dtype, up=up, forward=forward)
    from skelagnostic.io.gltf import read_gltf

    return read_gltf(path, dtype=dtype, up=up, forward=forward)


def write_motion(
    motion: Motion, path: str | Path, up: str | None = None, forward: str | None = None
) -> None:
    """Write a motion in the format its suffix names, atomically.

    Args:
        motion: The motion.
        path: A ``.bvh``, ``.glb`` or ``.gltf`` path.
        up: The file's up axis (``None``: ``"y"``); the motion is turned from the
            canonical frame into it.
        forward: The file's forward axis (``None``: the usual one for ``up``).

    Raises:
        SkelagnosticError: An unknown suffix, or the writer's ``BVHError`` /
            ``GLTFError`` (a glTF file without the ``gltf`` extra installed, a
            directory that cannot be written, ...), or ``AxesError`` for a bad
            ``up``/``forward``.
    """
    if motion_format(path) == "bvh":
        from skelagnostic.io.bvh import write_bvh

        write_bvh(motion, path, up=up, forward=forward)
    else:
        from skelagnostic.io.gltf import write_gltf

        write_gltf(motion, path, up=up, forward=forward)
