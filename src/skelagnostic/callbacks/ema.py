"""Exponential moving average of the weights that checks it covers every parameter.

Lightning's :class:`~lightning.pytorch.callbacks.EMAWeightAveraging` copies the
model into an :class:`~torch.optim.swa_utils.AveragedModel` in its ``setup``
hook, which Lightning runs *before* the LightningModule's own ``setup``. An
aligner that builds layers from the data module there (the usual place before
Lightning 2.1) would be averaged without those layers: the checkpoint's
``state_dict`` would lack them and loading it would fail. Lightning's answer is
the ``configure_model`` hook, which the callback calls before making its copy;
skelagnostic's aligners build their data-dependent layers there.
:class:`EMAWeights` adds a check of that contract with an error that says what
to change, and silences the callback's warning about sharding
``configure_model`` models (it does not apply to the unsharded models here).
"""

from __future__ import annotations

import warnings
from typing import Any

import lightning as L
from lightning.pytorch.callbacks import EMAWeightAveraging

from skelagnostic.errors import SkelagnosticError

__all__ = ["EMAWeights"]


class EMAWeights(EMAWeightAveraging):
    """:class:`~lightning.pytorch.callbacks.EMAWeightAveraging` that fails loudly on late layers.

    Args:
        decay: Weight of the previous average in each update (0.999: about the
            last 1,000 steps).
        **kwargs: Further arguments of ``EMAWeightAveraging`` (``update_every_n_steps``,
            ``update_starting_at_step``, ...).
    """

    def __init__(self, decay: float = 0.999, **kwargs: Any) -> None:
        if not 0.0 <= decay < 1.0:
            raise SkelagnosticError(f"callbacks.ema.decay must lie in [0, 1), got {decay}")
        super().__init__(decay=decay, **kwargs)

    def setup(self, trainer: L.Trainer, pl_module: L.LightningModule, stage: str) -> None:
        """Make the averaged copy (after ``configure_model``), without the sharding warning."""
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=".*overrides the configure_model.*")
            super().setup(trainer, pl_module, stage)

    def on_fit_start(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        """Check that the average holds every parameter the model has now."""
        if self._average_model is None:
            return
        averaged = {name for name, _ in self._average_model.module.named_parameters()}
        missing = [name for name, _ in pl_module.named_parameters() if name not in averaged]
        if missing:
            shown = ", ".join(missing[:5]) + (" ..." if len(missing) > 5 else "")
            raise SkelagnosticError(
                f"callbacks=ema: {type(pl_module).__name__} created {len(missing)} parameters "
                f"({shown}) after the averaged copy was made, i.e. in its setup() hook; "
                "build data-dependent layers in configure_model() instead "
                "(docs/write-an-aligner.md)"
            )
