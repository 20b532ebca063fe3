"""``skelagnostic evaluate``: a registered protocol on the held-out clips of a run.

``skelagnostic evaluate ckpt_path=RUN_OR_CKPT [protocol=NAME] [+protocol_options.KEY=VALUE]
[split=test|val|heldout|train] [cleanup=footlock] [overrides]`` takes the model and data of
the checkpoint's run (as ``validate`` and ``test`` do), loads the weights, collects the run's
test clips (else its validation clips; ``split=`` chooses,
:func:`~skelagnostic.evaluation.held_out`; ``train``: the training clips, labelled as not
held out), runs the protocol (default: the model's default protocol; ``protocol_options``
become its keyword arguments) and writes ``evaluation.json``, ``evaluation.md`` and plots
into its own run directory (``runs/<model>/evaluate/<time>``); see :mod:`skelagnostic.evaluation`.
``cleanup=footlock`` also measures :func:`skelagnostic.cleanup.foot_lock` on the
model's output of every clip (:func:`measure_cleanup`).
"""

from __future__ import annotations

import inspect
import math
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch
from omegaconf import DictConfig, OmegaConf

from skelagnostic.aligners.checkpoints import load_checkpoint
from skelagnostic.evaluation import (
    MODEL,
    Evaluation,
    EvaluationError,
    held_out,
    track,
    write_evaluation,
)
from skelagnostic.plugins import PluginManager

__all__ = [
    "CLEANUPS",
    "evaluate_checkpoint",
    "measure_cleanup",
    "print_evaluation",
]

#: The values of ``evaluate cleanup=``.
CLEANUPS = ("none", "footlock")


