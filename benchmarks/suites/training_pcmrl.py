"""Suite ``training`` (PC-MRL part): training throughput of both stages at the paper's sizes.

The full Lightning training step on CPU (:mod:`benchmarks.suites.steptime`):

* Stage 1, reconstruction (``experiment=pcmrl_paper``): 256 source / 1024 target
  points, sigma 0.05 m, the 4-stage Point Transformer (64 -> 1024 channels), the
  6-layer temporal transformer, temporal KNN loss with K = 8, unit-norm penalty.
  LaFAN1 (walk4_subject1, 30 fps) -> the CMU-31 skeleton of 131_01, unpaired.
  The paper gives neither batch size nor window for this stage; the preset's
  16 windows of 64 frames are used.
* Stage 2, interpolation (``model=pcmrl_interp`` defaults, the authors'
  settings): width 512, 8 heads, 6 layers, 128-frame windows with 5-36 random
  keyframes, rest-pose augmentation, batch 16 (the paper does not state the
  batch size); CMU-31 clips (131_01, 131_03) at 30 fps.

Clips come from ``$SKELAGNOSTIC_TEST_DATA`` or ``../shared/data``; procedural
biped22 -> biped31 (stage 1) and biped31 (stage 2) replace them when absent.
Reported per stage: steps/s, windows/s and the share of time in data loading,
and ``pcmrl_<stage>_peak_rss_mib``, the peak RSS of the process that trained.

Baseline (``run.py --authors-repo pcmrl=DIR``): stage 1 of the authors' code
(``train_pointcloud.py``'s ``PointCloudTrainer``, with pure-torch stand-ins for
pytorch3d: :mod:`benchmarks.suites.authors_pcmrl`) run in the same suite at the
same sizes (their config: 256 / 1024 points, sigma 0.05, d_model 64, 6 temporal
layers, K = 8; batch 16 windows of 64 frames set to ours) on the same LaFAN1
clip, onto the CMU-31 skeleton of ``human/xia_cmu/neutral_01_000.bvh`` (their
loader knows the MotionBuilder joint names of that file, not the 3ds Max names of
131_01: the same 31-joint skeleton). It is the baseline of the ``recon`` rows,
and of the ``recon_authors_layout`` rows, measured only with the option: the
same step with ``model.layout=authors``, their point encoder and temporal
transformer (86.4 M parameters, as their network at these settings; the default
layout has 94.6 M), so that the two trainers are compared on the same network.
Stage 2 has none: their stage-2 step also runs the stage-1 network on fresh
point clouds to make its training data, and its batch is fixed by the keyframe
range (32 windows), so it is not the same step as ours. Without the option the
``recon`` baselines are absent (``null``).

The baseline of the ``interp`` rows (sizes ``default`` and ``large``) is the same
steps of the reference network (``model.fast_path=false``: the keyframe encoder
runs on every frame), same weights, data and seed, timed in the same run after
the keyframe-only encoder (``fast_path=true``, the default); at ``smoke`` size
they have none (the CI smoke test stays short).
"""

from __future__ import annotations

import importlib
import inspect
import sys
import tempfile
from pathlib import Path
from typing import Any

from benchmarks.authors import authors_repo
from benchmarks.harness import REPO_ROOT, Result, run_child, shared_data
from benchmarks.suites.authors_pcmrl import VISUALISED_WINDOWS
from benchmarks.suites.steptime import accelerators, suffix, time_fit

#: Timed steps per size (after one warm-up step) for (reconstruction, interpolation). One
#: thread takes about 32 s and 13 s per step at these sizes (94.6 M and 61.8 M parameters).
STEPS = {"smoke": (1, 1), "default": (3, 3), "large": (10, 20)}
#: Windows per step (the batch size) of both stages, per size: ``smoke`` only checks that
#: the part runs (CI), so it takes 2 windows instead of the measured sizes' 16.
BATCH = {"smoke": 2, "default": 16, "large": 16}
#: The smallest batch the authors' trainer runs (it draws the first windows of each batch
#: every 50 iterations, from its first on, and fails on a smaller one). With
#: ``--authors-repo pcmrl=DIR`` every row of this part takes at least this batch, so both
#: sides train the same batch.
AUTHORS_MIN_BATCH = VISUALISED_WINDOWS
AUTHORS = "authors' train_pointcloud.py (same run)"
#: Baseline of the stage-2 rows (sizes ``default`` and ``large``).
REFERENCE = "reference network (fast_path=false), same run"


#: The presets :func:`setup` builds: the paper's settings (``model=pcmrl`` / ``model=pcmrl_interp``
#: defaults) or the 2-CPU-hour presets' model and batch (``experiment=pcmrl_cpu2h`` /
#: ``experiment=pcmrl_interp_cpu2h``) on the same one clip.
PRESETS = ("paper", "cpu2h")


