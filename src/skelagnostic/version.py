"""Versions from the installed distributions' metadata (the one version source).

The version of skelagnostic is the ``version`` of ``pyproject.toml``, read back from
the installed distribution's metadata with :mod:`importlib.metadata`; nothing else
in the sources spells it. Plugin packages report the version of the distribution
that ships them: the built-in methods ship in ``skelagnostic``, a third-party
plugin in its own distribution::

    from skelagnostic.version import distribution_version

    __version__ = distribution_version("skelagnostic-myplugin")
"""

from __future__ import annotations

from importlib import metadata

#: Reported when the distribution is not installed (sources put on ``sys.path`` by
#: hand): a PEP 440 version lower than any release, so it is never mistaken for one.
UNKNOWN_VERSION = "0+unknown"


def distribution_version(name: str) -> str:
    """The version of the installed distribution ``name``.

    Args:
        name: Distribution name as in ``pyproject.toml`` (``"skelagnostic"``,
            ``"skelagnostic-example-aligner"``); ``-``/``_`` and case do not matter.

    Returns:
        Its version, or :data:`UNKNOWN_VERSION` when it is not installed.

    Examples:
        >>> from skelagnostic.version import distribution_version
        >>> distribution_version("no-such-distribution-x")
        '0+unknown'
    """
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return UNKNOWN_VERSION
