"""Lightning callback that writes what a person looks at after training.

At the end of ``fit`` :class:`FitSummary` writes into the run directory:

* ``<name>_metrics.json``: the last logged metrics (``trainer.callback_metrics``)
  plus the figures the aligner computes for its summary;
* ``<name>_<key>.gif`` and ``<name>_<key>.png`` (a contact sheet) for every
  motion the aligner wants rendered, ``<name>_<key>.png`` for every matplotlib
  figure it draws;
* ``summary.md``: the run in one page (metrics table, the aligner's figures,
  links to the pictures).

Aligners contribute through one method, :meth:`Aligner.fit_summary
<skelagnostic.aligners.Aligner.fit_summary>`, which returns a
:class:`SummaryContent` mapping; they write no files themselves.

How much the aligner computes is the run's ``summary=`` key (:data:`SUMMARY_MODES`):
``full``, ``quick`` (a smoke run's summary: seconds), ``none`` (only the logged
metrics) or ``auto``: ``quick`` for runs of fewer than :data:`QUICK_BELOW_STEPS`
optimiser steps, else ``full``. ``summary.md`` and the metrics (``"summary"``) say
which one ran and why.
"""

from __future__ import annotations

import inspect
import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, TypedDict

import lightning.pytorch as pl
import torch
from lightning.pytorch.utilities import rank_zero_only

from skelagnostic.io.markdown import markdown_cell
from skelagnostic.io.outputs import write_output

__all__ = ["QUICK_BELOW_STEPS", "SUMMARY_MODES", "FitSummary", "SummaryContent", "summary_mode"]

#: The values of ``summary=`` (``FitSummary(mode=...)``).
SUMMARY_MODES = ("auto", "full", "quick", "none")

#: ``summary=auto`` is ``quick`` for runs of fewer optimiser steps than this, else ``full``.
QUICK_BELOW_STEPS = 1000


def summary_mode(mode: str, steps: int, quick_below: int = QUICK_BELOW_STEPS) -> tuple[str, str]:
    """The summary a run gets, and why: ``(full | quick | none, reason)``.

    Args:
        mode: ``summary=`` (one of :data:`SUMMARY_MODES`).
        steps: Optimiser steps the run made.
        quick_below: ``auto`` picks ``quick`` below this many steps.

    Example:
        >>> summary_mode("auto", 20)
        ('quick', 'summary=auto: 20 optimiser steps, fewer than 1000')
        >>> summary_mode("none", 20)[0]
        'none'
    """
    if mode not in SUMMARY_MODES:
        raise ValueError(f"summary must be one of {', '.join(SUMMARY_MODES)}, got {mode!r}")
    if mode != "auto":
        return mode, f"summary={mode}"
    if steps < quick_below:
        return "quick", f"summary=auto: {steps} optimiser steps, fewer than {quick_below}"
    return "full", f"summary=auto: {steps} optimiser steps, at least {quick_below}"


class SummaryContent(TypedDict, total=False):
    """What :meth:`Aligner.fit_summary <skelagnostic.aligners.Aligner.fit_summary>` returns.

    Every key is optional.

    Attributes:
        metrics: JSON-serialisable figures (numbers, strings, ``None``, nested
            dicts and lists) merged over the logged metrics in ``<name>_metrics.json``.
        renders: ``{key: motions}``: each value is what
            :func:`skelagnostic.viz.render_motion` draws (``Motion`` or
            ``StickFigure``, or a list of them), written as ``<name>_<key>.gif``
            and a contact sheet ``<name>_<key>.png`` (the GIF only when
            ``figures`` has the same key: the figure is that PNG).
        render_options: ``{key: options}``: keyword arguments of
            :func:`skelagnostic.viz.render_motion` for the render of that key (for
            example ``size``, ``labels``, ``fps``, ``follow``, ``same_scale``), over
            the callback's ``size`` and ``sheet_frames``.
        figures: ``{key: matplotlib Figure}``, saved as ``<name>_<key>.png`` (and closed).
        notes: Markdown paragraphs appended to ``summary.md``.
        headline: Markdown paragraphs placed at the top of ``summary.md``, under the
            run's step count (the one finding a reader must not miss).
    """

    metrics: dict[str, Any]
    renders: dict[str, Any]
    render_options: dict[str, dict[str, Any]]
    figures: dict[str, Any]
    notes: list[str]
    headline: list[str]