def _preset_options(stage: str, preset: str) -> tuple[dict[str, Any], dict[str, Any]]:
    """``(model options, data options)`` of ``preset`` for ``stage`` (empty for ``paper``).

    Raises:
        ValueError: ``stage`` or ``preset`` is unknown.
    """
    if stage not in ("recon", "interp"):
        raise ValueError(f"stage must be 'recon' or 'interp', got {stage!r}")
    if preset not in PRESETS:
        raise ValueError(f"preset must be one of {', '.join(PRESETS)}, got {preset!r}")
    if preset == "paper":
        return {}, {}
    from omegaconf import OmegaConf

    from skelagnostic.cli import app

    model, experiment = (
        ("pcmrl", "pcmrl_cpu2h") if stage == "recon" else ("pcmrl_interp", "pcmrl_interp_cpu2h")
    )
    with tempfile.TemporaryDirectory() as run_dir:
        cfg = app.compose([f"model={model}", f"experiment={experiment}", f"run_dir={run_dir}"])
        options = OmegaConf.to_container(cfg.model, resolve=True)
        data = OmegaConf.to_container(cfg.data, resolve=False)
    assert isinstance(options, dict) and isinstance(data, dict)
    target = str(options.pop("_target_"))
    module, _, name = target.rpartition(".")
    accepted = inspect.signature(getattr(importlib.import_module(module), name)).parameters
    options = {k: v for k, v in options.items() if k in accepted}  # not e.g. the config's name
    keep = (
        ("window", "stride", "batch_size")
        if stage == "recon"
        else ("window", "stride", "batch_size", "key_mode", "rpa_prob", "mirror", "fps")
    )
    return options, {k: data[k] for k in keep if k in data}


def setup(
    stage: str, batch: int | None = None, preset: str = "paper", **model_options: Any
) -> tuple[Any, Any, str]:
    """The aligner (seed 0) and data module of one ``stage`` (recon or interp) at ``preset``.

    Args:
        stage: ``"recon"`` (stage 1) or ``"interp"`` (stage 2).
        batch: Windows per step (``None``: the preset's, 16 for ``paper``).
        preset: One of :data:`PRESETS`. ``cpu2h`` takes the model and the window, batch and
            keyframe options of the preset and trains on the clip of the ``paper`` rows
            (stage 2: LaFAN1 walk4_subject1, the preset's skeleton).
        **model_options: More constructor options of the aligner (e.g. ``fast_path``).

    Returns:
        ``(aligner, data module, description of the data)``.
    """
    sys.path.insert(0, str(REPO_ROOT / "plugins" / "pcmrl" / "src"))
    import torch
    from skelagnostic_pcmrl.interp.aligner import PcmrlInterpAligner
    from skelagnostic_pcmrl.interp.data import PcmrlInterpDataModule
    from skelagnostic_pcmrl.recon.aligner import PcmrlReconAligner
    from skelagnostic_pcmrl.recon.data import PcmrlReconDataModule

    from skelagnostic.data import BVHSource, ProceduralSource

    options, data_options = _preset_options(stage, preset)
    options.update(model_options)
    data_options["batch_size"] = batch or data_options.get("batch_size", BATCH["default"])
    root = shared_data("human/cmu", "human/lafan1")
    cache = Path(tempfile.gettempdir()) / "skelagnostic-bench-cache"
    lafan1 = None if root is None else root / "human" / "lafan1" / "walk4_subject1.bvh"
    torch.manual_seed(0)
    dm: Any
    if stage == "recon":
        if lafan1 is not None:
            source: Any = BVHSource([lafan1], units="cm", name="lafan1")
            target, target_units = str(root / "human" / "cmu" / "131_01.bvh"), "cmu"
            data = "LaFAN1 walk4_subject1 -> CMU-31 (131_01)"
        else:
            source = ProceduralSource(kinds=["biped22"], gaits=["walk", "run"], seconds=8.0)
            target, target_units = "biped31", None
            data = "procedural biped22 -> biped31"
        data_options = {"window": 64, "stride": 16, **data_options}
        dm = PcmrlReconDataModule(
            source,
            target=target,
            target_units=target_units,
            fps=30.0,
            val_fraction=0.0,
            cache_dir=cache,
            **data_options,
        )
        options.pop("target", None)
        options.pop("target_units", None)
        return PcmrlReconAligner(**options), dm, data
    if preset == "paper" and root is not None:
        source = BVHSource([root / "human" / "cmu"], units="cmu", name="cmu")
        data = "CMU-31 (131_01, 131_03) at 30 fps"
    elif lafan1 is not None:
        source = BVHSource([lafan1], units="cm", name="lafan1")
        data = "LaFAN1-22 (walk4_subject1) at 30 fps"
    else:
        source = ProceduralSource(kinds=["biped31"], gaits=["walk", "run"], seconds=10.0)
        data = "procedural biped31"
    data_options = {"fps": 30.0, **data_options}
    dm = PcmrlInterpDataModule(source, val_fraction=0.0, **data_options)
    return PcmrlInterpAligner(**options), dm, data


