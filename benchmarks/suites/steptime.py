"""Timing of real Lightning training steps, shared by the ``training`` suite's parts.

:func:`time_fit` runs ``Trainer.fit`` for ``warmup + steps`` steps on CPU (or a
GPU) and records, for every step after the warm-up, the compute time
(``on_train_batch_start`` -> ``on_train_batch_end``: forward, backward,
optimiser, the module's own per-step work) and the data-fetch time before it
(the gap between the end of one step and the start of the next: the
DataLoader, collation, transfers).
"""

from __future__ import annotations

import statistics
import tempfile
import time
from collections.abc import Sequence
from typing import Any


def accelerators() -> list[str]:
    """``["cpu"]``, plus ``"gpu"`` when torch sees a CUDA device."""
    import torch

    return ["cpu", "gpu"] if torch.cuda.is_available() else ["cpu"]


def suffix(accelerator: str) -> str:
    """Result-name suffix of a device: ``""`` for ``"cpu"``, ``"_gpu"`` for ``"gpu"``."""
    return "" if accelerator == "cpu" else f"_{accelerator}"


def time_fit(
    model: Any,
    datamodule: Any,
    steps: int,
    warmup: int = 1,
    accelerator: str = "cpu",
    *,
    devices: int = 1,
    strategy: str = "auto",
    precision: str | None = None,
    callbacks: Sequence[Any] = (),
) -> dict[str, float]:
    """Median step time and data-loading share of ``steps`` timed training steps.

    Args:
        model: A LightningModule.
        datamodule: Its LightningDataModule.
        steps: Timed steps.
        warmup: Untimed steps first (allocator, caches, lazy builds).
        accelerator: Lightning accelerator, ``"cpu"`` or ``"gpu"``.
        devices: Lightning devices (processes under ``strategy="ddp"``, each started
            by the caller with Lightning's environment variables, ``LOCAL_RANK`` etc.).
        strategy: Lightning strategy (``"ddp"``: the times are this rank's).
        precision: Lightning precision (``None``: Lightning's default, 32-bit).
        callbacks: More Lightning callbacks (run after the timer's hooks).

    Returns:
        ``median_step_s`` (compute + fetch of a step, median), ``median_compute_s``,
        ``median_fetch_s``, ``data_share`` (total fetch time over total time of the
        timed steps) and ``median_step_cpu_s``: the process CPU time of a step
        (fetch + compute, all threads; from the second timed step when there is no
        warm-up), which other jobs on the machine do not inflate as they do wall time.
    """
    import lightning as L
    import torch

    from skelagnostic.aligners import quiet_trainer

    compute: list[float] = []
    sync = torch.cuda.synchronize if accelerator == "gpu" else (lambda: None)
    fetch: list[float] = []
    cpu: list[float] = []  # process CPU time from the end of a step to the end of the next

    class Timer(L.Callback):
        end: float | None = None
        cpu_end: float | None = None
        start = 0.0

        def on_train_batch_start(self, *args: Any) -> None:
            sync()
            self.start = time.perf_counter()
            if self.end is not None:
                fetch.append(self.start - self.end)

        def on_train_batch_end(self, *args: Any) -> None:
            sync()
            self.end = time.perf_counter()
            compute.append(self.end - self.start)
            now = time.process_time()
            if self.cpu_end is not None:
                cpu.append(now - self.cpu_end)
            self.cpu_end = now

    with tempfile.TemporaryDirectory() as run_dir:  # aligners may write renders here
        trainer = quiet_trainer(
            max_steps=warmup + steps,
            accelerator=accelerator,
            devices=devices,
            strategy=strategy,
            precision=precision,
            limit_val_batches=0,
            num_sanity_val_steps=0,
            callbacks=[Timer(), *callbacks],
            default_root_dir=run_dir,
        )
        trainer.fit(model, datamodule=datamodule)
    # fetch[i] is the gap before compute[i + 1]
    timed_compute = compute[warmup:]
    timed_fetch = fetch[warmup - 1 :] if warmup else [0.0, *fetch]
    totals = [c + f for c, f in zip(timed_compute, timed_fetch, strict=True)]
    return {
        "median_step_s": statistics.median(totals),
        "median_step_cpu_s": statistics.median(cpu[warmup - 1 :] if warmup else cpu),
        "median_compute_s": statistics.median(timed_compute),
        "median_fetch_s": statistics.median(timed_fetch),
        "data_share": sum(timed_fetch) / sum(totals),
    }
