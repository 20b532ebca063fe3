"""Suite ``allocators``: each method's training step on glibc's malloc, tcmalloc and jemalloc.

For each method of the ``scaling`` suite (``vqpae``, ``humot``, ``pcmrl_recon``,
``pcmrl_interp``, or ``run.py --methods``), at the smallest and the largest
batch of :data:`benchmarks.suites.scaling.SETTINGS` (``smoke``: the smallest) and
1 torch thread, the full
Lightning training step (:func:`benchmarks.suites.steptime.time_fit`, the
papers' networks at ``default`` and ``large``, tiny ones at ``smoke``) on the
first 2 LaFAN1 clips of the corpus root (generated walks without it), in a
fresh process per allocator:

* ``system``: the C library's ``malloc`` (no ``LD_PRELOAD``), the **baseline**
  of every row;
* ``tcmalloc`` and ``jemalloc``: the libraries
  :func:`skelagnostic.cli.allocator.find_allocator` finds, preloaded as
  ``SKELAGNOSTIC_ALLOCATOR`` does (jemalloc with
  :data:`skelagnostic.cli.allocator.JEMALLOC_CONF` unless ``MALLOC_CONF`` is set).
  An allocator that is not installed has no rows (a message says so), never an
  estimate.

Results per method, allocator and batch: ``<method>_windows_per_s_b<B>_<allocator>``
(baseline: ``system``, same batch), ``<method>_sys_share_b<B>_<allocator>``: the
kernel's share of the step's CPU time (median over the timed steps; page faults
are counted there), ``<method>_minor_faults_per_step_b<B>_<allocator>`` and the
process's ``<method>_peak_rss_mib_b<B>_<allocator>`` (baselines: ``system``), and
``<method>_same_weights_b<B>_<allocator>``: 1 when the weights after the timed steps
are bit for bit those of the ``system`` run (same seed, data and steps), else 0.
Each child checks that it runs on the allocator it was started with
(:func:`skelagnostic.cli.allocator.active_allocator`).
"""

from __future__ import annotations

import hashlib
import itertools
import resource
import statistics
import sys
import tempfile
from pathlib import Path
from typing import Any

from benchmarks.harness import Result, run_child
from benchmarks.suites import scaling

#: Allocators, in report order; the first is the baseline.
ALLOCATORS = ("system", "tcmalloc", "jemalloc")


def batches(method: str, size: str) -> tuple[int, ...]:
    """The smallest and the largest batch of the scaling suite's rows of ``method``.

    ``smoke`` (tiny networks, a check of the suite): the smallest only.
    """
    settings = scaling.SETTINGS[size]
    chosen = settings.batches[method]
    return (chosen[0],) if settings.tiny else tuple(sorted({chosen[0], chosen[-1]}))


def environment(allocator: str, environ: dict[str, str] | None = None) -> dict[str, str]:
    """The environment of a child on ``allocator``, whatever this process runs on.

    :func:`skelagnostic.cli.allocator.allocator_environment`, without ``SKELAGNOSTIC_ALLOCATOR``
    (the children are not the ``skelagnostic`` command).

    Raises:
        skelagnostic.cli.allocator.AllocatorError: The allocator is not installed.
    """
    from skelagnostic.cli.allocator import ALLOCATOR_ENV, allocator_environment

    env = allocator_environment(allocator, environ)
    env.pop(ALLOCATOR_ENV, None)
    return env


