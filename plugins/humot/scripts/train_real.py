"""Train HuMoT on the real BVH clips of ``../shared/data`` within a wall-clock budget (CPU).

Each dataset is a separate :class:`~skelagnostic.data.BVHSource` with its own length unit
(CMU files are in CMU units of ~5.6 cm, LaFAN1 in cm), which ``data=bvh`` cannot express
(one ``units`` for all paths). Held-out clips (the ``test`` split, never trained on):

* CMU-31, 3dsMax names (``LeftHip``, ``LeftShoulder`` = upper arm): ``cmu/131_03.bvh``;
* CMU-31, MotionBuilder names (Xia et al.'s ``LeftUpLeg``): ``xia_cmu/strutting_01_000.bvh``;
* LaFAN1-22: ``lafan1/obstacles1_subject5.bvh`` (subject 5 is LaFAN1's test subject).

``--train cmu`` trains on CMU only, so that LaFAN1 is a topology never seen in training;
``--train all`` trains on CMU and LaFAN1. ``--size reduced`` is ``experiment=humot_quick``'s
network (dim 64, 2 blocks, lr 1e-4..1e-3: the paper's network takes ~10 s per step on one
core, see docs/methods/humot.md); ``--size paper`` the paper's. Usage::

    OMP_NUM_THREADS=1 python plugins/humot/scripts/train_real.py DATA_ROOT OUT_DIR
        --train cmu --size reduced --minutes 20   # (one command line)
"""

from __future__ import annotations

import argparse
from datetime import timedelta
from pathlib import Path

import lightning as L
import torch
from lightning.pytorch.callbacks import ModelCheckpoint
from lightning.pytorch.loggers import CSVLogger
from skelagnostic_humot import HumotAligner, HumotDataModule

from skelagnostic.data import BVHSource

#: Clips held out of training (regular expression on the path).
HELD_OUT = r"131_03|strutting_01_000|obstacles1_subject5"

#: ``experiment=humot_quick``'s reduced network and learning rates.
REDUCED = {"dim": 64, "latent": 64, "blocks": 2, "heads": 8, "lr_min": 1e-4, "lr_max": 1e-3}


def sources(root: Path, train: str) -> list[BVHSource]:
    """The BVH sources of ``root`` (``DATA_ROOT``) for ``--train cmu|all``."""
    human = root / "human"
    out = [BVHSource([human / "cmu", human / "xia_cmu"], units="cmu", test_pattern=HELD_OUT,
                     name="cmu")]
    if train == "all":
        out.append(BVHSource([human / "lafan1"], units="cm", test_pattern=HELD_OUT,
                             name="lafan1"))
    return out


def main() -> None:
    """Train and save ``OUT_DIR/last.ckpt`` and ``OUT_DIR/csv/metrics.csv``."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("data_root", type=Path)
    parser.add_argument("out", type=Path)
    parser.add_argument("--train", choices=("cmu", "all"), default="cmu")
    parser.add_argument("--size", choices=("reduced", "paper"), default="reduced")
    parser.add_argument("--minutes", type=float, default=20.0)
    parser.add_argument("--epochs", type=int, default=200,
                        help="max epochs; the triangular learning-rate cycle spans them")
    parser.add_argument("--batch-size", type=int, default=16)
    args = parser.parse_args()
    torch.set_num_threads(1)
    dm = HumotDataModule(sources(args.data_root, args.train), val_fraction=0.0,
                         batch_size=args.batch_size, cache_dir=args.out / "cache")
    L.seed_everything(0)
    options = dict(REDUCED) if args.size == "reduced" else {}
    model = HumotAligner(**options, lr_period_epochs=float(args.epochs))
    trainer = L.Trainer(accelerator="cpu", max_epochs=args.epochs,
                        max_time=timedelta(minutes=args.minutes),
                        logger=CSVLogger(args.out, name="csv", version=""), log_every_n_steps=5,
                        limit_val_batches=0, enable_progress_bar=False,
                        enable_model_summary=False,
                        callbacks=[ModelCheckpoint(dirpath=args.out, save_last=True)],
                        default_root_dir=args.out)
    trainer.fit(model, datamodule=dm)


if __name__ == "__main__":
    main()
