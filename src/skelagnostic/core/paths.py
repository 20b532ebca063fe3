"""Paths given by users: ``~`` and environment variables expanded in one place."""

from __future__ import annotations

import os
import re
from pathlib import Path

__all__ = ["expand_home_in_override", "expand_path"]


def expand_path(path: str | os.PathLike[str]) -> Path:
    """``path`` with ``$VAR`` / ``${VAR}`` and a leading ``~`` / ``~user`` expanded.

    Every path option of the package (``data.paths``, ``data.root``,
    ``data.cache_dir``, ``ckpt_path``, ``out=``, ...) goes through this, so
    ``~/mocap`` and ``$DATA/lafan1`` mean what they mean in a shell. Unset
    variables are left as written (as :func:`os.path.expandvars` does), so the
    error that follows names the path as the user wrote it.

    Example:
        >>> import os
        >>> os.environ["SA_DOC_ROOT"] = "/data"
        >>> expand_path("$SA_DOC_ROOT/lafan1").as_posix()
        '/data/lafan1'
        >>> expand_path("~/mocap") == Path.home() / "mocap"
        True
    """
    return Path(os.path.expanduser(os.path.expandvars(os.fspath(path))))


#: ``~`` or ``~/...`` at the start of a value or of a list/dict element of an override.
_HOME_IN_VALUE = re.compile(r"(?P<lead>^|[\[,:]\s*)~(?=/|\s*[,\]}]|$)")


def expand_home_in_override(override: str) -> str:
    """Replace an unquoted ``~`` that starts a path in a Hydra override's value by ``$HOME``.

    Hydra's grammar reads ``~`` as its delete operator, so
    ``data.paths=[~/mocap]`` or ``data.root=~/lafan1`` did not parse. Only the
    value (after the first ``=``) is rewritten and only where ``~`` starts a
    path (the value, a list element or a dict value); ``~key`` (delete) and
    quoted values are left alone.

    Example:
        >>> from pathlib import Path
        >>> expand_home_in_override("data.paths=[~/a,~/b]") == (
        ...     f"data.paths=[{Path.home()}/a,{Path.home()}/b]")
        True
        >>> expand_home_in_override("~trainer.max_time")
        '~trainer.max_time'
    """
    key, sep, value = override.partition("=")
    if not sep or "~" not in value:
        return override
    home = str(Path.home())
    out, quote = [], None
    # rewrite only outside quotes: split the value into quoted and unquoted runs
    for part in re.split(r"""('(?:[^'\\]|\\.)*'|"(?:[^"\\]|\\.)*")""", value):
        quote = part[:1] in {"'", '"'}
        out.append(part if quote else _HOME_IN_VALUE.sub(lambda m: m["lead"] + home, part))
    return f"{key}={''.join(out)}"
