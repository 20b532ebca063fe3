"""Train HuMoT on the CMU-31 clips of ../shared/data within a wall-clock budget (CPU).

Held out: xia_cmu/strutting_01_000.bvh and cmu/131_03.bvh (test split). Usage:
    python plugins/humot/scripts/train_cmu.py DATA_ROOT OUT_DIR MINUTES
"""

from __future__ import annotations

import sys
from datetime import timedelta
from pathlib import Path

import lightning as L
from lightning.pytorch.callbacks import ModelCheckpoint
from lightning.pytorch.loggers import CSVLogger
from skelagnostic_humot import HumotAligner, HumotDataModule

from skelagnostic.data import BVHSource


def main() -> None:
    """Train and save ``OUT_DIR/last.ckpt``."""
    root, out, minutes = Path(sys.argv[1]), Path(sys.argv[2]), float(sys.argv[3])
    source = BVHSource([root / "human" / "xia_cmu", root / "human" / "cmu"], units="cmu",
                       test_pattern=r"strutting|131_03", name="cmu")
    dm = HumotDataModule([source], val_fraction=0.0, cache_dir=out / "cache")
    L.seed_everything(0)
    model = HumotAligner()
    trainer = L.Trainer(accelerator="cpu", max_epochs=1000, max_time=timedelta(minutes=minutes),
                        logger=CSVLogger(out, name="csv", version=""), log_every_n_steps=5,
                        limit_val_batches=0, enable_progress_bar=False,
                        callbacks=[ModelCheckpoint(dirpath=out, save_last=True)],
                        default_root_dir=out)
    trainer.fit(model, datamodule=dm)


if __name__ == "__main__":
    main()