def measure(
    method: str, size: str, batch: int, files: list[str] | None, cache_dir: str
) -> dict[str, Any]:
    """Child process: time ``method``'s step at ``batch`` on the allocator it was started on.

    Returns:
        ``windows_per_s``, ``sys_share`` and ``minor_faults_per_step`` (medians over the
        timed steps), ``allocator`` (the one running) and ``weights_sha256``: a digest
        of the trained weights (an allocator must not change them).
    """
    import lightning as L
    import torch

    from benchmarks.suites.steptime import time_fit
    from skelagnostic.cli.allocator import active_allocator

    scaling._import_everything()
    torch.set_num_threads(1)
    settings = scaling.SETTINGS[size]
    clips = scaling.source(len(files) if files else 2, files, size)
    model, dm, windows = scaling.build(method, settings.tiny, clips, batch, cache_dir)
    usage: list[resource.struct_rusage] = []

    class Usage(L.Callback):
        def on_train_batch_end(self, *args: Any) -> None:
            usage.append(resource.getrusage(resource.RUSAGE_SELF))

    L.seed_everything(0, verbose=False)
    timing = time_fit(model, dm, settings.steps, settings.warmup, callbacks=[Usage()])
    timed = usage[settings.warmup - 1 :] if settings.warmup else usage
    steps = list(itertools.pairwise(timed))
    faults = [b.ru_minflt - a.ru_minflt for a, b in steps]
    shares = [
        (b.ru_stime - a.ru_stime) / max(1e-9, b.ru_stime + b.ru_utime - a.ru_stime - a.ru_utime)
        for a, b in steps
    ]
    digest = hashlib.sha256()
    for tensor in model.state_dict().values():
        digest.update(tensor.detach().cpu().contiguous().numpy().tobytes())
    return {
        "weights_sha256": digest.hexdigest(),
        "windows_per_s": windows / timing["median_step_s"],
        "sys_share": statistics.median(shares),
        "minor_faults_per_step": statistics.median(faults),
        "allocator": active_allocator(),
    }


def measure_all(size: str) -> dict[str, dict[str, dict[str, Any]]]:
    """Every method, batch and installed allocator, each in its own process.

    Returns:
        ``{method: {"b<B>_<allocator>": figures + peak_rss_mib}}``.
    """
    from skelagnostic.cli.allocator import AllocatorError

    found = scaling.corpus(2)
    files = found[1] if found else None
    envs: dict[str, dict[str, str]] = {}
    for allocator in ALLOCATORS:
        try:
            envs[allocator] = environment(allocator)
        except AllocatorError as err:
            print(f"allocators: no rows for {allocator}: {err}", file=sys.stderr)
    raw: dict[str, dict[str, dict[str, Any]]] = {}
    with tempfile.TemporaryDirectory(prefix="skelagnostic-allocators-") as tmp:
        for method in scaling.selected_methods():
            cache = str(Path(tmp) / method)
            raw[method] = {}
            for batch in batches(method, size):
                for allocator, env in envs.items():
                    got, peak = run_child(
                        "benchmarks.suites.allocators:measure",
                        child_env=env,
                        method=method,
                        size=size,
                        batch=batch,
                        files=files,
                        cache_dir=cache,
                    )
                    if got["allocator"] != allocator:
                        raise RuntimeError(
                            f"allocators: the {allocator} child of {method} ran on "
                            f"{got['allocator']} (LD_PRELOAD={env.get('LD_PRELOAD')!r})"
                        )
                    raw[method][f"b{batch}_{allocator}"] = {**got, "peak_rss_mib": peak}
    return raw


def results(raw: dict[str, dict[str, dict[str, Any]]], size: str) -> list[Result]:
    """The suite's results (see the module doc) from :func:`measure_all`'s figures."""
    out: list[Result] = []
    figures = (
        ("windows_per_s", "windows/s", True),
        ("sys_share", "fraction", False),
        ("minor_faults_per_step", "faults", False),
        ("peak_rss_mib", "MiB", False),
    )
    for method in (m for m in scaling.METHODS if m in raw):
        rows = raw[method]
        for batch in batches(method, size):
            base = rows.get(f"b{batch}_system")
            for allocator in ALLOCATORS:
                row = rows.get(f"b{batch}_{allocator}")
                if row is None:
                    continue
                if allocator != "system" and base is not None:
                    same = float(row["weights_sha256"] == base["weights_sha256"])
                    out.append(
                        Result(
                            f"{method}_same_weights_b{batch}_{allocator}",
                            "bool",
                            same,
                            f"system malloc, batch {batch} (same run)",
                            1.0,
                            higher_is_better=True,
                        )
                    )
                for key, unit, higher in figures:
                    name = f"{method}_{key}_b{batch}_{allocator}"
                    if allocator == "system" or base is None:
                        out.append(Result(name, unit, row[key], higher_is_better=higher))
                    else:
                        label = f"system malloc, batch {batch} (same run)"
                        out.append(Result(name, unit, row[key], label, base[key], higher))
    return out


def run(size: str) -> list[Result]:
    """Run the suite at ``size`` (a child process per method, batch and allocator)."""
    scaling.selected_methods()  # an unknown --methods name fails before any child starts
    return results(measure_all(size), size)
