"""Loggers of the ``logger=`` presets that need more than Lightning's defaults, and media.

:class:`LocalMLFlowLogger` is ``logger=mlflow``: Lightning's ``MLFlowLogger`` on a
local file store in the run directory. :func:`log_image` sends a picture (the
render callback's contact sheet) to every logger that takes images: TensorBoard
(``add_image``), Weights & Biases (``log_image``) and MLflow (an image artifact).
:func:`finished_runs` closes the Weights & Biases run of a task when it ends.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterable, Iterator
from typing import Any

import numpy as np
from lightning.pytorch.loggers import Logger, MLFlowLogger, WandbLogger

__all__ = ["FILE_STORE_ENV", "LocalMLFlowLogger", "finished_runs", "log_image"]

#: The variable MLflow 3 asks for before it opens a ``file:`` tracking store.
FILE_STORE_ENV = "MLFLOW_ALLOW_FILE_STORE"


class LocalMLFlowLogger(MLFlowLogger):
    """Lightning's ``MLFlowLogger`` that may write to a local ``file:`` store.

    MLflow 3 keeps its file store in maintenance mode and refuses to open one
    unless ``$MLFLOW_ALLOW_FILE_STORE`` is true; with a ``file:`` tracking URI this
    logger sets it (when unset) for the process, so ``logger=mlflow`` writes
    ``<run_dir>/mlruns`` without a server or a database. Any other URI
    (``sqlite:///...``, ``http://...``) is passed on unchanged.

    Args:
        tracking_uri: Where to log (``logger.mlflow.tracking_uri``).
        **kwargs: The other arguments of ``MLFlowLogger`` (``experiment_name``,
            ``run_name``, ``log_model``, ...).
    """

    def __init__(self, tracking_uri: str | None = None, **kwargs: Any) -> None:
        if tracking_uri is not None and tracking_uri.startswith("file:"):
            os.environ.setdefault(FILE_STORE_ENV, "true")
        super().__init__(tracking_uri=tracking_uri, **kwargs)


def log_image(loggers: Iterable[Logger], tag: str, image: np.ndarray, step: int) -> None:
    """Send an ``[H, W, 3]`` uint8 picture to every logger that takes images.

    TensorBoard (any logger whose ``experiment`` has ``add_image``) gets it under
    ``tag``; Weights & Biases under ``tag`` at ``step``; MLflow as the artifact
    ``<tag>/step<step>.png`` of its run. Other loggers (CSV) are skipped.

    Args:
        loggers: The trainer's loggers.
        tag: Name of the picture (``renders/val``).
        image: The picture, height x width x RGB.
        step: The global step.
    """
    for logger in loggers:
        if isinstance(logger, WandbLogger):
            logger.log_image(key=tag, images=[image], step=step)
        elif isinstance(logger, MLFlowLogger):
            artifact = f"{tag}/step{step:07d}.png"
            logger.experiment.log_image(logger.run_id, image, artifact_file=artifact)
        else:
            experiment: Any = getattr(logger, "experiment", None)
            if hasattr(experiment, "add_image"):
                experiment.add_image(tag, image, global_step=step, dataformats="HWC")


@contextlib.contextmanager
def finished_runs(loggers: Iterable[Logger]) -> Iterator[None]:
    """Within the block a task runs; after it, every Weights & Biases run it opened is finished.

    Lightning leaves a ``WandbLogger``'s run open until the process exits, so a
    second task in the same process (a Hydra multirun, a notebook) would log into
    the first one's run, and an offline run's summary would not be written yet.
    The run is finished with exit code 1 when the block raises.

    Args:
        loggers: The trainer's loggers.
    """
    failed = True
    try:
        yield
        failed = False
    finally:
        for logger in loggers:
            run = getattr(logger, "_experiment", None)
            if isinstance(logger, WandbLogger) and run is not None:
                run.finish(exit_code=int(failed))
