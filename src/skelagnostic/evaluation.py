"""Evaluation protocols: held-out clips in, every figure beside its baselines out.

A plugin registers protocols through the ``register_evaluations`` hook (see
:mod:`skelagnostic.plugins.hookspecs`); ``skelagnostic evaluate`` builds the
run's aligner and data, loads the checkpoint, collects the held-out clips
(:func:`held_out`), calls the protocol and writes its :class:`Evaluation` with
:func:`write_evaluation`:

* ``evaluation.json``: the protocol, the data (config, split, clip names), the
  checkpoint, the metric descriptions, per-clip rows and their mean for the
  model and every baseline computed in the same run;
* ``evaluation.md``: the same as Markdown tables;
* ``evaluation.png``: the mean figures, model beside baselines, plus the
  protocol's own plots.

A protocol is a plain function ``protocol(aligner, held_out, out_dir) -> Evaluation``,
so tests and benchmarks call it without the command line.
"""

from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from skelagnostic.analysis import contact_joints, contacts_of_positions
from skelagnostic.baselines import mean_pose, mean_pose_on_trajectory
from skelagnostic.core.motion import Motion
from skelagnostic.core.units import UNITS, infer_units
from skelagnostic.errors import SkelagnosticError
from skelagnostic.io.markdown import markdown_cell
from skelagnostic.io.outputs import write_output
from skelagnostic.metrics.functional import foot_skate, foot_skate_ratio

__all__ = [
    "FOOT_SKATE_METRICS",
    "GROUND_TRUTH",
    "MODEL",
    "RECONSTRUCTION_METRICS",
    "SKATE_THRESHOLD",
    "SPLITS",
    "Evaluation",
    "EvaluationError",
    "HeldOut",
    "clips_of_split",
    "foot_skate_figures",
    "foot_skate_rows",
    "held_out",
    "markdown",
    "mean_rows",
    "own_foot_skate",
    "portable_names",
    "reconstruction_rows",
    "skate_feet",
    "track",
    "write_evaluation",
]

#: The method name of the evaluated aligner in every :class:`Evaluation`.
MODEL = "model"
#: The method name of the ground truth's own figures (its foot skate): a reference row
#: beside the model and the baselines, not a baseline (``references:`` of a result entry).
GROUND_TRUTH = "ground_truth"
#: Speed above which a planted step skates (``foot_skate_ratio``), in skeleton heights per
#: second (8.5 cm/s for a 1.7 m human).
SKATE_THRESHOLD = 0.05
#: Metrics of :func:`foot_skate_figures` and :func:`foot_skate_rows`.
FOOT_SKATE_METRICS = {
    "foot_skate_cm_s": "mean horizontal speed of the feet on the frames where the ground "
    "truth's feet are planted, cm/s, lower is better",
    "foot_skate_ratio": f"share of those planted steps faster than {SKATE_THRESHOLD:g} skeleton "
    "heights/s, lower is better",
}
#: Version of the layout of ``evaluation.json``.
SCHEMA_VERSION = 1


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


#: Metrics of :func:`reconstruction_rows`.
RECONSTRUCTION_METRICS = {
    "mpjpe_cm": "MPJPE of global joint positions, cm, lower is better",
    "mpjpe_over_height": "MPJPE / skeleton height, lower is better",
    **FOOT_SKATE_METRICS,
}


def skate_feet(skeleton: Any) -> list[int] | None:
    """The foot joints foot skate is read on (:func:`~skelagnostic.analysis.contact_joints`).

    Returns:
        The joints, or ``None`` for a skeleton without legs (no foot-skate columns).
    """
    try:
        return contact_joints(skeleton)
    except SkelagnosticError:
        return None


