"""The clip split of a fit, recorded in its run directory.

``validate``, ``test``, ``predict`` and ``evaluate`` of a run keep the split its
``fit`` recorded (:func:`skelagnostic.cli.runs.read_split`), so a clip the model
trained on is never evaluated as held out.
"""

from __future__ import annotations

import json
from pathlib import Path

import lightning as L

from skelagnostic.filenames import SPLIT_FILE

__all__ = ["SPLIT_FILE", "RecordSplit"]


class RecordSplit(L.Callback):
    """Writes ``<run_dir>/split.json`` once the data module has split its clips.

    Args:
        run_dir: The run directory.
    """

    def __init__(self, run_dir: str | Path) -> None:
        self.run_dir = Path(run_dir)

    def setup(self, trainer: L.Trainer, pl_module: L.LightningModule, stage: str) -> None:
        """After the data module's ``setup``: write its ``assigned_splits`` (rank 0)."""
        assigned = getattr(trainer.datamodule, "assigned_splits", None)
        if assigned and trainer.is_global_zero:
            self.run_dir.mkdir(parents=True, exist_ok=True)
            counts = {
                part: sum(v == part for v in assigned.values()) for part in ("train", "val", "test")
            }
            payload = {"counts": counts, "clips": dict(sorted(assigned.items()))}
            (self.run_dir / SPLIT_FILE).write_text(
                json.dumps(payload, indent=1) + "\n", encoding="utf-8"
            )