def measure(
    stage: str,
    steps: int,
    accelerator: str = "cpu",
    batch: int = BATCH["default"],
    fast_path: bool = True,
    layout: str | None = None,
) -> dict[str, Any]:
    """Median step time and data share of ``steps`` steps of ``stage`` (recon or interp).

    ``fast_path=False`` (stage 2 only) times the reference network that encodes every frame;
    ``layout`` (stage 1 only) is ``model.layout`` (default: the aligner's).
    """
    import lightning as L
    import torch

    options: dict[str, Any] = {} if stage == "recon" else {"fast_path": fast_path}
    if layout is not None:
        options["layout"] = layout
    model, dm, data = setup(stage, batch, **options)
    L.seed_everything(0, verbose=False)  # the same windows and keyframes for both networks
    timing = time_fit(model, dm, steps, accelerator=accelerator)
    return {
        **timing,
        "data": data,
        "threads": torch.get_num_threads(),
        "parameters": sum(p.numel() for p in model.parameters()),
    }


def authors_stage1(repo: Path, steps: int, batch: int) -> tuple[dict[str, Any], float]:
    """Time the authors' stage 1 at this part's settings: (timing, peak RSS in MiB).

    Raises:
        FileNotFoundError: If the shared clips are missing (the comparison needs the
            same real clip on both sides).
    """
    root = shared_data("human/lafan1", "human/xia_cmu")
    if root is None:
        raise FileNotFoundError(
            "--authors-repo pcmrl: the comparison with the authors' stage 1 needs the shared "
            "LaFAN1 and CMU clips ($SKELAGNOSTIC_TEST_DATA or ../shared/data)"
        )
    return run_child(
        "benchmarks.suites.authors_pcmrl:train_stage1",
        repo=str(repo),
        source=str(root / "human" / "lafan1" / "walk4_subject1.bvh"),
        target_skeleton=str(root / "human" / "xia_cmu" / "neutral_01_000.bvh"),
        steps=steps,
        batch_size=batch,
        window=64,
    )


def run(size: str) -> list[Result]:
    """Steps/s, windows/s, data-loading share and peak RSS of both stages.

    With ``--authors-repo pcmrl=DIR`` the authors' stage 1 is the baseline of the
    CPU ``recon`` rows (otherwise they have none); the ``interp`` rows of sizes
    ``default`` and ``large`` have the reference network (:data:`REFERENCE`).
    """
    repo = authors_repo("pcmrl")
    batch = BATCH[size] if repo is None else max(BATCH[size], AUTHORS_MIN_BATCH)
    theirs = authors_stage1(repo, STEPS[size][0], batch) if repo is not None else None
    results = []
    for device in accelerators():
        for stage, steps in zip(("recon", "interp"), STEPS[size], strict=True):
            child = "benchmarks.suites.training_pcmrl:measure"
            out, rss = run_child(child, stage=stage, steps=steps, accelerator=device, batch=batch)
            step, tag = out["median_step_s"], f"{stage}{suffix(device)}"
            base, base_rss, name = None, None, None
            if theirs is not None and stage == "recon" and device == "cpu":
                base, base_rss, name = theirs[0]["median_step_s"], theirs[1], AUTHORS
            elif stage == "interp" and size != "smoke":
                ref, base_rss = run_child(
                    child, stage=stage, steps=steps, accelerator=device, batch=batch,
                    fast_path=False,
                )  # fmt: skip
                base, name = ref["median_step_s"], REFERENCE
            results += _rows(tag, batch, step, out["data_share"], rss, name, base, base_rss)
            if theirs is not None and stage == "recon" and device == "cpu":
                same, same_rss = run_child(
                    child, stage=stage, steps=steps, accelerator=device, batch=batch,
                    layout="authors",
                )  # fmt: skip
                results += _rows(
                    f"{tag}_authors_layout", batch, same["median_step_s"], same["data_share"],
                    same_rss, name, base, base_rss,
                )  # fmt: skip
    return results


def _rows(
    tag: str,
    batch: int,
    step: float,
    data_share: float,
    rss: float,
    name: str | None,
    base: float | None,
    base_rss: float | None,
) -> list[Result]:
    """Steps/s, windows/s, data share and peak RSS of one measurement against its baseline."""
    return [
        Result(f"pcmrl_{tag}_steps_per_s", "steps/s", 1.0 / step, name,
               base and 1.0 / base, higher_is_better=True),
        Result(f"pcmrl_{tag}_windows_per_s", "windows/s", batch / step, name,
               base and batch / base, higher_is_better=True),
        Result(f"pcmrl_{tag}_data_share", "fraction", data_share),
        Result(f"pcmrl_{tag}_peak_rss_mib", "MiB", rss, name, base_rss),
    ]  # fmt: skip
