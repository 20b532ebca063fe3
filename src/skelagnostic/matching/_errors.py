"""The error raised by :mod:`skelagnostic.matching` on bad input."""

from __future__ import annotations

from skelagnostic.errors import SkelagnosticError


class MatchingError(SkelagnosticError, ValueError):
    """Invalid motion-matching input: empty database, mismatched feature sizes, NaN values.

    The message always names the offending argument or feature group.
    """