def evaluate_checkpoint(
    cfg: DictConfig,
    pm: PluginManager,
    module: type,
    datamodule: Any,
    ckpt: str,
    aligner: Any | None = None,
) -> dict[str, float]:
    """Load the checkpoint, run the protocol of ``cfg.protocol`` and write its report.

    The aligner is rebuilt from the checkpoint as the inference verbs do
    (:func:`~skelagnostic.aligners.checkpoints.load_checkpoint`: its saved
    hyperparameters, which include the layers an aligner builds from its data).

    Args:
        cfg: The composed config (``model``, ``data``, ``protocol``, ``run_dir``, optional
            ``protocol_options``: keyword arguments of the protocol function, optional
            ``split``: which held-out clips, :func:`~skelagnostic.evaluation.held_out`;
            optional ``cleanup``: ``footlock`` adds :func:`measure_cleanup`).
        pm: Where the protocol is looked up.
        module: The aligner class of ``cfg.model.name``.
        datamodule: The data module built from ``cfg.data``.
        ckpt: The checkpoint file (or the ``<scheme>:<path>`` of ``aligner``).
        aligner: The aligner already built by a plugin's checkpoint reader
            (``ckpt_path=<scheme>:<path>``; ``None``: load ``ckpt``). It is evaluated
            on the held-out clips of ``cfg.data``.

    Returns:
        The model's mean figures, ``model/<metric>``.

    Raises:
        PluginError: Unknown protocol, or one of another model (the message lists the
            model's protocols).
        EvaluationError: No held-out split, the protocol found nothing to evaluate,
            ``protocol_options`` names an argument the protocol does not take, or
            ``cleanup`` is unknown or the protocol has no output motions to clean.
    """
    protocol = pm.evaluation(cfg.get("protocol"), cfg.model.name)
    options = _protocol_options(cfg, protocol.name, protocol.function)
    cleanup = str(cfg.get("cleanup") or "none")
    if cleanup not in CLEANUPS:
        raise EvaluationError(f"cleanup={cleanup!r}: must be one of {', '.join(CLEANUPS)}")
    if aligner is None:
        aligner = load_checkpoint(
            module, ckpt, option="ckpt_path", aligners=pm.aligner_classes()
        ).eval()
    held = held_out(datamodule, cfg.get("split"))
    run_dir = Path(cfg.run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    with torch.no_grad():
        result = protocol.function(aligner, held, run_dir, **options)
        if cleanup == "footlock":
            measure_cleanup(result, protocol.name)
    data = OmegaConf.to_container(cfg.data, resolve=True)
    report = write_evaluation(
        result,
        run_dir,
        protocol=protocol.name,
        model=cfg.model.name,
        description=protocol.description,
        checkpoint=ckpt,
        data=data,  # type: ignore[arg-type]
        held=held,
    )
    print_evaluation(report, run_dir)
    return {f"{MODEL}/{k}": v for k, v in report["mean"][MODEL].items()}


def measure_cleanup(result: Evaluation, protocol: str) -> Evaluation:
    """Add :func:`~skelagnostic.cleanup.foot_lock_figures` of every model output to ``result``.

    For each clip of ``result.outputs`` the model's output motion is made, cleaned
    with :func:`~skelagnostic.cleanup.foot_lock` (contacts detected on the output, as
    ``cleanup=footlock`` on the verbs) and measured; the figures
    (:data:`~skelagnostic.cleanup.FOOT_LOCK_METRICS`) join the :data:`MODEL` values of
    the clip's row (a new row for a clip without one). Undefined figures (no skate
    to reduce) are left out.

    Args:
        result: What the protocol returned; changed in place.
        protocol: Its name, for messages.

    Returns:
        ``result``.

    Raises:
        EvaluationError: The protocol hands over no output motion, or an output cannot
            be cleaned (a rig without legs); the message names the clip.
    """
    from skelagnostic.cleanup import FOOT_LOCK_METRICS, foot_lock_figures
    from skelagnostic.errors import SkelagnosticError

    if not result.outputs:
        raise EvaluationError(
            f"cleanup=footlock: protocol {protocol!r} hands over no output motion of the model "
            "(Evaluation.outputs is empty); choose a protocol with motion outputs, e.g. the "
            "models' default protocols"
        )
    rows = {str(row["clip"]): row for row in result.rows}
    for clip, make in track(list(result.outputs.items()), "cleanup=footlock: model outputs"):
        try:
            figures = foot_lock_figures(make())
        except SkelagnosticError as error:
            raise EvaluationError(f"cleanup=footlock: clip {clip!r}: {error}") from error
        if clip not in rows:
            rows[clip] = {"clip": clip, "values": {}}
            result.rows.append(rows[clip])
        values = rows[clip]["values"].setdefault(MODEL, {})
        values.update({k: v for k, v in figures.items() if math.isfinite(v)})
    result.metrics.update(FOOT_LOCK_METRICS)
    result.notes.append(
        "cleanup=footlock: the model's output of each clip "
        f"({len(result.outputs)} outputs) before and after skelagnostic.cleanup.foot_lock, "
        "contacts detected on the output (as cleanup=footlock on the verbs); footlock_* "
        "figures are in the model's column"
    )
    return result


def _protocol_options(cfg: DictConfig, name: str, function: Any) -> dict[str, Any]:
    """``cfg.protocol_options`` as keyword arguments of ``function``, checked by its signature."""
    raw = cfg.get("protocol_options")
    if raw is None:
        return {}
    options = OmegaConf.to_container(raw, resolve=True) if isinstance(raw, DictConfig) else raw
    if not isinstance(options, dict):
        raise EvaluationError(f"protocol_options must be a mapping, got {options!r}")
    params = inspect.signature(function).parameters
    accepted = [
        n
        for n, p in list(params.items())[3:]
        if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
    ]
    takes_any = any(p.kind is p.VAR_KEYWORD for p in params.values())
    unknown = sorted(set(options) - set(accepted))
    if unknown and not takes_any:
        raise EvaluationError(
            f"protocol_options: protocol {name!r} takes no option {unknown}; its options: "
            f"{accepted or 'none'}"
        )
    return dict(options)


def print_evaluation(report: Mapping[str, Any], run_dir: Path) -> None:
    """The mean table of an ``evaluation.json`` report, as one Rich table on stdout."""
    from rich.console import Console
    from rich.table import Table

    data = report["data"]
    table = Table(
        title=f"skelagnostic evaluate: {report['protocol']} on the "
        f"{data['split_name']}, {len(data['clips'])} clips",
        title_justify="left",
    )
    table.add_column("metric", style="bold", overflow="fold")  # wrapped, never cut
    for method in report["methods"]:
        table.add_column(method, justify="right", overflow="fold")
    for metric, text in report["metrics"].items():
        cells = [report["mean"].get(m, {}).get(metric) for m in report["methods"]]
        table.add_row(f"{metric} ({text})", *("-" if c is None else f"{c:.4g}" for c in cells))
    console = Console(file=sys.stdout, width=max(100, 30 * (len(report["methods"]) + 1)))
    console.print(table)
    console.print(f"report: {run_dir / 'evaluation.md'}")
