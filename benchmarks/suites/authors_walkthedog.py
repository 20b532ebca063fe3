"""The WalkTheDog authors' code (github PeizhuoLi/walk-the-dog) timed as a same-run baseline.

Used by the ``training`` suite's VQ-PAE part and the ``matching`` suite when
``run.py --authors-repo walkthedog=DIR`` is given. Every function that runs the
authors' code is meant for a child process (:func:`benchmarks.harness.run_child`):
it puts the checkout first on ``sys.path`` and imports from it, so nothing of
their code is in this repository, and the child's peak RSS is theirs alone.

* :func:`write_datasets` converts BVH clips into their dataset layout with
  ``wtd_data.py`` (``../shared/tools/wtd_data.py``, or ``$SKELAGNOSTIC_WTD_DATA``).
* :func:`train` runs their ``train_vq.py`` unchanged (its ``main()``, with the
  command line set) and times a fixed number of its training iterations by wall
  clock: ``train_vq.tqdm``, the progress bar that wraps the iteration loop, is
  replaced by the same bar writing to ``/dev/null`` that also records the time at
  which each iteration starts, and stops the run after ``warmup + steps``
  iterations. The start-up (data loading, model building) is not timed; one
  iteration is their whole training step (one batch per dataset, both networks,
  loss, backward, codebook re-initialisation, optimiser, scheduler, logging).
  Their trainer needs ``tensorboard``, ``scikit-learn``, ``matplotlib`` and
  ``tqdm`` importable by the benchmark's interpreter.
* :func:`find_nn` calls their matching kernel, ``motion_matching.kernel.find_nn_separate``
  (what ``offline_motion_matching.py`` runs once per query, through
  ``MotionMatchingDatabase.match_with_target``).
"""

from __future__ import annotations

import io
import os
import statistics
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from benchmarks.harness import REPO_ROOT, run_process

#: Environment variable overriding the path of ``wtd_data.py``.
WTD_DATA_ENV = "SKELAGNOSTIC_WTD_DATA"
#: Modules their trainer imports that a skelagnostic environment may lack (import name -> pip).
TRAINER_REQUIREMENTS = {
    "tensorboard": "tensorboard",
    "sklearn": "scikit-learn",
    "matplotlib": "matplotlib",
    "tqdm": "tqdm",
}


def wtd_data_script() -> Path:
    """The converter from BVH to the authors' dataset layout.

    Raises:
        FileNotFoundError: If neither ``$SKELAGNOSTIC_WTD_DATA`` nor
            ``../shared/tools/wtd_data.py`` exists (the message names both).
    """
    env = os.environ.get(WTD_DATA_ENV)
    path = Path(env) if env else REPO_ROOT.parent / "shared" / "tools" / "wtd_data.py"
    if not path.is_file():
        raise FileNotFoundError(
            f"wtd_data.py not found at {path}: the WalkTheDog baseline converts the clips "
            f"with it (set ${WTD_DATA_ENV} to its path, or check out ../shared beside "
            "the repository)"
        )
    return path


def write_datasets(
    out: Path, parts: dict[str, tuple[list[Path], str]], fps: float = 60.0
) -> list[Path]:
    """Write one authors' dataset per part: ``out/Datasets/<name>``.

    Args:
        out: Directory to write into.
        parts: Dataset name (their trainer infers ``human``/``dog`` from it) ->
            (BVH files, ``"biped"`` or ``"quadruped"``).
        fps: Frame rate every clip is resampled to (theirs: 60).

    Returns:
        The dataset directories, in the order of ``parts``.

    Raises:
        RuntimeError: If the conversion fails (with its output).
    """
    script = wtd_data_script()
    dirs = []
    for name, (files, topology) in parts.items():
        target = out / "Datasets" / name
        # one copy of each clip, like skelagnostic's data module (no mirrored copy)
        cmd = [
            sys.executable,
            str(script),
            "--files",
            *map(str, files),
            "--topology",
            topology,
            "--out",
            str(target),
            "--fps",
            str(fps),
            "--no-mirror",
        ]
        proc = run_process(cmd)  # dies with the benchmark
        if proc.returncode != 0:
            raise RuntimeError(
                f"{script} failed for {name} (exit {proc.returncode}):\n"
                f"{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}"
            )
        dirs.append(target)
    return dirs


def check_trainer_requirements() -> None:
    """Raise ``ModuleNotFoundError`` naming what their trainer needs and this Python lacks."""
    import importlib.util

    missing = [
        pip for mod, pip in TRAINER_REQUIREMENTS.items() if importlib.util.find_spec(mod) is None
    ]
    if missing:
        raise ModuleNotFoundError(
            f"the WalkTheDog authors' trainer needs {', '.join(missing)} in {sys.executable} "
            f"(pip install {' '.join(missing)}, or add a directory holding them to PYTHONPATH)"
        )


