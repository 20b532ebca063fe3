"""Lightning callback that renders a validation sample every few epochs.

The model decides what to draw through a one-method protocol
(:class:`RenderSampleSource`): given the first validation batch of the epoch it
returns the motions to show, e.g. ``{"input": x, "output": y, "target": gt}``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import lightning.pytorch as pl
import torch
from lightning.pytorch.utilities import rank_zero_warn
from PIL import Image

from skelagnostic.callbacks.loggers import log_image
from skelagnostic.io.outputs import write_output
from skelagnostic.viz.html import to_html
from skelagnostic.viz.render import contact_sheet, render_frames, write_animation
from skelagnostic.viz.stick import RenderError

if TYPE_CHECKING:
    from skelagnostic import Motion
    from skelagnostic.viz.stick import StickFigure

__all__ = ["RenderSampleSource", "RenderSamples"]


@runtime_checkable
class RenderSampleSource(Protocol):
    """What a LightningModule implements to be rendered by :class:`RenderSamples`."""

    def render_sample(
        self, batch: Any
    ) -> Sequence[Motion | StickFigure] | Mapping[str, Motion | StickFigure]:
        """Motions to draw for one validation batch.

        Args:
            batch: The first batch of the validation epoch, as the dataloader
                yields it (already on the module's device).

        Returns:
            The motions to draw; with a mapping, its keys label the characters
            (e.g. ``{"input": ..., "output": ..., "target": ...}``).
        """
        ...


class RenderSamples(pl.Callback):
    """Render a validation sample to the run directory every ``every_n_epochs`` epochs.

    At the end of a due validation epoch (and of the last epoch, when
    ``trainer.max_epochs`` is known), the callback hands the epoch's first
    validation batch to ``pl_module.render_sample(batch)`` (see
    :class:`RenderSampleSource`) and writes ``epoch{N:04d}.gif`` and a contact
    sheet ``epoch{N:04d}.png`` (and with ``html=True`` the 3D viewer page
    ``epoch{N:04d}.html``) to ``dirpath``. Every attached logger that takes
    images (TensorBoard, tensorboardX, Weights & Biases, MLflow:
    :func:`~skelagnostic.callbacks.loggers.log_image`) also receives the contact
    sheet under ``tag``. Only global
    rank 0 renders; the sanity check is skipped. A module without
    ``render_sample`` gets one warning and no renders.

    Args:
        every_n_epochs: Render after every ``n``-th validation epoch.
        dirpath: Output directory (default: ``<trainer.default_root_dir>/renders``).
        mode: ``"side"`` or ``"overlay"`` (see :func:`skelagnostic.viz.render_frames`).
        max_frames: Cap on the number of animation frames (clock subsampled).
        size: ``(width, height)`` of one panel in pixels.
        sheet_frames: Number of frames on the contact sheet (one row).
        tag: Image tag for the loggers.
        html: Also write ``epochNNNN.html``, the interactive 3D viewer of
            :func:`skelagnostic.viz.to_html` (one self-contained page).

    Raises:
        RenderError: If ``every_n_epochs`` or ``sheet_frames`` is not positive,
            or ``mode`` is unknown.

    Examples:
        >>> from skelagnostic.callbacks import RenderSamples
        >>> RenderSamples(every_n_epochs=10, mode="overlay").every_n_epochs
        10
    """

    def __init__(
        self,
        every_n_epochs: int = 5,
        dirpath: str | Path | None = None,
        mode: str = "side",
        max_frames: int = 60,
        size: tuple[int, int] = (240, 240),
        sheet_frames: int = 6,
        tag: str = "val/render",
        html: bool = False,
    ) -> None:
        if every_n_epochs < 1:
            raise RenderError(f"every_n_epochs must be at least 1, got {every_n_epochs}")
        if sheet_frames < 1:
            raise RenderError(f"sheet_frames must be at least 1, got {sheet_frames}")
        if mode not in ("side", "overlay"):
            raise RenderError(f"mode must be 'side' or 'overlay', got {mode!r}")
        self.every_n_epochs = every_n_epochs
        self.dirpath = None if dirpath is None else Path(dirpath)
        self.mode = mode
        self.max_frames = max_frames
        self.size = (int(size[0]), int(size[1]))
        self.sheet_frames = sheet_frames
        self.tag = tag
        self.html = bool(html)
        #: Viewer page written by the most recent render (``html=True``).
        self.last_html: Path | None = None
        #: Paths written by the most recent render (GIF, PNG).
        self.last_paths: tuple[Path, Path] | None = None
        self._batch: Any = None
        self._warned = False

    def _due(self, trainer: pl.Trainer) -> bool:
        if trainer.sanity_checking or not trainer.is_global_zero:
            return False
        epoch = trainer.current_epoch + 1
        last = trainer.max_epochs is not None and trainer.max_epochs > 0
        return epoch % self.every_n_epochs == 0 or (last and epoch == trainer.max_epochs)

    def on_validation_batch_end(
        self,
        trainer: pl.Trainer,
        pl_module: pl.LightningModule,
        outputs: Any,
        batch: Any,
        batch_idx: int,
        dataloader_idx: int = 0,
    ) -> None:
        """Keep the first batch of the first validation dataloader of a due epoch."""
        if batch_idx == 0 and dataloader_idx == 0 and self._due(trainer):
            self._batch = batch

    def on_validation_epoch_end(self, trainer: pl.Trainer, pl_module: pl.LightningModule) -> None:
        """Render the kept batch, write GIF + PNG and log the PNG to image loggers."""
        batch, self._batch = self._batch, None
        if batch is None or not self._due(trainer):
            return
        if not isinstance(pl_module, RenderSampleSource):
            if not self._warned:
                rank_zero_warn(
                    f"RenderSamples: {type(pl_module).__name__} has no render_sample(batch) "
                    "method, so no validation renders are written"
                )
                self._warned = True
            return
        with torch.no_grad():
            sample = pl_module.render_sample(batch)
        labels = None
        if isinstance(sample, Mapping):
            labels, sample = list(sample), list(sample.values())
        rendering = render_frames(
            sample, mode=self.mode, labels=labels, max_frames=self.max_frames, size=self.size
        )
        directory = self.dirpath or Path(trainer.default_root_dir) / "renders"
        stem = f"epoch{trainer.current_epoch:04d}"
        gif = write_animation(rendering, directory / f"{stem}.gif")
        sheet = contact_sheet(rendering, frames=self.sheet_frames, columns=self.sheet_frames)
        png = directory / f"{stem}.png"
        picture = Image.fromarray(sheet)
        write_output(png, lambda fh: picture.save(fh, format="PNG"), "renders")
        self.last_paths = (gif, png)
        if self.html:
            self.last_html = directory / f"{stem}.html"
            to_html(sample, names=labels, out=self.last_html, mode=self.mode)
        log_image(trainer.loggers, self.tag, sheet, trainer.global_step)
