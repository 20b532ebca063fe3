"""Exception hierarchy shared by every layer of skelagnostic.

Every error a user can trigger with bad input derives from
:class:`SkelagnosticError`, so callers (and the CLI) can catch one type and
print a one-line message instead of a traceback.
"""

from __future__ import annotations

from pathlib import Path


class SkelagnosticError(Exception):
    """Base class of every error skelagnostic raises on bad input or configuration."""


class SkeletonError(SkelagnosticError, ValueError):
    """An invalid skeleton: bad parents, duplicate or unknown joints, zero-length bones."""


class MotionError(SkelagnosticError, ValueError):
    """Invalid motion data: wrong shapes, NaN/inf values, mismatched skeletons."""


class BVHError(SkelagnosticError, ValueError):
    """A BVH file that cannot be read or written.

    The message always names the file and, when known, the 1-based line at fault.

    Attributes:
        path: The file being read or written (``None`` for in-memory text).
        line: 1-based line number of the problem, or ``None``.
        reason: The problem, without the location prefix.
    """

    def __init__(self, reason: str, path: str | Path | None = None, line: int | None = None):
        self.path = None if path is None else Path(path)
        self.line = line
        self.reason = reason
        where = str(self.path) if self.path is not None else "<bvh text>"
        if line is not None:
            where += f":{line}"
        super().__init__(f"{where}: {reason}")


class NotInvertibleError(SkelagnosticError):
    """A motion representation cannot be decoded back to a :class:`~skelagnostic.Motion`."""