class _Stop(Exception):
    """Raised by the timed progress bar once enough iterations ran."""


def _children_peak_rss() -> float:
    import resource

    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return peak / 2**20 if sys.platform == "darwin" else peak / 2**10


def train(
    repo: str,
    datasets: list[str],
    steps: int,
    warmup: int = 5,
    phase_decoder: bool = True,
    batch_size: int = 32,
    num_codes: int = 32,
    std_cap: float = 0.001,
) -> dict[str, Any]:
    """Time ``warmup + steps`` iterations of the authors' ``train_vq.py`` (child process).

    Args:
        repo: Checkout of github PeizhuoLi/walk-the-dog.
        datasets: Dataset directories written by :func:`write_datasets`.
        steps: Timed iterations (after ``warmup``).
        warmup: Untimed iterations first.
        phase_decoder: Train their average-pose decoders alongside
            (``--train_phase_decoder``, their default 1).
        batch_size: Windows per dataset per iteration (``--batch_size``).
        num_codes: Codebook size (``--num_embed_vq``).
        std_cap: ``--std_cap``; their default 0 gives NaN losses on real data
            with constant channels (see ``../shared/tools/README.md``).

    Returns:
        ``median_step_s`` (median wall time of a timed iteration), ``mean_step_s``,
        ``iterations_per_epoch`` and ``children_peak_rss_mib`` (the largest of
        their data-loader worker processes).

    Raises:
        ValueError: If an epoch of their trainer is shorter than ``warmup + steps``
            iterations (the end of an epoch saves and evaluates, which is not a step).
    """
    check_trainer_requirements()
    os.environ["CUDA_VISIBLE_DEVICES"] = ""  # the CPU figure; their code uses CUDA when it sees one
    os.environ.setdefault("MPLBACKEND", "Agg")
    sys.path.insert(0, str(repo))
    import tqdm as tqdm_module
    import train_vq

    total = warmup + steps
    stamps: list[float] = []
    epoch_lengths: list[int] = []
    sink = io.StringIO()

    def timed_tqdm(iterable: Any, *args: Any, **kwargs: Any) -> Any:
        bar = tqdm_module.tqdm(iterable, *args, file=sink, **kwargs)
        epoch_lengths.append(len(bar))
        if len(bar) < total:
            raise ValueError(
                f"an epoch of the authors' trainer has {len(bar)} iterations, "
                f"fewer than the {total} to time: use more clips"
            )

        class Timed:
            def __iter__(self) -> Iterator[Any]:
                for item in bar:
                    stamps.append(time.perf_counter())
                    if len(stamps) > total:
                        raise _Stop
                    yield item

            def __getattr__(self, name: str) -> Any:  # set_description and the like
                return getattr(bar, name)

        return Timed()

    train_vq.tqdm = timed_tqdm
    with tempfile.TemporaryDirectory() as run_dir:
        sys.argv = [
            "train_vq.py",
            f"--load={','.join(datasets)}",
            f"--save={run_dir}/run",
            "--device=cpu",
            f"--std_cap={std_cap}",
            f"--batch_size={batch_size}",
            f"--num_embed_vq={num_codes}",
            f"--train_phase_decoder={int(phase_decoder)}",
        ]
        cwd = os.getcwd()
        os.chdir(run_dir)
        try:
            train_vq.main()
        except _Stop:
            pass
        finally:
            os.chdir(cwd)
    if len(stamps) <= total:
        raise RuntimeError(
            f"the authors' trainer stopped after {len(stamps)} iterations, "
            f"before the {total} to time:\n{sink.getvalue()[-2000:]}"
        )
    import gc

    gc.collect()  # shuts their data-loader workers down, so their peak RSS is counted
    times = [b - a for a, b in zip(stamps[warmup:total], stamps[warmup + 1 :], strict=True)]
    return {
        "median_step_s": statistics.median(times),
        "mean_step_s": statistics.fmean(times),
        "iterations_per_epoch": epoch_lengths[0],
        "children_peak_rss_mib": _children_peak_rss(),
    }


def find_nn(repo: str) -> Any:
    """Their per-query matching kernel ``find_nn_separate`` (imported from ``repo``)."""
    os.environ.setdefault("MPLBACKEND", "Agg")
    sys.path.insert(0, str(repo))
    from motion_matching.kernel import find_nn_separate

    return find_nn_separate