def foot_skate_figures(
    positions: torch.Tensor,
    contacts: torch.Tensor,
    feet: Sequence[int],
    fps: float,
    up_index: int,
    height: float,
    to_cm: float = 100.0,
) -> dict[str, float]:
    """:data:`FOOT_SKATE_METRICS` of one motion's positions on given contacts.

    Args:
        positions: ``[..., T, J, 3]`` global joint positions (any constant shift per
            sequence is harmless: only frame-to-frame steps count).
        contacts: ``[..., T, F]`` bool contacts of the ``F`` feet.
        feet: The foot joints.
        fps: Frame rate.
        up_index: Index of the up axis.
        height: The skeleton's height, in the positions' units.
        to_cm: Centimetres per unit of the positions.

    Returns:
        ``foot_skate_cm_s`` and ``foot_skate_ratio``; empty when no foot is planted at
        two consecutive frames (no value rather than NaN).
    """
    cm = positions[..., list(feet), :].double() * to_cm
    skate = float(foot_skate(cm, contacts, fps, up_axis=up_index))
    if not math.isfinite(skate):
        return {}
    threshold = SKATE_THRESHOLD * height * to_cm
    ratio = float(foot_skate_ratio(cm, contacts, fps, threshold, up_axis=up_index))
    return {"foot_skate_cm_s": skate, "foot_skate_ratio": ratio}


def foot_skate_rows(
    positions: Mapping[str, torch.Tensor],
    truth: torch.Tensor,
    feet: Sequence[int] | None,
    fps: float,
    up_index: int,
    height: float,
    to_cm: float = 100.0,
    contacts: torch.Tensor | None = None,
) -> dict[str, dict[str, float]]:
    """Foot skate of every method's positions on the contacts of the ground truth.

    The contacts are detected once, on ``truth``
    (:func:`~skelagnostic.analysis.contacts_of_positions`; or given), so the model and every
    baseline are scored on the same planted frames; the truth's own skate is the
    :data:`GROUND_TRUTH` entry, what the data itself has (a reference, not a baseline).
    Positions already computed by the protocol are reused: no forward kinematics here.

    Args:
        positions: ``method -> [..., T, J, 3]`` positions, on the truth's skeleton
            (joints in the same order; frames beyond the truth's are ignored).
        truth: ``[..., T, J, 3]`` ground-truth positions.
        feet: The foot joints (:func:`skate_feet`); ``None``: no figures.
        fps: Frame rate.
        up_index: Index of the up axis.
        height: The skeleton's height, in the positions' units.
        to_cm: Centimetres per unit of the positions.
        contacts: ``[..., T, F]`` contacts of the truth when the caller detected them
            (e.g. on whole clips before cutting them into chunks).

    Returns:
        ``method -> {foot_skate_cm_s, foot_skate_ratio}``, then :data:`GROUND_TRUTH`;
        empty without feet.
    """
    if feet is None:
        return {}
    frames = min(truth.shape[-3], *(p.shape[-3] for p in positions.values()))
    truth = truth[..., :frames, :, :]
    if contacts is None:
        contacts = contacts_of_positions(truth[..., list(feet), :], fps, up_index, height)
    contacts = contacts[..., :frames, :]
    args = (contacts, feet, fps, up_index, height, to_cm)
    out = {m: foot_skate_figures(p[..., :frames, :, :], *args) for m, p in positions.items()}
    return out | {GROUND_TRUTH: foot_skate_figures(truth, *args)}


