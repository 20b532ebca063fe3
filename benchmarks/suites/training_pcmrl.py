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
131_01: the same 31-joint skeleton). It is the baseline of the ``recon`` rows.
Stage 2 has none: their stage-2 step also runs the stage-1 network on fresh
point clouds to make its training data, and its batch is fixed by the keyframe
range (32 windows), so it is not the same step as ours. Without the option the
baselines are absent (``null``).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path
from typing import Any

from benchmarks.authors import authors_repo
from benchmarks.harness import REPO_ROOT, Result, run_child, shared_data
from benchmarks.suites.steptime import accelerators, suffix, time_fit

#: Timed steps per size (after one warm-up step) for (reconstruction, interpolation). One
#: thread takes about 32 s and 13 s per step at these sizes (94.6 M and 61.8 M parameters).
STEPS = {"smoke": (1, 1), "default": (3, 3), "large": (10, 20)}
#: Windows per step (the batch size) of both stages, per size: ``smoke`` only checks that
#: the part runs (CI), so it takes 2 windows instead of the measured sizes' 16.
BATCH = {"smoke": 2, "default": 16, "large": 16}
AUTHORS = "authors' train_pointcloud.py (same run)"


def measure(
    stage: str, steps: int, accelerator: str = "cpu", batch: int = BATCH["default"]
) -> dict[str, Any]:
    """Median step time and data share of ``steps`` steps of ``stage`` (recon or interp)."""
    sys.path.insert(0, str(REPO_ROOT / "plugins" / "pcmrl" / "src"))
    import torch
    from skelagnostic_pcmrl.interp import PcmrlInterpAligner
    from skelagnostic_pcmrl.interp_data import PcmrlInterpDataModule
    from skelagnostic_pcmrl.recon import PcmrlReconAligner
    from skelagnostic_pcmrl.recon_data import PcmrlReconDataModule

    from skelagnostic.data import BVHSource, ProceduralSource

    root = shared_data("human/cmu", "human/lafan1")
    cache = Path(tempfile.gettempdir()) / "skelagnostic-bench-cache"
    torch.manual_seed(0)
    dm: Any
    if stage == "recon":
        if root is not None:
            source: Any = BVHSource(
                [root / "human" / "lafan1" / "walk4_subject1.bvh"], units="cm", name="lafan1"
            )
            target, target_units = str(root / "human" / "cmu" / "131_01.bvh"), "cmu"
            data = "LaFAN1 walk4_subject1 -> CMU-31 (131_01)"
        else:
            source = ProceduralSource(kinds=["biped22"], gaits=["walk", "run"], seconds=8.0)
            target, target_units = "biped31", None
            data = "procedural biped22 -> biped31"
        dm = PcmrlReconDataModule(
            source,
            target=target,
            target_units=target_units,
            fps=30.0,
            window=64,
            stride=16,
            batch_size=batch,
            val_fraction=0.0,
            cache_dir=cache,
        )
        model: Any = PcmrlReconAligner(lr=1e-4)
    else:
        if root is not None:
            source = BVHSource([root / "human" / "cmu"], units="cmu", name="cmu")
            data = "CMU-31 (131_01, 131_03) at 30 fps"
        else:
            source = ProceduralSource(kinds=["biped31"], gaits=["walk", "run"], seconds=10.0)
            data = "procedural biped31"
        dm = PcmrlInterpDataModule(source, fps=30.0, batch_size=batch, val_fraction=0.0)
        model = PcmrlInterpAligner()
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
    CPU ``recon`` rows; otherwise every baseline is absent.
    """
    repo = authors_repo("pcmrl")
    batch = BATCH[size]
    theirs = authors_stage1(repo, STEPS[size][0], batch) if repo is not None else None
    results = []
    for device in accelerators():
        for stage, steps in zip(("recon", "interp"), STEPS[size], strict=True):
            out, rss = run_child(
                "benchmarks.suites.training_pcmrl:measure",
                stage=stage,
                steps=steps,
                accelerator=device,
                batch=batch,
            )
            step, tag = out["median_step_s"], f"{stage}{suffix(device)}"
            base, base_rss = (None, None)
            if theirs is not None and stage == "recon" and device == "cpu":
                base, base_rss = theirs[0]["median_step_s"], theirs[1]
            name = AUTHORS if base is not None else None
            results += [
                Result(f"pcmrl_{tag}_steps_per_s", "steps/s", 1.0 / step, name,
                       base and 1.0 / base, higher_is_better=True),
                Result(f"pcmrl_{tag}_windows_per_s", "windows/s", batch / step, name,
                       base and batch / base, higher_is_better=True),
                Result(f"pcmrl_{tag}_data_share", "fraction", out["data_share"]),
                Result(f"pcmrl_{tag}_peak_rss_mib", "MiB", rss, name, base_rss),
            ]  # fmt: skip
    return results
