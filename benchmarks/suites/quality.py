"""Suite ``quality``: each method's evaluation protocol on held-out clips, after a short training.

Every part trains its method from scratch for a fixed number of steps (in a
child process, one torch thread unless ``--threads`` says otherwise), then runs
the method's own evaluation on held-out clips and reports the figures its paper
reports, each next to a baseline measured in the same run:

* HuMoT (``quality_humot``): reconstruction MPJPE (cm) on held-out procedural
  clips of three human topologies, against the clip's mean pose; retargeting
  error between topologies against paired procedural ground truth,
  normalised by the target's height, against the nearest-joint-name copy.
  The network is the reduced CPU configuration of ``experiment=humot_quick``.
* VQ-PAE (``quality_vqpae``): predicted gait frequency (relative error) and
  phase linearity (R^2 of the unwrapped phase) on held-out procedural gaits of
  a biped and a quadruped (``benchmarks/vqpae_quality.py procedural``).
* PC-MRL interpolation (``quality_pcmrl_interp``): L2P at keyframe gaps 5, 15
  and 30 on 128-frame windows of held-out procedural biped31 clips (the
  paper's Table 1 protocol, ``skelagnostic_pcmrl.interp_eval``; L2P normalised
  with the evaluated windows' statistics), against LERP/SLERP, for
  ``experiment=pcmrl_interp_cpu``.

Not included yet: PC-MRL stage 1 (the temporal KNN metric of Table 2 takes
minutes per clip on a CPU; ``python -m skelagnostic_pcmrl.evaluate`` runs it).

Sizes are training budgets: ``smoke`` checks that the protocols run (a few
steps, figures meaningless), ``default`` fits in about five minutes on two
idle cores, ``large`` is the budget the method pages in docs/methods/ report.
These budgets are far below the papers' GPU training: read the figures as
"what a CPU buys", not as a reproduction.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path
from typing import Any

from benchmarks.harness import REPO_ROOT, Result, run_child

#: Training steps per size and method.
STEPS: dict[str, dict[str, int]] = {
    "smoke": {"humot": 3, "vqpae": 5, "pcmrl_interp": 3},
    "default": {"humot": 120, "vqpae": 400, "pcmrl_interp": 300},
    "large": {"humot": 600, "vqpae": 2000, "pcmrl_interp": 2000},
}


def _plugin(name: str) -> None:
    """Make ``plugins/<name>/src`` importable when the plugin is not installed."""
    src = str(REPO_ROOT / "plugins" / name / "src")
    if src not in sys.path:
        sys.path.insert(0, src)


def humot(steps: int) -> dict[str, Any]:
    """Train the reduced HuMoT on procedural humans, evaluate on held-out seeds."""
    _plugin("humot")
    import lightning as L
    from skelagnostic_humot import HumotAligner, HumotDataModule
    from skelagnostic_humot.evaluate import HUMAN_KINDS, evaluate_procedural

    from skelagnostic.data import ProceduralSource

    L.seed_everything(0, verbose=False)
    source = ProceduralSource(kinds=list(HUMAN_KINDS), gaits=["walk", "run"],
                              clips_per_gait=4, seconds=6.0)
    cache = Path(tempfile.gettempdir()) / "skelagnostic-quality-cache"
    dm = HumotDataModule([source], batch_size=16, val_fraction=0.0, cache_dir=cache)
    # experiment=humot_quick: the CPU configuration (0.41 M parameters)
    model = HumotAligner(dim=64, latent=64, blocks=2, heads=8, lr_min=1e-4, lr_max=1e-3,
                         lr_period_epochs=40)
    with tempfile.TemporaryDirectory() as run_dir:
        trainer = L.Trainer(max_steps=steps, accelerator="cpu", devices=1, logger=False,
                            enable_checkpointing=False, enable_progress_bar=False,
                            enable_model_summary=False, limit_val_batches=0,
                            num_sanity_val_steps=0, default_root_dir=run_dir)
        trainer.fit(model, datamodule=dm)
    model.eval()
    clips = 1 if steps < 10 else 2
    return evaluate_procedural(model, clips_per_gait=clips, seconds=4.0 if clips == 1 else 6.0)


def vqpae(steps: int) -> dict[str, Any]:
    """``vqpae_quality.py procedural`` at ``steps`` steps."""
    _plugin("vqpae")
    from benchmarks.vqpae_quality import check_procedural

    return check_procedural(steps, lr=1e-3, fps=30.0, options={})


def pcmrl_interp(steps: int) -> dict[str, Any]:
    """Train ``experiment=pcmrl_interp_cpu`` for ``steps`` steps; Table 1 on held-out clips."""
    _plugin("pcmrl")
    import skelagnostic_pcmrl.plugin as plugin
    from skelagnostic_pcmrl.interp import InterpolationAligner
    from skelagnostic_pcmrl.interp_eval import GAPS, evaluate, lerp_slerp

    from skelagnostic import procedural
    from skelagnostic.cli.app import compose, run
    from skelagnostic.plugins import PluginManager

    pm = PluginManager(load_entrypoints=False)
    pm.register(plugin, "pcmrl")
    with tempfile.TemporaryDirectory() as tmp:
        run(compose(["model=pcmrl_interp", "experiment=pcmrl_interp_cpu", f"run_dir={tmp}",
                     f"trainer.max_steps={steps}", "trainer.max_time=null",
                     "trainer.limit_val_batches=0", "logger=none",
                     f"data.cache_dir={Path(tmp) / 'cache'}"], plugin_manager=pm), pm)
        model = InterpolationAligner.load_from_checkpoint(
            Path(tmp) / "checkpoints" / "last.ckpt", map_location="cpu").eval()
    clips = [procedural.generate("biped31", gait, seconds=8.0, fps=30, seed=777 + k)[0]
             for gait in ("walk", "run") for k in range(2)]
    return evaluate({"model": model.interpolate, "lerp": lerp_slerp}, clips, gaps=GAPS)


def _humot_results(out: dict[str, Any], steps: int) -> list[Result]:
    results = []
    tag = f" ({steps} steps)"
    for kind, res in out["kinds"].items():
        rec = res["reconstruction"]
        results.append(Result(f"humot_reconstruction_mpjpe {kind}{tag}", "cm", rec["mpjpe_cm"],
                              "mean pose of the clip", rec["mean_pose_cm"]))
    mean = out["retargeting"]["mean"]  # over the ordered topology pairs
    results.append(Result(f"humot_retargeting_error_over_height{tag}", "ratio",
                          mean["humot_mpjpe_over_height"], "nearest-joint-name copy",
                          mean["name_copy_mpjpe_over_height"]))
    return results


def _vqpae_results(out: dict[str, Any], steps: int) -> list[Result]:
    results = []
    tag = f" ({steps} steps)"
    for clip in out["clips"]:
        results.append(Result(f"vqpae_frequency_rel_error {clip['clip']}{tag}", "ratio",
                              float(clip["rel_error"])))
        results.append(Result(f"vqpae_phase_r2 {clip['clip']}{tag}", "R^2",
                              float(clip["phase_r2"]), higher_is_better=True))
    return results


def _pcmrl_interp_results(out: dict[str, Any], steps: int) -> list[Result]:
    results = []
    model, lerp = out["results"]["model"], out["results"]["lerp"]
    for gap, figures in model.items():
        results.append(Result(f"pcmrl_interp_l2p gap {gap} ({steps} steps)", "L2P",
                              float(figures["l2p"]), "LERP/SLERP",
                              float(lerp[gap]["l2p"])))
    return results


def run(size: str) -> list[Result]:
    """Train and evaluate every method at ``size``."""
    steps = STEPS[size]
    out, _ = run_child("benchmarks.suites.quality:humot", steps=steps["humot"])
    results = _humot_results(out, steps["humot"])
    out, _ = run_child("benchmarks.suites.quality:vqpae", steps=steps["vqpae"])
    results += _vqpae_results(out, steps["vqpae"])
    out, _ = run_child("benchmarks.suites.quality:pcmrl_interp", steps=steps["pcmrl_interp"])
    results += _pcmrl_interp_results(out, steps["pcmrl_interp"])
    return results
