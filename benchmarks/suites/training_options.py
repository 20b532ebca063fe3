"""Suite ``training`` (options part): what buys more steps of the CPU presets (issue #46).

Each method's 2-CPU-hour preset (``humot_cpu2h``, ``vqpae_cpu2h``, ``pcmrl_cpu2h``:
the networks, batches and data the held-out runs train with) is timed over the
same steps of the full Lightning training step (:mod:`benchmarks.suites.steptime`)
under each option, in its own child process, against the preset as it runs
today (``eager``: 32-bit, eager, one thread) in the same run:

* ``bf16``: ``trainer.precision=bf16-mixed`` (CPU autocast; changes the numerics);
* ``compiled``: the networks the step calls compiled in place with ``torch.compile``
  (:func:`benchmarks.suites.scaling.compile_networks`; two more warm-up steps);
* ``batch2x``: twice the windows per batch (half the optimiser steps per epoch);
* ``threads2``: two intra-op threads (both cores of the project's machine).

Results, per method ``m`` and option ``o``: ``m_windows_per_s_o`` (windows per
second of wall time, from the median step) and ``m_windows_per_cpu_s_o``
(windows per second of process CPU time: what one core of an idle machine does,
the figure a loaded machine does not distort; for ``threads2`` it counts both
threads, so the wall figure is the one to read there). The baseline of every
row is the method's ``eager`` row of the same run.

``bf16`` also reports ``m_loss_rel_diff_bf16``: the relative difference of the
training loss after the timed steps from the 32-bit run's (same seed, data and
steps), the change of numerics an option would bring.

The window caches go to ``<tmp>/skelagnostic-bench-cache`` (shared by the options
of a method and by later runs), so only the first option of a method builds them.
The corpora come from ``$SKELAGNOSTIC_BENCH_DATA``, ``$SKELAGNOSTIC_DATA`` or
``../shared/datasets`` (LaFAN1, MANN dog); a method whose corpus is missing has no
rows (it says so). ``smoke`` (the tests) runs the ``humot_quick``-sized HuMoT on
procedural data only, 2 timed steps, eager and ``bf16``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from benchmarks.harness import Result, run_child
from benchmarks.suites.scaling import compile_networks, corpus_root
from benchmarks.suites.steptime import time_fit

#: Timed steps per size (after the warm-up).
STEPS = {"smoke": 2, "default": 20, "large": 60}
#: Untimed steps first (compiled: two more, to find and compile the networks).
WARMUP = 3
#: method -> (the preset's command-line overrides, corpora it reads under the data root).
PRESETS: dict[str, tuple[list[str], list[str]]] = {
    "humot": (["model=humot", "experiment=humot_cpu2h"], ["lafan1"]),
    "vqpae": (["model=vqpae", "experiment=vqpae_cpu2h"], ["lafan1", "mann_dog"]),
    "pcmrl": (["model=pcmrl", "experiment=pcmrl_cpu2h"], ["lafan1"]),
}
#: The smoke preset: small, procedural, no corpus.
SMOKE = (["model=humot", "experiment=humot_quick", "data.clips_per_gait=1"], [])
OPTIONS = ("eager", "bf16", "compiled", "batch2x", "threads2")


def measure(overrides: list[str], option: str, steps: int) -> dict[str, Any]:
    """Time ``steps`` training steps of the preset ``overrides`` under ``option``.

    Returns:
        The :func:`~benchmarks.suites.steptime.time_fit` figures, the windows per
        step and the last training loss.
    """
    import tempfile

    import lightning as L
    import torch

    from skelagnostic.cli.app import compose
    from skelagnostic.cli.build import build_datamodule, build_model
    from skelagnostic.plugins import get_plugin_manager

    torch.set_num_threads(2 if option == "threads2" else 1)
    pm = get_plugin_manager()
    cache = Path(tempfile.gettempdir()) / "skelagnostic-bench-cache"  # shared by the options
    extra = [f"run_dir={tempfile.mkdtemp(prefix='bench-options-')}", f"data.cache_dir={cache}"]
    if option == "batch2x":
        base = compose([*overrides, *extra], plugin_manager=pm)
        extra.append(f"data.batch_size={2 * int(base.data.batch_size)}")
    cfg = compose([*overrides, *extra], plugin_manager=pm)
    L.seed_everything(0, verbose=False)
    datamodule = build_datamodule(cfg, pm)
    model, _ = build_model(cfg, pm.aligner(cfg.model.name))
    callbacks = [compile_networks()] if option == "compiled" else []
    losses: list[float] = []

    class LastLoss(L.Callback):
        def on_train_batch_end(self, trainer: Any, *args: Any) -> None:
            loss = trainer.callback_metrics.get("train/loss")
            if loss is not None:
                losses.append(float(loss))

    timing = time_fit(
        model,
        datamodule,
        steps,
        warmup=WARMUP + (2 if option == "compiled" else 0),
        precision="bf16-mixed" if option == "bf16" else None,
        callbacks=[*callbacks, LastLoss()],
    )
    datasets = len(datamodule.datasets["train"])
    return {
        **timing,
        "windows_per_step": int(cfg.data.batch_size) * datasets,
        "loss": losses[-1] if losses else None,
    }


def _rows(method: str, figures: dict[str, dict[str, Any]]) -> list[Result]:
    """The results of one method: every option against its ``eager`` figures."""
    base = figures["eager"]
    baseline = f"{method} preset as it runs (32-bit, eager, 1 thread), same run"
    rows = []
    for option, out in figures.items():
        if option == "eager":
            name, wall0, cpu0 = None, None, None
        else:
            name = baseline
            wall0 = base["windows_per_step"] / base["median_step_s"]
            cpu0 = base["windows_per_step"] / base["median_step_cpu_s"]
        windows = out["windows_per_step"]
        rows += [
            Result(
                f"{method}_windows_per_s_{option}",
                "windows/s",
                windows / out["median_step_s"],
                name,
                wall0,
                higher_is_better=True,
            ),
            Result(
                f"{method}_windows_per_cpu_s_{option}",
                "windows/CPU-s",
                windows / out["median_step_cpu_s"],
                name,
                cpu0,
                higher_is_better=True,
            ),
        ]
    if "bf16" in figures and base["loss"] and figures["bf16"]["loss"] is not None:
        diff = abs(figures["bf16"]["loss"] - base["loss"]) / abs(base["loss"])
        rows.append(Result(f"{method}_loss_rel_diff_bf16", "fraction", diff))
    return rows


def run(size: str) -> list[Result]:
    """Every method's options against its preset, or the smoke preset at ``smoke`` size."""
    results: list[Result] = []
    if size == "smoke":
        presets = {"humot": SMOKE}
        options: tuple[str, ...] = ("eager", "bf16")
    else:
        presets, options = PRESETS, OPTIONS
    root = corpus_root()
    env = dict(os.environ, SKELAGNOSTIC_DATA=str(root))
    for method, (overrides, corpora) in presets.items():
        missing = [c for c in corpora if not (root / c).is_dir()]
        if missing:
            print(f"training_options: no {', '.join(missing)} under {root}: no {method} rows")
            continue
        figures = {}
        for option in options:
            try:
                figures[option], _ = run_child(
                    "benchmarks.suites.training_options:measure",
                    child_env=env,
                    overrides=overrides,
                    option=option,
                    steps=STEPS[size],
                )
            except RuntimeError as exc:  # e.g. a compiler missing: no row, the error shown
                print(f"training_options: {method} {option} failed: {str(exc)[-600:]}")
        if "eager" in figures:
            results += _rows(method, figures)
    return results
