"""What both HuMoT protocols share: the held-out human clips and their topology status.

The clips a protocol measures are the run's held-out clips of bipeds plus any
``+protocol_options.extra=[...]`` files (:func:`extra_clips`,
:func:`protocol_clips`); every row names whether a training skeleton of the run
had the clip's joint hierarchy (:func:`topology_status`), and
:func:`by_topology` averages the rows of each status.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from skelagnostic.core.motion import Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.evaluation import EvaluationError, HeldOut, mean_rows

__all__ = [
    "HELD_OUT_SEED",
    "HUMAN_KINDS",
    "SEEN_NOTE",
    "by_topology",
    "extra_clips",
    "protocol_clips",
    "topology_status",
    "trained_hierarchies",
]

#: Procedural human topologies (22, 31 and 17 joints).
HUMAN_KINDS: tuple[str, ...] = ("biped22", "biped31", "biped17")

#: Base seed of held-out procedural clips: training uses seeds 0 up to the clip count.
HELD_OUT_SEED = 1000


def trained_hierarchies(held: HeldOut) -> set[tuple[int, ...]] | None:
    """The joint hierarchies (parent lists) of the run's training skeletons.

    HuMoT never sees joint names, only the hierarchy and the template geometry,
    so a topology counts as seen when a training skeleton has its hierarchy
    (CMU-31 with 3dsMax names and the procedural ``biped31`` share one).

    Returns:
        The parent tuples, or ``None`` when ``held`` carries no set-up data module.
    """
    skeletons = getattr(held.datamodule, "skeletons", None)
    if not skeletons:
        return None
    return {tuple(sk.parents) for sk in skeletons.values()}


def topology_status(skeleton: Skeleton, trained: set[tuple[int, ...]] | None) -> str:
    """``"seen"``, ``"unseen"`` (see :func:`trained_hierarchies`) or ``"unknown"``."""
    if trained is None:
        return "unknown"
    return "seen" if tuple(skeleton.parents) in trained else "unseen"


def _clip_path(clip_id: str) -> Path | None:
    """The file of a clip id (``path`` or ``part:path`` of a multi-source), if it is one."""
    path = Path(clip_id)
    if path.is_file():
        return path.resolve()
    return _clip_path(clip_id.split(":", 1)[1]) if ":" in clip_id else None


def extra_clips(
    paths: str | Sequence[str], units: str | None = None, held: HeldOut | None = None
) -> list[Motion]:
    """BVH clips outside the run's data (``+protocol_options.extra=[DIR_OR_FILE, ...]``).

    Held-out clips of a topology the run never trained on come from here: a
    run's test split only holds clips of its own datasets.

    Args:
        paths: BVH files or directories (searched recursively for ``*.bvh``).
        units: Length unit of the files (``cm``, ``cmu``, ...); ``None``: the file's,
            else guessed from the skeleton's height.
        held: The run's held-out clips; clips its data module trained on are refused.

    Returns:
        The clips in metres, named by their path, in path order.

    Raises:
        EvaluationError: A path does not exist, holds no BVH file, or names a
            training clip of the run.
    """
    from skelagnostic.io.bvh import read_bvh

    if isinstance(paths, (str, Path)):
        paths = [paths]
    assigned = (getattr(held.datamodule, "assigned_splits", None) or {}) if held else {}
    trained = {_clip_path(i) for i, split in assigned.items() if split == "train"} - {None}
    clips = []
    for entry in paths:
        root = Path(entry).expanduser()
        if not root.exists():
            raise EvaluationError(f"protocol_options.extra: {root} does not exist")
        files = sorted(root.rglob("*.bvh")) if root.is_dir() else [root]
        if not files:
            raise EvaluationError(f"protocol_options.extra: no .bvh file below {root}")
        for file in files:
            if file.resolve() in trained:
                raise EvaluationError(
                    f"protocol_options.extra: {file} is a training clip of the run; "
                    "evaluate on clips it never saw"
                )
            motion = read_bvh(file).to_metres(units)
            motion.name = str(file)
            clips.append(motion)
    return clips


def _humans(held: HeldOut, notes: list[str], extra: Sequence[Motion] = ()) -> list[Motion]:
    """The held-out clips HuMoT models (bipeds); the others are named in ``notes``."""
    clips = [*held.clips, *extra]
    humans = [c for c in clips if c.skeleton.morphology == "biped"]
    others = [str(c.name) for c in clips if c.skeleton.morphology != "biped"]
    if others:
        notes.append(f"skipped {len(others)} non-human clip(s): {', '.join(others)}")
    return humans


def protocol_clips(
    held: HeldOut, notes: list[str], extra: str | Sequence[str] | None, units: str | None
) -> tuple[list[Motion], set[tuple[int, ...]] | None]:
    """The human clips a protocol measures (held out, then ``extra``); the trained hierarchies."""
    more = extra_clips(extra, units, held) if extra else []
    if more:
        notes.append(f"{len(more)} clip(s) from protocol_options.extra, outside the run's data")
    return _humans(held, notes, more), trained_hierarchies(held)


def by_topology(rows: list[dict[str, Any]]) -> dict[str, dict[str, dict[str, float]]]:
    """Mean figures of the rows of each topology status (``seen`` / ``unseen`` / ...)."""
    statuses = dict.fromkeys(r["topology"] for r in rows)
    return {s: mean_rows([r for r in rows if r["topology"] == s]) for s in statuses}


#: The note both protocols add on the ``topology`` of a row.
SEEN_NOTE = (
    "topology: 'seen' when a training skeleton of the run has the clip's joint hierarchy "
    "(HuMoT never sees joint names), 'unseen' otherwise; extra['by_topology'] holds the "
    "means of each"
)