def own_foot_skate(motion: Motion, positions: torch.Tensor | None = None) -> dict[str, float]:
    """:data:`FOOT_SKATE_METRICS` of a motion on its own contacts (no ground truth).

    For outputs on a character without ground truth (a transfer onto another rig):
    the contacts are detected on the motion itself
    (:func:`~skelagnostic.analysis.contacts_of_positions`), so a foot the method
    drags fast enough is not planted and does not count; compare methods with it, and
    prefer :func:`foot_skate_rows` where a ground truth exists.

    Args:
        motion: The motion (any units: centimetres per unit from
            :func:`~skelagnostic.core.units.infer_units`).
        positions: Its global positions ``[T, J, 3]`` when already computed.

    Returns:
        ``foot_skate_cm_s`` and ``foot_skate_ratio``; empty without legs or contacts.
    """
    sk = motion.skeleton
    feet = skate_feet(sk)
    if feet is None or motion.num_frames < 2:
        return {}
    pos = motion.global_positions() if positions is None else positions
    height = sk.height()
    contacts = contacts_of_positions(pos[:, feet], motion.fps, sk.up_index, height)
    to_cm = 100.0 * UNITS[infer_units(sk, motion.units)]
    return foot_skate_figures(pos, contacts, feet, motion.fps, sk.up_index, height, to_cm)


def reconstruction_rows(
    clips: Sequence[Motion], reconstruct: Callable[[Motion], Motion]
) -> list[dict[str, Any]]:
    """Per-clip pose error of ``reconstruct(clip)`` beside the static baselines.

    Methods: :data:`MODEL`, ``mean_pose`` (the clip's temporal mean pose) and
    ``mean_pose_on_trajectory`` (its mean root-relative pose along the true root
    path), see :mod:`skelagnostic.baselines`. Positions are compared in metres
    over the frames both motions have (at the clip's frame rate). Each method's
    foot skate on the clip's contacts (:func:`foot_skate_rows`) comes with it, and
    the clip's own as :data:`GROUND_TRUTH` (when the skeleton has legs).

    Args:
        clips: The held-out clips.
        reconstruct: The model's output for a clip, on the clip's skeleton.

    Returns:
        Rows for :class:`Evaluation` with :data:`RECONSTRUCTION_METRICS`.
    """
    rows = []
    for clip in track(clips, "held-out clips"):
        pred = reconstruct(clip)
        if pred.fps != clip.fps:
            pred = pred.resample(clip.fps)
        truth_m, pred_m = clip.to_metres(), pred.to_metres()
        frames = min(truth_m.num_frames, pred_m.num_frames)
        truth = truth_m.global_positions()[:frames].double()
        height = truth_m.skeleton.height()
        guesses = {
            MODEL: pred_m.global_positions()[:frames].double(),
            "mean_pose": mean_pose(truth),
            "mean_pose_on_trajectory": mean_pose_on_trajectory(truth),
        }
        sk = truth_m.skeleton
        skates = foot_skate_rows(guesses, truth, skate_feet(sk), clip.fps, sk.up_index, height)
        values = {}
        for method, guess in guesses.items():
            err = float((guess - truth).norm(dim=-1).mean())
            values[method] = {"mpjpe_cm": 100.0 * err, "mpjpe_over_height": err / height}
            values[method] |= skates.get(method, {})
        if skates:
            values[GROUND_TRUTH] = skates[GROUND_TRUTH]
        rows.append({"clip": str(clip.name), "frames": frames, "values": values})
    return rows


def mean_rows(rows: Sequence[Mapping[str, Any]]) -> dict[str, dict[str, float]]:
    """``method -> metric -> mean`` over the rows that have the value (NaN values skipped)."""
    sums: dict[str, dict[str, list[float]]] = {}
    for row in rows:
        for method, values in row["values"].items():
            for metric, value in values.items():
                if value is not None and math.isfinite(float(value)):
                    sums.setdefault(method, {}).setdefault(metric, []).append(float(value))
    return {m: {k: sum(v) / len(v) for k, v in per.items()} for m, per in sums.items()}


def _check(result: Evaluation, protocol: str) -> None:
    if not isinstance(result, Evaluation):
        raise EvaluationError(
            f"protocol {protocol!r} returned {type(result).__name__}, not an Evaluation"
        )
    if not result.rows:
        raise EvaluationError(
            f"protocol {protocol!r}: no held-out clip could be evaluated "
            "(too short for the protocol?)"
        )
    if MODEL not in result.methods:
        raise EvaluationError(f"protocol {protocol!r}: no row has values of {MODEL!r}")
    for row in result.rows:
        unknown = {k for v in row["values"].values() for k in v} - set(result.metrics)
        if unknown:
            raise EvaluationError(
                f"protocol {protocol!r}: clip {row.get('clip')!r} has metrics "
                f"without a description: {sorted(unknown)}"
            )


