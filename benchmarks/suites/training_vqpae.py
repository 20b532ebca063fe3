"""Suite ``training`` (VQ-PAE part): training throughput at the authors' settings.

Two datasets (LaFAN1 human + MANN dog from ``$SKELAGNOSTIC_TEST_DATA`` or
``../shared/data``; procedural biped + quadruped when the clips are absent),
batch 32 per dataset, 1 s windows at 60 fps (T = 61), K = 32, the full Lightning
training step (data loading, both VQ-PAEs, codebook re-initialisation, AdamW,
scheduler) on CPU, with the network of the authors' ``train_vq.py`` set
explicitly (:data:`AUTHORS_OPTIONS`: zero padding, raw power spectrum, kernel-23
timing convolution, 7-layer frequency MLP with ELUs, decoder centring, windows
not centred, squared-distance re-initialisation), so the comparison stays at
equal settings whatever ``model=vqpae``'s defaults are:

* ``vqpae_windows_per_s_pose`` / ``vqpae_steps_per_s_pose``: with the average-pose
  MLPs trained alongside (``pose_mlp="joint"``, as the authors' trainer does with
  its phase decoders);
* ``vqpae_windows_per_s_nopose`` / ``_steps_per_s_nopose``: without them
  (``pose_mlp="none"``; theirs with ``--train_phase_decoder=0``);
* ``..._pose_phase_rate`` / ``..._nopose_phase_rate``: the same with the phase-rate
  loss (``lambda_phase_rate=1``, not in the paper), which also encodes every
  window's partner (no baseline).

The first two run with ``lambda_phase_rate=0``, the authors' objective. Also
``vqpae_data_share_<tag>``, the share of the step time spent fetching batches,
and ``vqpae_peak_rss_mib_<tag>``, the peak RSS of the process that trained.
Windows/s = 64 windows per step / median step time (compute and the data fetch
before it, :mod:`benchmarks.suites.steptime`).

Baseline (``run.py --authors-repo walkthedog=DIR``): the authors' ``train_vq.py``
run in the same suite, in a child process, on the same clips converted to their
format (``wtd_data.py``, 60 fps, no mirrored copies), batch 32 per dataset, 1 s
windows, K = 32, ``--std_cap=0.001``, the same torch thread count; its steps/s,
windows/s and peak RSS (main process; its four data-loader workers' largest peak
is ``vqpae_authors_worker_peak_rss_mib_<tag>``) are the baseline of the ``pose``
and ``nopose`` rows (:mod:`benchmarks.suites.authors_walkthedog`). Without the
option the baseline is absent (``null``).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path
from typing import Any

from benchmarks.authors import authors_repo
from benchmarks.harness import REPO_ROOT, Result, run_child, shared_data
from benchmarks.suites.steptime import accelerators, suffix, time_fit

STEPS = {"smoke": 15, "default": 60, "large": 200}
#: Untimed steps first, on both sides.
WARMUP = 5
#: Windows per dataset per step, on both sides.
BATCH = 32
#: The network and objective of the authors' ``train_vq.py`` (its defaults), as VqpaeAligner
#: options; ``pose_mlp`` and ``lambda_phase_rate`` are set per row.
AUTHORS_OPTIONS: dict[str, Any] = {
    "latent": 10, "num_codes": 32, "kernel_size": 23, "freq_layers": 7, "amp_layers": 5,
    "decoder_centering": True, "spectrum": "power", "padding_mode": "zeros",
    "frequency_head": "mlp", "phase_kernel": 23, "freq_hidden_elu": True,
    "center_windows": False, "reinit_squared_distance": True, "pose_layers": 8,
    "pose_lr": 1e-3,
    "optimizer": {
        "_target_": "torch.optim.AdamW", "_partial_": True, "lr": 1e-4, "weight_decay": 1e-4,
    },
}  # fmt: skip
#: Row tag -> (pose_mlp, lambda_phase_rate, the authors' --train_phase_decoder or None).
ROWS: dict[str, tuple[str, float, bool | None]] = {
    "pose": ("joint", 0.0, True),
    "nopose": ("none", 0.0, False),
    "pose_phase_rate": ("joint", 1.0, None),
    "nopose_phase_rate": ("none", 1.0, None),
}
AUTHORS = "authors' train_vq.py (same run)"


def clips(root: Path) -> tuple[list[Path], list[Path]]:
    """The human (LaFAN1) and dog (MANN) clips of the shared data under ``root``."""
    human = [
        root / "human" / "lafan1" / "Lafan1_example.bvh",
        root / "human" / "lafan1" / "walk4_subject1.bvh",
    ]
    return human, sorted((root / "dog" / "mann").glob("*.bvh"))


def measure(
    pose_mlp: str, steps: int, accelerator: str = "cpu", lambda_phase_rate: float = 0.0
) -> dict[str, Any]:
    """Median training-step time (seconds) of ``steps`` steps after 5 warm-up steps."""
    sys.path.insert(0, str(REPO_ROOT / "plugins" / "vqpae" / "src"))
    from skelagnostic_vqpae.aligner import VqpaeAligner
    from skelagnostic_vqpae.data import MultiSource, VqpaeDataModule

    from skelagnostic.data import BVHSource, ProceduralSource

    root = shared_data("dog/mann")
    if root is not None:
        human_files, dog_files = clips(root)
        human = BVHSource(human_files, units="cm", name="human")
        dog = BVHSource(dog_files, units="cm", name="dog")
        source: Any = MultiSource([human, dog])
        data = "LaFAN1 (2 clips) + MANN dog (8 clips)"
    else:
        source = ProceduralSource(kinds=["biped22", "quadruped"], seconds=20.0)
        data = "procedural biped22 + quadruped"
    cache = Path(tempfile.gettempdir()) / "skelagnostic-bench-cache"
    # partner windows only where the loss uses them (the presets without it set 0 too)
    dm = VqpaeDataModule(
        source,
        fps=60,
        stride=1,
        batch_size=BATCH,
        cache_dir=cache,
        pair_seconds=0.1 if lambda_phase_rate > 0 else 0.0,
    )
    model = VqpaeAligner(**AUTHORS_OPTIONS, pose_mlp=pose_mlp, lambda_phase_rate=lambda_phase_rate)
    timing = time_fit(model, dm, steps, warmup=WARMUP, accelerator=accelerator)
    return {**timing, "data": data, "threads": __import__("torch").get_num_threads()}


def authors_baselines(repo: Path, steps: int) -> dict[str, tuple[dict[str, Any], float]]:
    """Time the authors' trainer on the shared clips: row tag -> (timing, peak RSS in MiB).

    Raises:
        FileNotFoundError: If the shared clips (or ``wtd_data.py``) are missing: the
            comparison needs the same real clips on both sides.
    """
    from benchmarks.suites.authors_walkthedog import write_datasets

    root = shared_data("dog/mann", "human/lafan1")
    if root is None:
        raise FileNotFoundError(
            "--authors-repo walkthedog: the comparison with the authors' trainer needs the "
            "shared LaFAN1 and MANN dog clips ($SKELAGNOSTIC_TEST_DATA or ../shared/data)"
        )
    human, dog = clips(root)
    out: dict[str, tuple[dict[str, Any], float]] = {}
    with tempfile.TemporaryDirectory(prefix="wtd-") as tmp:
        datasets = write_datasets(Path(tmp), {"human": (human, "biped"), "dog": (dog, "quadruped")})
        for tag, (_, _, decoder) in ROWS.items():
            if decoder is None:
                continue
            out[tag] = run_child(
                "benchmarks.suites.authors_walkthedog:train",
                repo=str(repo),
                datasets=[str(d) for d in datasets],
                steps=steps,
                warmup=WARMUP,
                phase_decoder=decoder,
                batch_size=BATCH,
                num_codes=AUTHORS_OPTIONS["num_codes"],
            )
    return out


def run(size: str) -> list[Result]:
    """Windows/s, steps/s and peak RSS with and without the pose MLPs (CPU, and a GPU if any).

    With ``--authors-repo walkthedog=DIR`` the authors' trainer is the baseline of
    the CPU ``pose`` and ``nopose`` rows; otherwise every baseline is absent.
    """
    steps = STEPS[size]
    repo = authors_repo("walkthedog")
    theirs = authors_baselines(repo, steps) if repo is not None else {}
    results = []
    for device in accelerators():
        for label, (mode, rate, _) in ROWS.items():
            out, rss = run_child(
                "benchmarks.suites.training_vqpae:measure",
                pose_mlp=mode,
                steps=steps,
                accelerator=device,
                lambda_phase_rate=rate,
            )
            tag = f"{label}{suffix(device)}"
            base, base_rss = theirs.get(label, (None, None)) if device == "cpu" else (None, None)
            name = AUTHORS if base is not None else None
            step, base_step = out["median_step_s"], base and base["median_step_s"]
            results += [
                Result(
                    f"vqpae_windows_per_s_{tag}",
                    "windows/s",
                    2 * BATCH / step,
                    name,
                    base_step and 2 * BATCH / base_step,
                    higher_is_better=True,
                ),
                Result(
                    f"vqpae_steps_per_s_{tag}",
                    "steps/s",
                    1 / step,
                    name,
                    base_step and 1 / base_step,
                    higher_is_better=True,
                ),
                Result(f"vqpae_data_share_{tag}", "fraction", out["data_share"]),
                Result(f"vqpae_peak_rss_mib_{tag}", "MiB", rss, name, base_rss),
            ]
            if base is not None:
                results.append(
                    Result(
                        f"vqpae_authors_worker_peak_rss_mib_{tag}",
                        "MiB",
                        base["children_peak_rss_mib"],
                    )
                )
    return results
