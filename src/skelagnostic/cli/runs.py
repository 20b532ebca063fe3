"""Run directories: what later verbs reuse from them, and what every verb reports.

A ``fit`` writes ``<run_dir>/config.yaml`` (the resolved config) and
``<run_dir>/split.json`` (which clip went to which split). ``validate``,
``test``, ``predict`` and a resumed ``fit`` given only ``ckpt_path=`` (a
checkpoint inside a run directory, or the run directory itself) take the model
and data configuration from there, and keep the recorded split, so a clip the
model trained on is never evaluated as held out. Explicit overrides still win.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import re
import sys
import warnings
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path

from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.errors import HydraException
from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf, open_dict

from skelagnostic.cli.lock import LOCK_FILE, RunDirectoryLock, RunDirectoryRefused
from skelagnostic.core.paths import expand_path
from skelagnostic.errors import SkelagnosticError
from skelagnostic.filenames import SPLIT_FILE, WEIGHTS_FILE

__all__ = [
    "LOCK_FILE",
    "RunDirectoryGuard",
    "RunDirectoryLock",
    "RunDirectoryRefused",
    "checkpoint_of",
    "find_run_dir",
    "quiet_lightning",
    "read_split",
    "release_run_directories",
    "reuse_run_config",
    "summary_table",
    "value_of",
]

#: The resolved config a run writes.
CONFIG_FILE = "config.yaml"
#: Config nodes a later verb takes from the run (unless the command line chooses them).
REUSED = ("model", "data")


def find_run_dir(ckpt: str | Path) -> Path | None:
    """The run directory of a checkpoint (or of a directory), if it has a ``config.yaml``.

    For a checkpoint file, looks at its folder, the one above it
    (``<run>/checkpoints/last.ckpt``) and, for a checkpoint deeper in a run's
    ``checkpoints`` folder (a second ``ModelCheckpoint`` writing to
    ``<run>/checkpoints/periodic/``), the folder that holds ``checkpoints``. A
    directory is the run directory itself or its ``checkpoints`` folder.

    Example:
        >>> find_run_dir("/nonexistent/run/checkpoints/last.ckpt") is None
        True
    """
    path = expand_path(ckpt)
    if path.is_dir():
        candidates = [path, path.parent] if path.name == "checkpoints" else [path]
    else:
        candidates = [path.parent, path.parent.parent]
        inside = next((p for p in path.parents if p.name == "checkpoints"), None)
        if inside is not None:
            candidates.append(inside.parent)
    return next((c for c in candidates if (c / CONFIG_FILE).is_file()), None)


def checkpoint_of(path: str | Path, prefer: str | None = None) -> Path:
    """``path`` itself, or for a run directory the checkpoint that stands for its model.

    A directory without them that holds ``model.safetensors`` (``export
    format=safetensors``) stands for that file.

    That is ``best.ckpt`` (lowest ``val/loss``) unless ``prefer`` or, without it, the
    run's own ``config.yaml`` says ``run_checkpoint: last`` (a schedule whose last
    step is the trained model, such as a cosine cycle that ends at zero). When the
    preferred file is missing the other one is taken.

    Args:
        path: A checkpoint file, or a run directory (or its ``checkpoints`` folder).
        prefer: ``"best"`` or ``"last"``; ``None``: the run's ``run_checkpoint``, else best.

    Raises:
        SkelagnosticError: ``prefer`` (or the run's ``run_checkpoint``) is neither best
            nor last, or the directory holds neither checkpoint.

    Example:
        >>> checkpoint_of("/nonexistent/run/checkpoints/last.ckpt").name
        'last.ckpt'
    """
    path = expand_path(path)
    if not path.is_dir():
        return path
    source = "run_checkpoint"
    if prefer is None:
        run_dir = find_run_dir(path)
        if run_dir is not None:
            with contextlib.suppress(Exception):  # a broken config is reported by its reader
                saved = OmegaConf.load(run_dir / CONFIG_FILE)
                prefer = saved.get("run_checkpoint") if isinstance(saved, DictConfig) else None
                source = f"{run_dir / CONFIG_FILE}: run_checkpoint"
    prefer = "best" if prefer is None else prefer
    if prefer not in ("best", "last"):
        raise SkelagnosticError(f"{source} must be 'best' or 'last', got {prefer!r}")
    order = (prefer, "last" if prefer == "best" else "best")
    for name in order:
        for candidate in (path / "checkpoints" / f"{name}.ckpt", path / f"{name}.ckpt"):
            if candidate.is_file():
                return candidate
    if (path / WEIGHTS_FILE).is_file():  # a directory of export format=safetensors
        return path / WEIGHTS_FILE
    raise SkelagnosticError(
        f"ckpt_path: the directory {str(path)!r} holds no "
        f"checkpoints/best.ckpt, checkpoints/last.ckpt or {WEIGHTS_FILE}"
    )


def value_of(overrides: Sequence[str], key: str) -> str | None:
    """The value the command-line overrides give ``key`` (as text), if any."""
    for override in overrides:
        name, sep, _ = override.partition("=")
        if sep and name.lstrip("+") == key:
            try:
                parsed = OverridesParser.create().parse_override(override).value()
            except HydraException as exc:  # e.g. a backtick: Hydra names only the token
                raise SkelagnosticError(
                    f"{override}: Hydra cannot parse this override ({exc}); "
                    f"quote the value: {name}='...'"
                ) from None
            return None if parsed is None else str(parsed)
    return None


def chosen_keys(overrides: Sequence[str]) -> set[str]:
    """Keys (and groups) the command line sets, without ``+``/``~`` prefixes."""
    return {o.partition("=")[0].lstrip("+~") for o in overrides}


def run_of_overrides(overrides: Sequence[str]) -> DictConfig | None:
    """The saved config of the run directory that ``ckpt_path=`` points into, if any."""
    ckpt = value_of(overrides, "ckpt_path")
    if not ckpt or "://" in ckpt or ckpt in ("last", "best", "hpc", "registry"):
        return None
    run_dir = find_run_dir(ckpt)
    if run_dir is None:
        return None
    path = run_dir / CONFIG_FILE
    try:
        saved = OmegaConf.load(path)
        name = saved.model.name if isinstance(saved, DictConfig) else None
    except Exception as exc:  # YAML errors, missing keys: the file is not a run's config
        raise SkelagnosticError(
            f"{path}: not the config.yaml of a skelagnostic run "
            f"({type(exc).__name__}); give model=... and data=..."
        ) from exc
    if not isinstance(name, str):
        raise SkelagnosticError(
            f"{path}: not the config.yaml of a skelagnostic run (no "
            "model.name); give model=... and data=..."
        )
    return saved


def reuse_run_config(cfg: DictConfig, saved: DictConfig, overrides: Sequence[str]) -> None:
    """Put the saved run's ``model`` and ``data`` into ``cfg``; the command line still wins.

    A node is reused unless the command line chooses its group (``model=``,
    ``data=``) or an ``experiment=``; the command line's ``model.*`` and
    ``data.*`` values are applied again on top of the reused node.

    Args:
        cfg: The composed config of this command (changed in place).
        saved: The run's ``config.yaml``.
        overrides: The user's overrides.
    """
    chosen = chosen_keys(overrides)
    if "experiment" in chosen:
        return
    parser = OverridesParser.create()
    with open_dict(cfg):
        for node in REUSED:
            if node in chosen or node not in saved:
                continue
            cfg[node] = saved[node]
            for override in parser.parse_overrides(
                [o for o in overrides if o.lstrip("+~").startswith(f"{node}.")]
            ):
                key = override.key_or_group
                if override.is_delete():
                    parent, _, leaf = key.rpartition(".")
                    OmegaConf.select(cfg, parent).pop(leaf, None)
                else:
                    OmegaConf.update(cfg, key, override.value(), merge=False, force_add=True)


def read_split(run_dir: Path) -> dict[str, str] | None:
    """``clip id -> split`` recorded in ``<run_dir>/split.json``, or None.

    Raises:
        SkelagnosticError: The file exists but cannot be read.
    """
    path = run_dir / SPLIT_FILE
    if not path.is_file():
        return None
    try:
        clips = json.loads(path.read_text(encoding="utf-8"))["clips"]
        return {str(k): str(v) for k, v in clips.items()}
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
        raise SkelagnosticError(f"{path}: not a split file of skelagnostic ({exc})") from exc


def summary_table(
    task: str,
    run_dir: Path,
    metrics: Mapping[str, float],
    checkpoint: Path | None = None,
    limit: int = 16,
    stopped: str | None = None,
) -> None:
    """Print the run directory, the checkpoints and the headline metrics (one Rich table).

    Args:
        task: The verb.
        run_dir: The run directory.
        metrics: The trainer's final metrics.
        checkpoint: The checkpoint evaluated (validate, test, predict).
        limit: Metrics shown at most.
        stopped: Why a fit ended (``max_steps 20 reached``, ...), shown as a row.
    """
    from lightning.pytorch.utilities import rank_zero_only  # loaded by the run already

    if rank_zero_only.rank != 0:
        return
    from rich.console import Console
    from rich.table import Table

    rows = [("run directory", str(run_dir))]
    if stopped:
        rows.append(("stopped", stopped))
    if checkpoint is not None:
        rows.append(("evaluated checkpoint", str(checkpoint)))
    for name in ("best", "last"):
        ckpt = run_dir / "checkpoints" / f"{name}.ckpt"
        if ckpt.is_file():
            rows.append((f"{name} checkpoint", str(ckpt)))
    rows += [(key, f"{metrics[key]:.5g}") for key in sorted(metrics)[:limit]]
    if len(metrics) > limit:
        rows.append(("...", f"{len(metrics) - limit} more in the run's csv/metrics.csv"))
    table = Table(title=f"skelagnostic {task}", show_header=False, title_justify="left")
    # never cut a name: fold what does not fit (the width below fits every cell)
    table.add_column(style="bold", overflow="fold")
    table.add_column(overflow="fold")
    for row in rows:
        table.add_row(*row)
    # wide enough for the longest name beside the longest value: whole paths, to copy them
    width = max(80, max(len(a) for a, _ in rows) + max(len(b) for _, b in rows) + 8)
    Console(file=sys.stdout, width=width).print(table)


#: Warnings a CLI user cannot act on (messages, as regular expressions).
NOISE = (
    r"`isinstance\(treespec, LeafSpec\)` is deprecated",
    r"The dirpath has changed from",
    r"Trying to infer the `batch_size` from an ambiguous collection",
    r"could not find the monitored key in the returned metrics",
    r"The number of training batches \(\d+\) is smaller than the logging interval",
    r"Checkpoint directory .* exists and is not empty",
)


class _DropTips(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return "Tip:" not in record.getMessage()


@contextlib.contextmanager
def quiet_lightning() -> Iterator[None]:
    """Within the block: drop the warnings of :data:`NOISE` and Lightning's advertising tips.

    Used by the CLI only, so a library user keeps every warning.
    """
    logger = logging.getLogger("lightning.pytorch.utilities.rank_zero")
    tips = _DropTips()
    logger.addFilter(tips)
    try:
        with warnings.catch_warnings():
            for pattern in NOISE:
                warnings.filterwarnings("ignore", message=f".*{pattern}")
            yield
    finally:
        logger.removeFilter(tips)


def max_steps_overrides(overrides: Sequence[str]) -> list[str]:
    """``trainer.max_epochs=-1`` when the user sets ``trainer.max_steps`` but not ``max_epochs``.

    A preset's (or the default) ``max_epochs`` would otherwise end a run the
    user sized in steps before it got there.
    """
    chosen = chosen_keys(overrides)
    if "trainer.max_steps" in chosen and "trainer.max_epochs" not in chosen:
        value = value_of(overrides, "trainer.max_steps")
        if value is not None and re.fullmatch(r"\d+", value) and int(value) > 0:
            return ["trainer.max_epochs=-1"]
    return []


# ------------------------------------------------------------ run directory ownership
#: Locks of run directories this process holds (released by :func:`release_run_directories`).
_HELD: list[RunDirectoryLock] = []


def release_run_directories() -> None:
    """Release every run directory lock this process took (the CLI calls it when it ends)."""
    while _HELD:
        _HELD.pop().release()


def _describe_contents(run_dir: Path, limit: int = 4) -> str:
    names = sorted(p.name + ("/" if p.is_dir() else "") for p in run_dir.iterdir())
    return ", ".join(names[:limit]) + (", ..." if len(names) > limit else "")


def check_run_directory(run_dir: Path, task: str) -> None:
    """Refuse ``run_dir`` when it holds files (other than a lock file): they belong to a run.

    Args:
        run_dir: The run directory about to be used.
        task: The verb (``fit`` is told how to resume the run found there).

    Raises:
        RunDirectoryRefused: The directory is not empty, or is not a directory.
    """
    if not run_dir.exists() and not run_dir.is_symlink():
        return
    if not run_dir.is_dir():
        raise RunDirectoryRefused(
            f"hydra.run.dir={str(run_dir)!r} is not a directory; name a new or empty directory"
        )
    if not any(p.name != LOCK_FILE for p in run_dir.iterdir()):
        return
    hint = ""
    if task == "fit":
        ckpt = next(
            (
                p
                for p in (
                    run_dir / "checkpoints" / "last.ckpt",
                    run_dir / "checkpoints" / "best.ckpt",
                )
                if p.is_file()
            ),
            None,
        )
        if ckpt is not None:
            hint = (
                f"; to continue that run, resume it with ckpt_path={ckpt} "
                "(the resumed run writes a new directory)"
            )
    raise RunDirectoryRefused(
        f"hydra.run.dir={str(run_dir)!r} is not empty (it holds {_describe_contents(run_dir)}); "
        "a run directory belongs to one run: name a new or empty directory, or leave "
        f"hydra.run.dir out (each run then gets a new one){hint}"
    )


class RunDirectoryGuard(Callback):
    """Hydra callback: a command gets a run directory of its own, or stops before writing.

    At ``on_run_start`` (before Hydra creates the directory and writes ``.hydra/``
    into it) the directory ``hydra.run.dir`` resolves to must be missing or empty
    (see :func:`check_run_directory`); then :class:`RunDirectoryLock` is taken, so
    two commands started at once with the same ``hydra.run.dir`` cannot both use it.
    The CLI releases the lock when the command ends. Extra DDP ranks (which Lightning
    starts with ``hydra.run.dir=<rank 0's directory>``) are let through. Sweeps
    (``-m``) are not checked: each job has its own numbered subdirectory.
    ``conf/config.yaml`` registers it under ``hydra.callbacks``.
    """

    def on_run_start(self, config: DictConfig, **kwargs: object) -> None:
        """Check and lock the run directory of this command (rank 0 only)."""
        from lightning.pytorch.utilities import rank_zero_only  # a job is about to run

        if rank_zero_only.rank != 0:
            return
        raw = OmegaConf.select(config, "hydra.run.dir")
        if raw is None:
            return
        run_dir = Path(os.path.abspath(str(raw)))
        task = str(OmegaConf.select(config, "task", default="fit"))
        lock = RunDirectoryLock(run_dir)
        if not lock.path.is_file():  # with a lock file, whether it is held says more
            check_run_directory(run_dir, task)
        try:
            lock.acquire()
        except OSError as exc:
            raise RunDirectoryRefused(
                f"hydra.run.dir={str(run_dir)!r}: cannot create the run directory "
                f"({exc.strerror or exc})"
            ) from exc
        _HELD.append(lock)
        try:  # a command started at the same moment may have written there first
            check_run_directory(run_dir, task)
        except RunDirectoryRefused:
            release_run_directories()
            raise
