"""Detect a folder named ``skelagnostic`` that hides the installed package.

Run from a folder that holds a checkout named ``skelagnostic`` (``python -m pytest``,
``python -m skelagnostic.cli``, ``PYTHONPATH=.``), ``import skelagnostic`` finds that
folder first: it has no ``__init__.py``, so Python makes it an empty namespace package.
With an editable install the submodules still load (the install's finder maps them),
so ``skelagnostic.testing`` and the CLI start, but the top-level API is missing and
the errors that follow do not say why. :func:`shadowing_folder` finds that case;
:func:`check_not_shadowed` says it in one line.
"""

from __future__ import annotations

import sys
from pathlib import Path

__all__ = ["ShadowedPackageError", "check_not_shadowed", "shadowing_folder"]


class ShadowedPackageError(ImportError):
    """``import skelagnostic`` found a folder without ``__init__.py``, not the package."""


def shadowing_folder() -> Path | None:
    """The folder imported as ``skelagnostic`` instead of the package, if that happened.

    Returns:
        The folder (the first entry of the namespace package's path), or ``None`` when
        ``skelagnostic`` is the package (or not imported yet).
    """
    module = sys.modules.get("skelagnostic")
    if module is None or getattr(module, "__file__", None) is not None:
        return None
    places = list(getattr(module, "__path__", []))
    return Path(places[0]) if places else None


def check_not_shadowed() -> None:
    """Raise :class:`ShadowedPackageError` (one line) when a folder hides the package.

    Raises:
        ShadowedPackageError: ``skelagnostic`` was imported from a folder without
            ``__init__.py``.
    """
    folder = shadowing_folder()
    if folder is None:
        return
    raise ShadowedPackageError(
        f"'import skelagnostic' found the folder {folder} (no __init__.py: a checkout named "
        "skelagnostic in the current folder or on PYTHONPATH) instead of the installed "
        "package; run from another folder (or rename that one)"
    )