def _plain(value: Any) -> Any:
    """``value`` with tensors and numpy scalars turned into Python numbers (for JSON)."""
    if isinstance(value, torch.Tensor):
        return value.item() if value.numel() == 1 else value.tolist()
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if hasattr(value, "item") and callable(value.item):  # numpy scalars
        return value.item()
    return value


def _cell(value: Any) -> str:
    if isinstance(value, float):
        return "n/a" if math.isnan(value) else f"{value:.6g}"
    return "n/a" if value is None else str(value)


class FitSummary(pl.Callback):
    """Write the metrics, renders and ``summary.md`` of a finished fit (global rank 0 only).

    On by default for ``skelagnostic fit`` (``conf/callbacks/default.yaml``,
    ``name: ${model.name}``).

    Args:
        name: Prefix of the written files (``humot`` gives ``humot_metrics.json``);
            ``None``: no prefix (``metrics.json``).
        dirpath: Output directory (default: ``trainer.default_root_dir``).
        size: Panel size in pixels of the renders (a render's ``render_options`` may set its own).
        sheet_frames: Frames on each render's contact sheet.
        mode: How much the aligner computes (:data:`SUMMARY_MODES`, the run's
            ``summary=``): ``full``; ``quick``, a smaller summary that takes
            seconds; ``none``, no aligner summary (the logged metrics and
            ``summary.md`` only); ``auto``, :func:`summary_mode`. An aligner whose
            ``fit_summary`` takes no ``mode`` argument computes its one summary.
        quick_below: ``auto`` is ``quick`` for runs of fewer optimiser steps.

    Example:
        >>> import lightning as L
        >>> trainer = L.Trainer(callbacks=[FitSummary(name="example")], logger=False)
    """

    def __init__(
        self,
        name: str | None = None,
        dirpath: str | Path | None = None,
        size: tuple[int, int] | Sequence[int] = (200, 200),
        sheet_frames: int = 4,
        mode: str = "auto",
        quick_below: int = QUICK_BELOW_STEPS,
    ) -> None:
        if sheet_frames < 1:
            raise ValueError(f"FitSummary: sheet_frames must be >= 1, got {sheet_frames}")
        if mode not in SUMMARY_MODES:
            raise ValueError(
                f"FitSummary: mode (summary=) must be one of {', '.join(SUMMARY_MODES)}, "
                f"got {mode!r}"
            )
        self.mode = mode
        self.quick_below = int(quick_below)
        self.name = name
        self.dirpath = Path(dirpath) if dirpath is not None else None
        self.size = (int(size[0]), int(size[1]))
        self.sheet_frames = int(sheet_frames)
        #: The files written by the last :meth:`on_fit_end`.
        self.written: list[Path] = []

    def _file(self, directory: Path, stem: str, suffix: str) -> Path:
        return directory / (f"{self.name}_{stem}{suffix}" if self.name else f"{stem}{suffix}")

    @rank_zero_only
    def on_fit_end(self, trainer: pl.Trainer, pl_module: pl.LightningModule) -> None:
        """Ask the module for its summary and write the files."""
        directory = self.dirpath or Path(trainer.default_root_dir)
        directory.mkdir(parents=True, exist_ok=True)
        content: SummaryContent = {}
        summarise = getattr(pl_module, "fit_summary", None)
        if callable(summarise):
            mode, reason = summary_mode(self.mode, int(trainer.global_step), self.quick_below)
            if mode != "none":
                takes_mode = "mode" in inspect.signature(summarise).parameters
                if not takes_mode:
                    mode, reason = "full", f"{reason}; the aligner has one summary"
                was_training = pl_module.training
                pl_module.eval()
                try:
                    with torch.no_grad():
                        made = summarise(trainer, mode=mode) if takes_mode else summarise(trainer)
                finally:
                    pl_module.train(was_training)
                content = made or {}
            chosen = {"summary": {"mode": mode, "reason": reason}}
            content = {**content, "metrics": {**chosen, **content.get("metrics", {})}}
        self.written = self.write(trainer, content, directory)

    def write(self, trainer: pl.Trainer, content: SummaryContent, directory: Path) -> list[Path]:
        """Write the files of ``content`` into ``directory``; the written paths.

        Args:
            trainer: The trainer (its logged metrics, epoch and step).
            content: What the module returned from ``fit_summary``.
            directory: Output directory (exists).
        """
        logged = {k: _plain(v) for k, v in trainer.callback_metrics.items()}
        metrics = {**logged, **_plain(content.get("metrics", {}))}
        written = [self._file(directory, "metrics", ".json")]
        write_output(written[0], json.dumps(metrics, indent=2) + "\n")
        pictures: list[tuple[str, Path]] = []
        if content.get("renders"):
            from rich.console import Console

            from skelagnostic.viz import render_motion

            console = Console(stderr=True, highlight=False)
            for key, motions in content["renders"].items():
                # a figure of the same key takes the .png: the render is the animation only
                suffixes = (".gif",) if key in content.get("figures", {}) else (".gif", ".png")
                options = {
                    "size": self.size,
                    "sheet_frames": self.sheet_frames,
                    **content.get("render_options", {}).get(key, {}),
                }
                for suffix in suffixes:
                    path = self._file(directory, key, suffix)
                    console.print(f"[bold]fit summary[/bold]: rendering {path.name}")
                    render_motion(motions, path, **options)
                    written.append(path)
                pictures.append((key, self._file(directory, key, ".gif")))
        if content.get("figures"):
            import matplotlib.pyplot as plt

            for key, figure in content["figures"].items():
                path = self._file(directory, key, ".png")
                write_output(path, lambda fh, figure=figure: figure.savefig(fh, format="png"))
                plt.close(figure)
                written.append(path)
                pictures.append((key, path))
        summary = directory / "summary.md"
        write_output(summary, self._markdown(trainer, logged, content, written[0], pictures))
        written.append(summary)
        return written

    def _markdown(
        self,
        trainer: pl.Trainer,
        logged: Mapping[str, Any],
        content: SummaryContent,
        metrics_file: Path,
        pictures: list[tuple[str, Path]],
    ) -> str:
        from skelagnostic.callbacks.stopping import stop_reason

        title = f"Fit summary: {markdown_cell(self.name)}" if self.name else "Fit summary"
        stopped = stop_reason(trainer) if isinstance(trainer, pl.Trainer) else None
        lines = [
            f"# {title}",
            "",
            f"{trainer.current_epoch} epoch(s), {trainer.global_step} optimiser step(s)"
            + (f"; stopped: {stopped}" if stopped else "")
            + f". Every figure is in `{metrics_file.name}`.",
            "",
        ]
        for paragraph in content.get("headline", []):
            lines += [paragraph, ""]
        chosen = content.get("metrics", {}).get("summary")
        if isinstance(chosen, Mapping):
            what = {
                "full": "the aligner's full summary",
                "quick": "the aligner's quick summary (fewer clips, shorter excerpts)",
                "none": "no aligner summary: the logged metrics only",
            }.get(str(chosen.get("mode")), str(chosen.get("mode")))
            lines += [
                f"Summary: {what} ({chosen.get('reason')}; `summary=full|quick|none` chooses).",
                "",
            ]
        if logged:
            lines += ["## Last logged metrics", "", "| metric | value |", "|---|---|"]
            lines += [
                f"| {markdown_cell(k, code=True)} | {markdown_cell(_cell(v))} |"
                for k, v in sorted(logged.items())
            ]
            lines.append("")
        own = {k: v for k, v in _plain(content.get("metrics", {})).items()}
        if own:
            lines += ["## Summary figures", "", "| figure | value |", "|---|---|"]
            for key, value in own.items():
                shown = json.dumps(value) if isinstance(value, (dict, list)) else _cell(value)
                shown = markdown_cell(shown)
                if len(shown) > 200:  # a nested record: its table is a note, its data the JSON
                    shown = f"see {markdown_cell(key, code=True)} in `{metrics_file.name}`"
                lines.append(f"| {markdown_cell(key, code=True)} | {shown} |")
            lines.append("")
        if pictures:
            lines += ["## Pictures", ""]
            lines += [f"![{key}]({path.name})" for key, path in pictures]
            lines.append("")
        for note in content.get("notes", []):
            lines += [note, ""]
        return "\n".join(lines)
