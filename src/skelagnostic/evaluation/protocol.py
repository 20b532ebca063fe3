"""What a protocol receives and returns: the held-out clips and its :class:`Evaluation`.

:func:`held_out` collects the clips of a set-up data module the model never
trained on (:data:`SPLITS`); a protocol returns per-clip rows for :data:`MODEL`
and its baselines in an :class:`Evaluation`; :func:`mean_rows` averages them and
:func:`track` draws a protocol's progress.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from skelagnostic.core.motion import Motion
from skelagnostic.errors import SkelagnosticError

#: The method name of the evaluated aligner in every :class:`Evaluation`.
MODEL = "model"


def track(
    items: Iterable[Any], description: str, total: int | None = None, console: Any = None
) -> Iterator[Any]:
    """Iterate ``items`` with a Rich progress bar on stderr (protocols' long loops).

    The bar is transient and drawn only when the console is a terminal, so logs
    and captured output stay clean.

    Args:
        items: What to iterate.
        description: The bar's label, e.g. ``"vqpae.manifold: held-out clips"``.
        total: Number of items (default: ``len(items)`` when it has one, else the
            bar shows no end).
        console: A ``rich.console.Console`` (default: one on stderr).

    Yields:
        The items, unchanged.
    """
    from rich.console import Console
    from rich.progress import track as rich_track

    console = console or Console(stderr=True)
    yield from rich_track(
        items,
        description=description,
        total=total,
        console=console,
        transient=True,
        disable=not console.is_terminal,
    )


class EvaluationError(SkelagnosticError):
    """An evaluation that cannot run (no held-out split, no clip long enough, ...)."""


@dataclass(frozen=True)
class HeldOut:
    """The clips of a run a protocol evaluates: those the model never trained on.

    With ``split="train"`` (``evaluate split=train``) they are the run's training
    clips instead, for figures a paper measures on its training data; the reports
    then say so (:attr:`name`, :attr:`is_training`).

    Attributes:
        split: ``"test"``, ``"val"``, ``"heldout"`` (both) or ``"train"`` (the training
            clips, not held out); see :func:`held_out`.
        clips: The clips, resampled to the data module's fps, named by their clip id.
        datamodule: The run's data module (after ``setup``), for its options
            (``fps``, ``window``, its training datasets for normalisation statistics).
        description: The split's name in reports, when not the default of ``split``.
    """

    split: str
    clips: list[Motion]
    datamodule: Any = None
    description: str = ""

    @property
    def name(self) -> str:
        """What the split is, as the reports write it (``"test split"``, ...)."""
        return self.description or _SPLIT_NAMES.get(self.split, self.split)

    @property
    def is_training(self) -> bool:
        """Whether the clips are the run's training clips (``split="train"``), not held out."""
        return self.split == "train"

    @property
    def names(self) -> list[str]:
        """The clip ids, in order."""
        return [str(c.name) for c in self.clips]


#: The values of ``evaluate split=``: which clips the model never trained on are evaluated
#: (``"train"``: the training clips instead, labelled as such).
SPLITS = ("test", "val", "heldout", "train")


def held_out(datamodule: Any, split: str | None = None) -> HeldOut:
    """The held-out clips of a data module: its test clips, else its validation clips.

    The data module is set up (``setup("test")``), then every clip its
    ``assigned_splits`` places in the chosen split is loaded again from its
    source and resampled to ``datamodule.fps``.

    Args:
        datamodule: A :class:`~skelagnostic.data.MotionDataModule` (or any object
            with ``sources``, ``assigned_splits`` and ``fps``).
        split: ``None``: the test split if the data has one, else the validation
            split. ``"test"`` or ``"val"``: that split. ``"heldout"``: the validation
            and the test clips together (every clip the model never trained on;
            for corpora whose test split is too small to decide a figure). Clips of
            the validation split are unseen by the weights, but a checkpoint chosen
            by its validation loss (``best.ckpt``) was selected on them. ``"train"``:
            the training clips, **not** held out (for a paper's figure measured on its
            training data); the result's ``name`` says so.

    Returns:
        The held-out clips (validation clips first for ``"heldout"``), or the
        training clips for ``"train"``.

    Raises:
        EvaluationError: ``split`` is not one of :data:`SPLITS`, or the chosen
            split holds no clip.
    """
    if split is not None and split not in SPLITS:
        raise EvaluationError(
            f"split={split!r}: expected one of {', '.join(SPLITS)} (or null: the test split, "
            "else the validation split; train: the training clips, not held out)"
        )
    datamodule.setup("test")
    assigned: Mapping[str, str] = getattr(datamodule, "assigned_splits", {}) or {}
    present = set(assigned.values())
    if split is None:
        split = next((s for s in ("test", "val") if s in present), None)
        if split is None:
            raise EvaluationError(
                "evaluate: the data has neither a test nor a validation split "
                "(data.test_fraction=0 and data.val_fraction=0, and no clip matches a test "
                "pattern); set data.test_fraction>0 or data.val_fraction>0 so the model is "
                "evaluated on clips it did not train on"
            )
    description = _NO_TEST if split == "val" and "test" not in present else ""
    wanted = ("val", "test") if split == "heldout" else (split,)
    if not present & set(wanted):
        raise EvaluationError(
            f"split={split}: the data has no {' or '.join(_SPLIT_NAMES[w] for w in wanted)} "
            f"(its splits: {', '.join(sorted(present)) or 'none'}); set data.test_fraction>0 "
            "or data.val_fraction>0, or choose another split"
        )
    clips = [clip for w in wanted for clip in clips_of_split(datamodule, w)]
    return HeldOut(split, clips, datamodule, description)


def clips_of_split(datamodule: Any, split: str) -> list[Motion]:
    """The clips a set-up data module assigns to ``split``, loaded again from their sources.

    Args:
        datamodule: A set-up :class:`~skelagnostic.data.MotionDataModule` (or any
            object with ``sources``, ``assigned_splits`` and ``fps``).
        split: ``"train"``, ``"val"`` or ``"test"``.

    Returns:
        The clips in source order, resampled to ``datamodule.fps``, named by clip id.
    """
    assigned: Mapping[str, str] = getattr(datamodule, "assigned_splits", {}) or {}
    fps = float(datamodule.fps)
    clips = []
    for source in datamodule.sources:
        for ref in source.clips():
            if assigned.get(ref.id) != split:
                continue
            motion = source.load(ref)
            if motion.fps != fps:
                motion = motion.resample(fps)
            motion.name = ref.id
            clips.append(motion)
    return clips


@dataclass
class Evaluation:
    """What a protocol returns.

    Attributes:
        metrics: ``metric key -> description`` (unit, and whether lower is better).
        rows: One row per clip (or window): ``{"clip": id, "values": {method: {metric:
            value}}}``; the first method is :data:`MODEL`, the others baselines computed
            on the same clips. A method may leave a metric out (no value).
        extra: More JSON-able results (curves, per-setting tables).
        plots: File names of the plots the protocol wrote into its ``out_dir``.
        notes: Sentences for the report (what the baselines are, caveats).
        outputs: ``clip id -> function making the model's output motion`` of a row's
            clip (what a user of the model gets, e.g. its retarget or interpolation),
            called only when asked (``evaluate cleanup=footlock`` measures a cleanup
            on them); not written to the report. A protocol without a motion output
            leaves it empty.
    """

    metrics: dict[str, str]
    rows: list[dict[str, Any]]
    extra: dict[str, Any] = field(default_factory=dict)
    plots: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    outputs: dict[str, Callable[[], Motion]] = field(default_factory=dict)

    @property
    def methods(self) -> list[str]:
        """The methods of the rows, :data:`MODEL` first."""
        names = dict.fromkeys(m for row in self.rows for m in row["values"])
        return sorted(names, key=lambda m: (m != MODEL, list(names).index(m)))


def mean_rows(rows: Sequence[Mapping[str, Any]]) -> dict[str, dict[str, float]]:
    """``method -> metric -> mean`` over the rows that have the value (NaN values skipped)."""
    sums: dict[str, dict[str, list[float]]] = {}
    for row in rows:
        for method, values in row["values"].items():
            for metric, value in values.items():
                if value is not None and math.isfinite(float(value)):
                    sums.setdefault(method, {}).setdefault(metric, []).append(float(value))
    return {m: {k: sum(v) / len(v) for k, v in per.items()} for m, per in sums.items()}


_SPLIT_NAMES = {
    "test": "test split",
    "val": "validation split",
    "heldout": "validation and test splits",
    "train": "training split (clips the model trained on, not held out)",
}


#: The split's name when ``evaluate`` falls back to the validation split.
_NO_TEST = "validation split (the data has no test split)"
