"""Suite ``bigdata``: the memory-mapped window cache on a large generated corpus.

A corpus of procedural biped22 walks (``skelagnostic.procedural.generate``,
30 fps, clips of 9,000 frames generated one at a time when the cache asks for
them, so the corpus itself is never in memory) goes through
:class:`~skelagnostic.data.MotionDataModule` with root-local joint positions,
``window=32`` and ``stride=32`` (every frame cached once):

1. ``prepare``: preprocess every clip into the on-disk cache (a fresh process).
2. ``read``: ``setup`` (split, streamed normalisation statistics) and one full
   pass of the training data loader over every cached window (another fresh
   process), as training would read it.

Sizes: ``smoke`` 18,000 frames, ``default`` 1,000,000 (a minute or two),
``large`` 10,080,000 (``python benchmarks/run.py --suite bigdata --size large``,
about 2.5 GB of cache in a temporary directory, deleted afterwards).
Reported: frames, cache size, wall times, throughput and memory. Memory is
the peak RSS of each process; for ``read`` also the peak RSS at the end of
``setup`` (the normalisation pass) and the peaks of its anonymous (heap) and
file-backed resident memory sampled every 64 batches of the pass over the
windows. Windows are read with positioned reads, not memory maps, so the
file-backed part is the loaded code, not the cache; all of it must stay
bounded, the same at every size.
"""

from __future__ import annotations

import hashlib
import shutil
import tempfile
import time
from pathlib import Path
from typing import Any

from benchmarks.harness import Result, run_child

FRAMES_PER_CLIP = 9_000
SIZES = {"smoke": 18_000, "default": 1_000_000, "large": 10_080_000}
WINDOW = 32


def generated_walks(num_clips: int, frames: int = FRAMES_PER_CLIP, name: str = "bigdata") -> Any:
    """A :class:`~skelagnostic.data.ClipSource` of ``num_clips`` procedural biped22 walks.

    Each clip (``frames`` frames at 30 fps, seed = its index) is generated when the
    cache loads it, so the corpus is never in memory as a whole; clip keys depend on
    the package version, ``frames`` and the index.
    """
    from skelagnostic import __version__, procedural
    from skelagnostic.data import ClipRef, ClipSource

    class GeneratedWalks(ClipSource):
        """``num_clips`` procedural walks, each generated when loaded (deterministic seeds)."""

        def clips(self) -> list[ClipRef]:
            return [
                ClipRef(
                    f"walk_{i}",
                    hashlib.sha256(f"bigdata:{__version__}:{frames}:{i}".encode()).hexdigest(),
                )
                for i in range(num_clips)
            ]

        def load(self, clip: ClipRef) -> Any:
            seed = int(clip.id.removeprefix("walk_"))
            motion, _ = procedural.generate(
                "biped22", "walk", seconds=(frames - 1) / 30, fps=30, seed=seed
            )
            return motion

    source = GeneratedWalks()
    source.name = name
    return source


def _datamodule(num_clips: int, cache_dir: str) -> Any:
    from skelagnostic.data import MotionDataModule
    from skelagnostic.representations import GlobalPositions

    return MotionDataModule(
        generated_walks(num_clips),
        GlobalPositions(frame="root"),
        window=WINDOW,
        stride=WINDOW,
        batch_size=64,
        val_fraction=0.01,
        cache_dir=cache_dir,
    )


def _status_kib(field: str) -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    return 0


def prepare(num_clips: int, cache_dir: str) -> dict[str, float]:
    """Child: fill the cache; returns the wall time (imports excluded)."""
    dm = _datamodule(num_clips, cache_dir)
    start = time.perf_counter()
    dm.prepare_data()
    return {"seconds": time.perf_counter() - start}


def read(num_clips: int, cache_dir: str) -> dict[str, float]:
    """Child: set up and read every training window once; returns times and memory."""
    dm = _datamodule(num_clips, cache_dir)
    start = time.perf_counter()
    dm.setup("fit")
    setup_s = time.perf_counter() - start
    setup_peak = _status_kib("VmHWM")
    anon = rss_file = 0
    windows = 0
    start = time.perf_counter()
    for step, (batch, _, _) in enumerate(iter(dm.train_dataloader())):
        windows += sum(len(b["features"]) for b in batch.values())
        if step % 64 == 0:
            anon = max(anon, _status_kib("RssAnon"))
            rss_file = max(rss_file, _status_kib("RssFile"))
    return {
        "setup_seconds": setup_s,
        "read_seconds": time.perf_counter() - start,
        "windows": windows,
        "anon_mib": anon / 1024,
        "file_mib": rss_file / 1024,
        "setup_peak_mib": setup_peak / 1024,
    }


def run(size: str) -> list[Result]:
    """Run the suite at ``size`` and return its results."""
    num_clips = SIZES[size] // FRAMES_PER_CLIP
    frames = num_clips * FRAMES_PER_CLIP
    workdir = Path(tempfile.mkdtemp(prefix="skelagnostic-bigdata-"))
    try:
        cache = str(workdir / "cache")
        prep, prep_rss = run_child(
            "benchmarks.suites.bigdata:prepare", num_clips=num_clips, cache_dir=cache
        )
        cache_bytes = sum(p.stat().st_size for p in Path(cache).rglob("*") if p.is_file())
        got, read_rss = run_child(
            "benchmarks.suites.bigdata:read", num_clips=num_clips, cache_dir=cache
        )
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    return [
        Result("frames", "frames", float(frames), higher_is_better=True),
        Result("cache_size", "MiB", cache_bytes / 2**20),
        Result("prepare_time", "s", prep["seconds"]),
        Result("prepare_frames_per_s", "frames/s", frames / prep["seconds"], higher_is_better=True),
        Result("prepare_peak_rss", "MiB", prep_rss),
        Result("read_setup_time", "s", got["setup_seconds"]),
        Result("read_setup_peak_rss", "MiB", got["setup_peak_mib"]),
        Result(
            "read_windows_per_s",
            "windows/s",
            got["windows"] / got["read_seconds"],
            higher_is_better=True,
        ),
        Result("read_peak_rss", "MiB", read_rss),
        Result("read_peak_anon_rss", "MiB", got["anon_mib"]),
        Result("read_peak_file_rss", "MiB", got["file_mib"]),
    ]
