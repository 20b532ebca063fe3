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
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, TypedDict

import lightning.pytorch as pl
import torch
from lightning.pytorch.utilities import rank_zero_only

from skelagnostic.io.outputs import write_output

__all__ = ["FitSummary", "SummaryContent"]


class SummaryContent(TypedDict, total=False):
    """What :meth:`Aligner.fit_summary <skelagnostic.aligners.Aligner.fit_summary>` returns.

    Every key is optional.

    Attributes:
        metrics: JSON-serialisable figures (numbers, strings, ``None``, nested
            dicts and lists) merged over the logged metrics in ``<name>_metrics.json``.
        renders: ``{key: motions}``: each value is what
            :func:`skelagnostic.viz.render_motion` draws (``Motion`` or
            ``StickFigure``, or a list of them), written as ``<name>_<key>.gif``
            and a contact sheet ``<name>_<key>.png``.
        figures: ``{key: matplotlib Figure}``, saved as ``<name>_<key>.png`` (and closed).
        notes: Markdown paragraphs appended to ``summary.md``.
    """

    metrics: dict[str, Any]
    renders: dict[str, Any]
    figures: dict[str, Any]
    notes: list[str]


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
        size: Frame size in pixels of the renders.
        sheet_frames: Frames on each render's contact sheet.

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
    ) -> None:
        if sheet_frames < 1:
            raise ValueError(f"FitSummary: sheet_frames must be >= 1, got {sheet_frames}")
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
            was_training = pl_module.training
            pl_module.eval()
            try:
                with torch.no_grad():
                    content = summarise(trainer) or {}
            finally:
                pl_module.train(was_training)
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
            from skelagnostic.viz import render_motion

            for key, motions in content["renders"].items():
                for suffix in (".gif", ".png"):
                    path = self._file(directory, key, suffix)
                    render_motion(motions, path, size=self.size, sheet_frames=self.sheet_frames)
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
        title = f"Fit summary: {self.name}" if self.name else "Fit summary"
        lines = [
            f"# {title}",
            "",
            f"{trainer.current_epoch} epoch(s), {trainer.global_step} optimiser step(s). "
            f"Every figure is in `{metrics_file.name}`.",
            "",
        ]
        if logged:
            lines += ["## Last logged metrics", "", "| metric | value |", "|---|---|"]
            lines += [f"| `{k}` | {_cell(v)} |" for k, v in sorted(logged.items())]
            lines.append("")
        own = {k: v for k, v in _plain(content.get("metrics", {})).items()}
        if own:
            lines += ["## Summary figures", "", "| figure | value |", "|---|---|"]
            for key, value in own.items():
                shown = json.dumps(value) if isinstance(value, (dict, list)) else _cell(value)
                if len(shown) > 200:  # a nested record: its table is a note, its data the JSON
                    shown = f"see `{key}` in `{metrics_file.name}`"
                lines.append(f"| `{key}` | {shown} |")
            lines.append("")
        if pictures:
            lines += ["## Pictures", ""]
            lines += [f"![{key}]({path.name})" for key, path in pictures]
            lines.append("")
        for note in content.get("notes", []):
            lines += [note, ""]
        return "\n".join(lines)
