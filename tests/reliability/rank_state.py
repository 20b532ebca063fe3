"""A callback writing every rank's final model state (DDP tests: do the replicas agree?)."""

from __future__ import annotations

from pathlib import Path

import lightning as L
import torch


class DumpRankState(L.Callback):
    """At the end of ``fit``, save ``rank<global rank>.pt`` in ``path`` on *every* rank.

    The file holds the module's ``state_dict`` (parameters and buffers, e.g.
    a shared codebook) and the trainer's ``callback_metrics``. Test
    instrumentation: everything else a run writes is rank-zero-only.

    Args:
        path: Directory of the files (created).
    """

    def __init__(self, path: str) -> None:
        self.path = Path(path)

    def on_fit_end(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        """Write this rank's state."""
        self.path.mkdir(parents=True, exist_ok=True)
        state = {k: v.detach().cpu().clone() for k, v in pl_module.state_dict().items()}
        metrics = {
            k: torch.as_tensor(v).detach().cpu().clone()
            for k, v in trainer.callback_metrics.items()
        }
        torch.save(
            {"state_dict": state, "metrics": metrics, "world_size": trainer.world_size},
            self.path / f"rank{trainer.global_rank}.pt",
        )
