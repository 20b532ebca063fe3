"""Write an :class:`~skelagnostic.evaluation.protocol.Evaluation`: JSON, Markdown and a plot.

:func:`write_evaluation` checks what a protocol returned and writes
``evaluation.json``, ``evaluation.md`` (:func:`markdown`) and ``evaluation.png``;
clip ids that are file paths lose this machine's folders (:func:`portable_names`).
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from skelagnostic.evaluation.protocol import MODEL, Evaluation, EvaluationError, HeldOut, mean_rows
from skelagnostic.io.markdown import markdown_cell
from skelagnostic.io.outputs import write_output

#: Version of the layout of ``evaluation.json``.
SCHEMA_VERSION = 1


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


#: The first note of a report on the training clips (``split=train``).
_TRAINING_NOTE = (
    "evaluated on the run's training clips (split=train), not on held-out clips: the "
    "model trained on every clip here; where the protocol says held-out, read training"
)


def _clips_kind(split: str | None) -> str:
    """What the mean table averages over: held-out clips, or training clips (``split=train``)."""
    return "training clips (not held out)" if split == "train" else "held-out clips"


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
