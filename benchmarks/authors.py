"""The methods' official code as same-run baselines (``run.py --authors-repo``).

``--authors-repo walkthedog=DIR[,pcmrl=DIR]`` names checkouts of the authors'
repositories (github PeizhuoLi/walk-the-dog, MiniEval/PC-MRL). The suites that
compare with them read the checkouts with :func:`authors_repo`; without the
option it returns ``None`` and those suites report the baseline as absent
(``baseline_value`` ``None``), never an estimate. The checkouts are passed to
the suites' child processes through the environment variable
:data:`AUTHORS_ENV` (JSON ``{name: path}``), like the thread count.

Nothing of the authors' code is part of this repository: the suites import it
from the given directory at run time, in a child process.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable
from pathlib import Path

#: Environment variable holding ``{name: checkout path}`` (JSON) for suites and children.
AUTHORS_ENV = "SKELAGNOSTIC_BENCH_AUTHORS"

#: Known official repositories: name -> files whose presence identifies a checkout.
CHECKOUTS: dict[str, tuple[str, ...]] = {
    "walkthedog": (
        "train_vq.py",
        "offline_motion_matching.py",
        "models/VQ.py",
        "motion_matching/kernel.py",
    ),
    "pcmrl": (
        "train_pointcloud.py",
        "train_inpainter.py",
        "models/pc_mrl.py",
        "models/modules.py",
    ),
}

#: Where each repository is published (for error messages and the docs).
SOURCES: dict[str, str] = {
    "walkthedog": "github PeizhuoLi/walk-the-dog",
    "pcmrl": "github MiniEval/PC-MRL",
}


class AuthorsRepoError(ValueError):
    """A bad ``--authors-repo`` value: unknown name, or a path that is not a checkout."""


def check_checkout(name: str, path: str | Path) -> Path:
    """The resolved checkout of repository ``name`` at ``path``.

    Args:
        name: A key of :data:`CHECKOUTS`.
        path: Directory of the checkout.

    Returns:
        The absolute path.

    Raises:
        AuthorsRepoError: If ``name`` is unknown, ``path`` is not a directory, or
            a file that identifies the repository is missing (named in the message).
    """
    if name not in CHECKOUTS:
        raise AuthorsRepoError(
            f"--authors-repo: unknown repository {name!r}; known: {', '.join(CHECKOUTS)}"
        )
    root = Path(path).expanduser().resolve()
    if not root.is_dir():
        raise AuthorsRepoError(f"--authors-repo {name}={path}: {root} is not a directory")
    missing = [f for f in CHECKOUTS[name] if not (root / f).is_file()]
    if missing:
        raise AuthorsRepoError(
            f"--authors-repo {name}={path}: {root} is not a checkout of {SOURCES[name]} "
            f"(missing {', '.join(missing)})"
        )
    return root


def parse_authors_repos(specs: Iterable[str]) -> dict[str, Path]:
    """Parse ``--authors-repo`` values (``name=DIR``, comma-separated, repeatable).

    Args:
        specs: The option's values, e.g. ``["walkthedog=/src/wtd,pcmrl=/src/pcmrl"]``.

    Returns:
        Repository name -> checked, absolute checkout path.

    Raises:
        AuthorsRepoError: On a malformed item, a repeated or unknown name, or a
            directory that is not a checkout of that repository.
    """
    repos: dict[str, Path] = {}
    for spec in specs:
        for item in filter(None, (part.strip() for part in spec.split(","))):
            name, sep, path = item.partition("=")
            name = name.strip()
            if not sep or not name or not path.strip():
                raise AuthorsRepoError(
                    f"--authors-repo: expected NAME=DIR (NAME one of {', '.join(CHECKOUTS)}), "
                    f"got {item!r}"
                )
            if name in repos:
                raise AuthorsRepoError(f"--authors-repo: {name} given twice")
            repos[name] = check_checkout(name, path.strip())
    return repos


def export_authors_repos(repos: dict[str, Path]) -> None:
    """Make ``repos`` visible to the suites and their child processes (or clear it)."""
    if repos:
        os.environ[AUTHORS_ENV] = json.dumps({k: str(v) for k, v in repos.items()})
    else:
        os.environ.pop(AUTHORS_ENV, None)


def authors_repo(name: str) -> Path | None:
    """The checkout of official repository ``name`` given to this run, or ``None``.

    Raises:
        AuthorsRepoError: If :data:`AUTHORS_ENV` is not valid JSON or names a
            directory that is not a checkout of ``name``.
    """
    raw = os.environ.get(AUTHORS_ENV)
    if not raw:
        return None
    try:
        repos = json.loads(raw)
    except json.JSONDecodeError as err:
        raise AuthorsRepoError(f"${AUTHORS_ENV}: not JSON ({err}): {raw!r}") from err
    if not isinstance(repos, dict):
        raise AuthorsRepoError(f"${AUTHORS_ENV}: expected a JSON object, got {raw!r}")
    path = repos.get(name)
    return None if path is None else check_checkout(name, path)