def _fmt(value: float | None) -> str:
    return "-" if value is None else f"{value:.4g}"


def markdown(report: Mapping[str, Any]) -> str:
    """``evaluation.md``: the header, the mean table (metrics x methods) and per-clip rows.

    Names (protocol, model, checkpoint, data source, methods, metrics, clips) are
    written with :func:`~skelagnostic.io.markdown.markdown_cell`, so each shows literally.
    """
    methods = report["methods"]
    data = report["data"]
    lines = [
        f"# Evaluation: {markdown_cell(report['protocol'])}",
        "",
        report.get("description", ""),
        "",
        f"- model: {markdown_cell(report['model'], code=True)}, "
        f"checkpoint {markdown_cell(report['checkpoint'], code=True)}",
        f"- data: {markdown_cell(data['source'], code=True)}, "
        f"{markdown_cell(data['split_name'])} ({len(data['clips'])} clips)",
        "",
        f"## Mean over {_clips_kind(data.get('split'))}",
        "",
        "| metric | " + " | ".join(map(markdown_cell, methods)) + " |",
        "|---" * (len(methods) + 1) + "|",
    ]
    for metric, text in report["metrics"].items():
        cells = [_fmt(report["mean"].get(m, {}).get(metric)) for m in methods]
        lines.append(f"| {markdown_cell(f'{metric} ({text})')} | " + " | ".join(cells) + " |")
    if report.get("notes"):
        lines += ["", *(f"- {n}" for n in report["notes"])]
    lines += ["", "## Per clip", ""]
    metrics = list(report["metrics"])
    lines.append("| clip | method | " + " | ".join(map(markdown_cell, metrics)) + " |")
    lines.append("|---" * (len(metrics) + 2) + "|")
    for row in report["per_clip"]:
        for method in methods:
            if method in row["values"]:
                cells = [_fmt(row["values"][method].get(k)) for k in metrics]
                names = f"| {markdown_cell(row['clip'])} | {markdown_cell(method)} | "
                lines.append(names + " | ".join(cells) + " |")
    if report.get("plots"):
        lines += ["", "## Plots", "", *(f"![{p}]({p})" for p in report["plots"])]
    return "\n".join(lines) + "\n"


_SPLIT_NAMES = {
    "test": "test split",
    "val": "validation split",
    "heldout": "validation and test splits",
    "train": "training split (clips the model trained on, not held out)",
}
#: The first note of a report on the training clips (``split=train``).
_TRAINING_NOTE = (
    "evaluated on the run's training clips (split=train), not on held-out clips: the "
    "model trained on every clip here; where the protocol says held-out, read training"
)


def _clips_kind(split: str | None) -> str:
    """What the mean table averages over: held-out clips, or training clips (``split=train``)."""
    return "training clips (not held out)" if split == "train" else "held-out clips"


#: The split's name when ``evaluate`` falls back to the validation split.
_NO_TEST = "validation split (the data has no test split)"


#: A clip id that is a file path, optionally behind a ``label:`` of a combined source.
_PATH_ID = re.compile(r"^(?P<label>[^/\\:]+:)?(?P<path>/.+)$")


