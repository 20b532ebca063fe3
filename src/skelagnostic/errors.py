"""Exception hierarchy shared by every layer of skelagnostic.

Every error a user can trigger with bad input derives from
:class:`SkelagnosticError`, so callers (and the CLI) can catch one type and
print a one-line message instead of a traceback.
"""

from __future__ import annotations

import re
from pathlib import Path

#: Characters a message never shows raw: C0 controls (newline, tab, ESC ...), DEL, C1
#: controls (CSI, NEL ...), the Unicode line and paragraph separators, and the
#: bidirectional marks, embeddings, overrides and isolates (U+202E shows the rest of a
#: name reversed: "clip\u202egpj.bvh" looks like "clipsvb.jpg").
_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f\u200e\u200f\u2028-\u202e\u2066-\u2069]")


def printable(text: object) -> str:
    r"""``str(text)`` with each control character written as its Python escape.

    File names, joint names and configuration values reach error messages; a
    control character in one could move the cursor, clear the screen or set
    the terminal's title (``ESC [2J``, ``ESC ]0;...BEL``), or split a one-line
    error in two. They are shown as :func:`repr` shows them (``\x1b``, ``\n``,
    ``\x9b``, ``\u2028``); every other character, backslashes included, is
    kept as it is.

    Args:
        text: A message, a path or a name.

    Returns:
        One line without control characters.

    Examples:
        >>> printable("clip\x1b[2J\nname.bvh")
        'clip\\x1b[2J\\nname.bvh'
    """
    return _CONTROL.sub(lambda match: repr(match.group())[1:-1], str(text))


def error_line(prog: str, message: object) -> str:
    """The one line the command line prints for an error: ``<prog>: error: <message>``.

    Args:
        prog: The command, e.g. ``"skelagnostic render"``.
        message: The error (an exception or a text); control characters are
            escaped (:func:`printable`), so the line stays one line.

    Returns:
        The line, without a line end.
    """
    return f"{prog}: error: {printable(message)}"


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
        where = printable(self.path) if self.path is not None else "<bvh text>"
        if line is not None:
            where += f":{line}"
        super().__init__(f"{where}: {reason}")


class ConfigError(SkelagnosticError):
    """A run configuration that cannot work (bad task, unknown options, missing packages).

    Raised by the builders of :mod:`skelagnostic.cli.build` and the task functions of
    :mod:`skelagnostic.cli.tasks`; defined here so that modules that only report it
    (the Hydra application's error handling) need not import the training stack.
    """


class NotInvertibleError(SkelagnosticError):
    """A motion representation cannot be decoded back to a :class:`~skelagnostic.Motion`."""


class GLTFError(SkelagnosticError, ValueError):
    """A glTF file that cannot be read or written, or a missing ``gltf`` extra.

    The message names the file and, when known, the glTF field at fault
    (``animations[0].samplers[3].output``).

    Attributes:
        path: The file being read or written (``None`` when there is none).
        field: The glTF field at fault, or ``None``.
        reason: The problem, without the location prefix.
    """

    def __init__(self, reason: str, path: str | Path | None = None, field: str | None = None):
        self.path = None if path is None else Path(path)
        self.field = field
        self.reason = reason
        where = printable(self.path) if self.path is not None else "<gltf>"
        if field is not None:
            where += f": {printable(field)}"
        super().__init__(f"{where}: {reason}")
