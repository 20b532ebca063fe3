"""Peak memory of the methods' data modules is flat in the corpus size (issue 23, item 10).

Each data module is set up on 2 and on 25 LaFAN1 clips (``../shared/datasets/lafan1``)
in a fresh subprocess per size, which then reads training and validation
batches; the peak resident set (``VmHWM``, else ``ru_maxrss``) of the two
runs must agree within 15 %, and the larger corpus must add less than its extra clips
occupy in the module's window cache (a data module that held the corpus in memory would
add at least all of it). The peak is reached in ``setup`` (the streamed normalisation
pass) and varies between runs of the same measurement: 449-484 MiB for PC-MRL stage 1's
module on the 25 clips, so 10 % of a 430 MiB peak left no margin. The
caches are built once, beforehand, in this process (each clip parsed once for all data
modules, one cache folder per module), so the measured runs only read them.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from skelagnostic import read_bvh
from skelagnostic.core.motion import Motion
from skelagnostic.data import BVHSource, ClipRef

REPO = Path(__file__).resolve().parents[2]
#: The methods' sources (in-repo plugins, importable here and in the subprocesses).
PLUGIN_SRCS = [str(REPO / "plugins" / p / "src") for p in ("vqpae", "humot", "pcmrl")]
for _src in PLUGIN_SRCS:
    if _src not in sys.path:
        sys.path.insert(0, _src)
SMALL, LARGE = 2, 25

#: data module -> (import path, keyword arguments besides sources and cache_dir)
MODULES: dict[str, tuple[str, dict[str, Any]]] = {
    "vqpae": (
        "skelagnostic_vqpae.data:VqpaeDataModule",
        {"fps": 30, "stride": 1, "batch_size": 32},
    ),
    "humot": ("skelagnostic_humot.data:HumotDataModule", {"batch_size": 32}),
    "pcmrl_recon": (
        "skelagnostic_pcmrl.recon.data:PcmrlReconDataModule",
        {"batch_size": 8, "target": "biped31"},
    ),
    "pcmrl_interp": ("skelagnostic_pcmrl.interp.data:PcmrlInterpDataModule", {"batch_size": 16}),
}

#: Run in the subprocess: set the data module up and read batches, print the peak RSS.
_MEASURE = """
import importlib, json, resource, sys
from skelagnostic.data import BVHSource
spec = json.loads(sys.argv[1])
def no_parsing(self, clip):  # the cache is complete: parsing a clip would be measured too
    raise AssertionError(f"cache miss: {clip.id}")
BVHSource.load = no_parsing
module, _, cls = spec["target"].partition(":")
source = BVHSource(spec["files"], units="cm", name="lafan1")
dm = getattr(importlib.import_module(module), cls)(source, cache_dir=spec["cache"],
                                                   **spec["kwargs"])
dm.prepare_data()
dm.setup("fit")
for i, _ in enumerate(dm.train_dataloader()):
    if i == 20:
        break
for i, _ in enumerate(dm.val_dataloader()):
    if i == 10:
        break
# VmHWM: this process's own peak; ru_maxrss would carry the parent's over the exec
status = open("/proc/self/status").read() if sys.platform == "linux" else ""
hwm = [int(line.split()[1]) for line in status.splitlines() if line.startswith("VmHWM:")]
print(json.dumps({"rss_kib": hwm[0] if hwm else
                  resource.getrusage(resource.RUSAGE_SELF).ru_maxrss}))
"""


def _corpus() -> Path | None:
    env = os.environ.get("SKELAGNOSTIC_TEST_DATA")
    data = Path(env) if env else REPO.parent / "shared" / "data"
    path = data.parent / "datasets" / "lafan1"
    return path if len(list(path.glob("*.bvh"))) >= LARGE else None


def _cls(target: str) -> Any:
    import importlib

    module, _, name = target.partition(":")
    return getattr(importlib.import_module(module), name)


@pytest.fixture(scope="module")
def corpus_cache(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[list[str], Path]]:
    """The 25 clips and a window cache holding every data module's entries of them."""
    corpus = _corpus()
    if corpus is None:
        pytest.skip(
            f"the LaFAN1 corpus ({LARGE} clips in ../shared/datasets/lafan1 next to "
            "SKELAGNOSTIC_TEST_DATA or ../shared/data) is not available"
        )
    files = sorted(str(p) for p in corpus.glob("*.bvh"))[:LARGE]
    cache = tmp_path_factory.mktemp("corpus-cache")
    source = BVHSource(files, units="cm", name="lafan1")
    modules = [
        _cls(target)(source, cache_dir=cache / name, **kwargs)
        for name, (target, kwargs) in MODULES.items()
    ]
    load, last = BVHSource.load, {}

    def load_once(self: BVHSource, clip: ClipRef) -> Motion:  # the clip of the previous call
        if last.get("id") != clip.id:
            last.update(id=clip.id, motion=load(self, clip))
        return last["motion"]

    with pytest.MonkeyPatch.context() as patch:  # each clip parsed once for every module
        patch.setattr(BVHSource, "load", load_once)
        for clip in source.clips():
            for dm in modules:
                dm.cache_entry(dm.sources[0], clip)
    yield files, cache


def _peak_rss(target: str, kwargs: dict[str, Any], files: list[str], cache: Path) -> int:
    spec = {"target": target, "kwargs": kwargs, "files": files, "cache": str(cache)}
    path = os.pathsep.join([*PLUGIN_SRCS, os.environ.get("PYTHONPATH", "")])
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": path}
    done = subprocess.run(
        [sys.executable, "-c", _MEASURE, json.dumps(spec)],
        check=True,
        capture_output=True,
        text=True,
        env=env,
    )
    return int(json.loads(done.stdout.strip().splitlines()[-1])["rss_kib"])


@pytest.mark.slow
@pytest.mark.parametrize("module", list(MODULES))
def test_peak_memory_is_flat_in_the_corpus_size(
    module: str, corpus_cache: tuple[list[str], Path]
) -> None:
    files, cache = corpus_cache
    target, kwargs = MODULES[module]
    small = _peak_rss(target, kwargs, files[:SMALL], cache / module)
    large = _peak_rss(target, kwargs, files, cache / module)
    frames = [read_bvh(f).num_frames for f in files]
    cached_kib = sum(p.stat().st_size for p in (cache / module).rglob("*") if p.is_file()) / 1024
    extra_kib = cached_kib * (1 - sum(frames[:SMALL]) / sum(frames))  # about: by frames
    print(
        f"{module}: peak RSS {small / 1024:.0f} MiB ({SMALL} clips), "
        f"{large / 1024:.0f} MiB ({LARGE} clips); the extra clips' cache {extra_kib / 1024:.0f} MiB"
    )
    assert large <= 1.15 * small, (module, small, large)
    assert large - small < extra_kib, (module, small, large, extra_kib)