def portable_names(names: Sequence[str]) -> dict[str, str]:
    """Clip ids without this machine's folders, as ``evaluation.json`` writes them.

    Ids that are absolute file paths are written relative to the deepest folder
    all of them share, or to its parent when a file lies in that folder itself:
    LaFAN1 and MANN dog clips of ``/data/sets/lafan1`` and
    ``/data/sets/mann_dog`` become ``lafan1/<file>`` and ``mann_dog/<file>``; the
    clips of one folder ``/data/sets/lafan1`` ``lafan1/<file>``. A ``label:``
    before a path (the parts of a combined source) is kept. Other ids
    (procedural clips, windows) are kept as they are.

    Args:
        names: Clip ids (each may appear more than once).

    Returns:
        ``id -> portable name`` for every distinct id.

    Examples:
        >>> names = portable_names(["/d/lafan1/a.bvh", "/d/mann_dog/b.bvh", "walk_3"])
        >>> names["/d/lafan1/a.bvh"], names["/d/mann_dog/b.bvh"], names["walk_3"]
        ('lafan1/a.bvh', 'mann_dog/b.bvh', 'walk_3')
        >>> portable_names(["human:/d/lafan1/a.bvh"])["human:/d/lafan1/a.bvh"]
        'human:lafan1/a.bvh'
    """
    matches = {n: _PATH_ID.match(n) for n in dict.fromkeys(map(str, names))}
    folders = [os.path.dirname(m["path"]) for m in matches.values() if m]
    if not folders:
        return {n: n for n in matches}
    common = os.path.commonpath(folders)
    base = os.path.dirname(common) if common in folders else common
    return {
        n: f"{m['label'] or ''}{os.path.relpath(m['path'], base)}" if m else n
        for n, m in matches.items()
    }


def _renamed(value: Any, names: Mapping[str, str]) -> Any:
    """``value`` with every string (or mapping key) that is a clip id in ``names`` renamed."""
    if isinstance(value, Mapping):
        return {
            names.get(k, k) if isinstance(k, str) else k: _renamed(v, names)
            for k, v in value.items()
        }
    if isinstance(value, list | tuple):
        return [_renamed(v, names) for v in value]
    return names.get(value, value) if isinstance(value, str) else value


def write_evaluation(
    result: Evaluation,
    out_dir: str | Path,
    *,
    protocol: str,
    model: str,
    description: str,
    checkpoint: str,
    data: Mapping[str, Any],
    held: HeldOut,
) -> dict[str, Any]:
    """Write ``evaluation.json``, ``evaluation.md`` and ``evaluation.png`` into ``out_dir``.

    Args:
        result: What the protocol returned.
        out_dir: The run directory.
        protocol: The protocol name.
        model: The aligner name.
        description: The protocol's description.
        checkpoint: The evaluated checkpoint file.
        data: The run's data config (plain values).
        held: The held-out clips the protocol received.

    Returns:
        The report written to ``evaluation.json``.

    Raises:
        EvaluationError: The result is malformed (no rows, no model values, a metric
            without description).
    """
    from skelagnostic import __version__
    from skelagnostic.viz import plot_method_comparison

    _check(result, protocol)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    mean = mean_rows(result.rows)
    portable = portable_names([*held.names, *(str(row["clip"]) for row in result.rows)])
    rows = [{**row, "clip": portable[str(row["clip"])]} for row in result.rows]
    extra = _renamed(result.extra, portable)
    plot_method_comparison(mean, title=protocol, out=out / "evaluation.png")
    report = {
        "schema": SCHEMA_VERSION,
        "skelagnostic_version": __version__,
        "protocol": protocol,
        "description": description,
        "model": model,
        "checkpoint": str(checkpoint),
        "data": {
            "source": data.get("source"),
            "split": held.split,
            "split_name": held.name,
            "clips": [portable[n] for n in held.names],
            "config": dict(data),
        },
        "methods": result.methods,
        "metrics": dict(result.metrics),
        "mean": mean,
        "per_clip": rows,
        "extra": extra,
        "plots": ["evaluation.png", *result.plots],
        "notes": [_TRAINING_NOTE, *result.notes] if held.is_training else list(result.notes),
    }
    write_output(out / "evaluation.json", json.dumps(report, indent=1) + "\n")
    write_output(out / "evaluation.md", markdown(report))
    return report
