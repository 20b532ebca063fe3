"""Where the Hydra verbs write: ``runs_dir=`` and ``hydra.run.dir=`` checked before a run.

Hydra creates the run directory itself, before any skelagnostic code runs, and a
path it cannot use (a regular file, a path under one, a dangling symbolic link, a
read-only directory) would end in its traceback. :func:`check_run_locations`
refuses such a value with one line naming the key and the cause, before Hydra starts.
"""

from __future__ import annotations

from collections.abc import Sequence

from skelagnostic.cli.runs import value_of
from skelagnostic.io.outputs import check_output_dir

__all__ = ["RUN_LOCATION_KEYS", "check_run_locations"]

#: Overrides that name where a run writes.
RUN_LOCATION_KEYS = ("hydra.run.dir", "runs_dir")


def check_run_locations(overrides: Sequence[str]) -> None:
    """Check the run locations the command line gives, before Hydra creates them.

    A value with an interpolation (``hydra.run.dir=/data/${now:%H}``) is checked
    up to its last literal folder.

    Args:
        overrides: The Hydra overrides of the command line.

    Raises:
        OutputError: The location is a file, lies under a file, is a dangling
            symbolic link or a read-only directory (the message names the key).
    """
    for key in RUN_LOCATION_KEYS:
        value = value_of(overrides, key)
        if not value:
            continue
        literal, interpolated, _ = value.partition("${")
        if not interpolated:
            check_output_dir(value, key)
        elif "/" in literal:
            check_output_dir(literal.rsplit("/", 1)[0] or "/", key)
