"""Environments for CLI subprocesses: in-repo plugins found as installed distributions."""

from __future__ import annotations

import os
import sys
from importlib import metadata
from pathlib import Path

from skelagnostic.plugins import ENTRY_POINT_GROUP, LOAD_PLUGINS_ENV

REPO = Path(__file__).resolve().parents[2]
EXAMPLE_SRC = REPO / "plugins" / "example-aligner" / "src"
HERE = Path(__file__).resolve().parent


def plugin_env(tmp_path: Path, name: str, module: str, src: Path) -> dict[str, str]:
    """Environment of ``python -m skelagnostic.cli`` with one in-repo plugin "installed".

    The plugin's sources go on ``PYTHONPATH`` and, unless a distribution found
    there or installed already declares the entry point, a fake ``<dist>.dist-info``
    declares it (group ``skelagnostic``), so the CLI finds the plugin as it
    would find an installed one, without installing anything or touching the
    plugin's files. Only that plugin is loaded (``SKELAGNOSTIC_LOAD_PLUGINS``);
    this directory is importable too (test callbacks such as ``killer.KillAt``).

    Args:
        tmp_path: The test's directory (holds the fake site and the window cache).
        name: Entry-point name, e.g. ``"humot"``.
        module: Module holding the hook implementations, e.g. ``"skelagnostic_humot.plugin"``.
        src: Directory to put on ``PYTHONPATH`` (the plugin's ``src``).
    """
    site = tmp_path / "site"
    declared = {
        ep.name
        for dist in metadata.distributions(path=[str(src), *sys.path])
        for ep in dist.entry_points
        if ep.group == ENTRY_POINT_GROUP
    }
    if name not in declared:  # e.g. no build metadata next to the sources
        dist = site / f"skelagnostic_{name.replace('-', '_')}-0.1.0.dist-info"
        dist.mkdir(parents=True)
        (dist / "METADATA").write_text(
            f"Metadata-Version: 2.1\nName: skelagnostic-{name}\nVersion: 0.1.0\n"
        )
        (dist / "entry_points.txt").write_text(f"[{ENTRY_POINT_GROUP}]\n{name} = {module}\n")
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(site), str(src), str(REPO / "src"), str(HERE)])
    env[LOAD_PLUGINS_ENV] = name
    env["SKELAGNOSTIC_CACHE"] = str(tmp_path / "cache")
    env["OMP_NUM_THREADS"] = "1"
    env.pop("SKELAGNOSTIC_DEBUG", None)
    return env


#: A small example-aligner fit on procedural data, one thread (Hydra overrides).
SMALL = [
    "model=example",
    "model.hidden=16",
    "model.latent=4",
    "data.seconds=2.0",
    "data.clips_per_gait=1",
    "data.window=16",
    "data.stride=4",
    "data.batch_size=4",
    "trainer.limit_val_batches=1",
    "trainer.enable_model_summary=false",
    "threads=1",
    "seed=7",
]

#: Overrides that write last.ckpt after every step (the default waits for an epoch end).
EVERY_STEP = [
    "+callbacks.resume._target_=lightning.pytorch.callbacks.ModelCheckpoint",
    "+callbacks.resume.dirpath=${run_dir}/checkpoints",
    "+callbacks.resume.save_top_k=0",
    "+callbacks.resume.save_last=true",
    "+callbacks.resume.every_n_train_steps=1",
    "callbacks.model_checkpoint.save_last=false",
]
