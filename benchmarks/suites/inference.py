"""Suite ``inference``: ``retarget``, ``interpolate`` and ``transfer`` end to end.

Each verb runs on a procedural clip of 60 s at 30 fps (``--size smoke``: 4 s;
``large``: 120 s) written to a temporary BVH, with a model at its method's
default (paper) sizes: the constructor's defaults, weights from a fixed seed,
saved as a Lightning checkpoint that the CLI reads. Timing needs no training:
the work per frame does not depend on the weights' values.

* ``retarget``: HuMoT (``model=humot``), a biped22 walk onto the biped31 rig.
* ``interpolate``: PC-MRL stage 2 (``model=pcmrl_interp``, trained skeleton
  biped31), a keyframe every 30 frames of a biped31 walk.
* ``transfer``: VQ-PAE (``model=vqpae``, characters biped22 and quadruped; its
  networks and statistics are built from a small procedural data module
  without a training step), a biped22 run re-enacted with 60 s of quadruped
  clips (walk, trot, gallop) as the matching database.

Figures per verb:

* ``<verb>_cli_s``: wall time of ``python -m skelagnostic.cli <verb> ...`` in a
  child process, as a user runs it (start-up, plugin loading, read, checkpoint,
  model, write); median of the repeats. ``<verb>_meets_10s`` is 1 when that is
  under 10 s (issue #28's goal), else 0.
* ``<verb>_read_s``, ``<verb>_load_s``, ``<verb>_model_s``, ``<verb>_write_s``:
  the stages as the CLI runs them, timed in-process (medians): reading the
  input BVH files, building the aligner from the checkpoint, the aligner's method
  (the network *and* the inverse kinematics or matching it does to produce local
  rotations: the methods do not expose those apart), writing the result.
  ``retarget_model_s`` has the name-copy baseline (``baselines.name_copy``) and
  ``interpolate_model_s`` the LERP/SLERP baseline (``baselines.lerp_slerp``),
  both timed in the same run on the same inputs; ``transfer`` has none.
* ``cli_startup_s``: a child process that imports the CLI, torch and Lightning
  and loads the plugins' aligner classes, as every verb does before its work:
  the fixed part of every ``<verb>_cli_s``.

Unless ``--threads`` is given, torch runs on one thread here and in the
children (the CLI's ``threads=`` option), the issue's setting for this machine.
"""

from __future__ import annotations

import os
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch

from benchmarks.harness import REPO_ROOT, THREADS_ENV, Result, run_process, timeit_median

SECONDS = {"smoke": 4.0, "default": 60.0, "large": 120.0}
REPEATS = {"smoke": 1, "default": 3, "large": 3}
FPS = 30.0
#: Keyframe spacing of ``interpolate`` (frames).
EVERY = 30
#: The issue's goal for each verb at 60 s (seconds).
GOAL_S = 10.0
SEED = 0


def _clip(kind: str, gait: str, seconds: float, path: Path, seed: int = 0) -> Path:
    import skelagnostic as sa

    motion, _ = sa.procedural.generate(kind, gait, seconds=seconds, fps=FPS, seed=seed)
    sa.write_bvh(motion, path)
    return path


def _save(model: Any, path: Path) -> Path:
    """``model`` written as a Lightning checkpoint at ``path``."""
    from skelagnostic.aligners import quiet_trainer

    trainer = quiet_trainer(accelerator="cpu", default_root_dir=str(path.parent))
    trainer.strategy.connect(model)
    trainer.save_checkpoint(path)
    return path


def _humot(workdir: Path) -> Path:
    from skelagnostic_humot.aligner import HumotAligner

    torch.manual_seed(SEED)
    return _save(HumotAligner(), workdir / "humot.ckpt")


def _pcmrl_interp(workdir: Path) -> Path:
    from skelagnostic_pcmrl.interp.aligner import PcmrlInterpAligner

    from skelagnostic import procedural

    torch.manual_seed(SEED)
    skeleton = procedural.skeleton("biped31").scaled(0.01)  # trained in metres
    model = PcmrlInterpAligner(skeleton=skeleton.to_dict(), fps=FPS)
    return _save(model, workdir / "pcmrl_interp.ckpt")


def _vqpae(workdir: Path) -> Path:
    """A VQ-PAE whose networks and statistics come from a small procedural data module."""
    import lightning as L
    from skelagnostic_vqpae.aligner import VqpaeAligner
    from skelagnostic_vqpae.data import VqpaeDataModule

    from skelagnostic.aligners import quiet_trainer
    from skelagnostic.data import ProceduralSource

    L.seed_everything(SEED, verbose=False)
    source = ProceduralSource(kinds=["biped22", "quadruped"], clips_per_gait=1, seconds=3.0)
    dm = VqpaeDataModule(source, fps=FPS, cache_dir=workdir / "cache")
    model = VqpaeAligner()
    # max_steps=0: Lightning builds the model from the data (configure_model), trains nothing
    trainer = quiet_trainer(
        max_steps=0,
        accelerator="cpu",
        limit_val_batches=0,
        default_root_dir=str(workdir),
    )
    trainer.fit(model, datamodule=dm)
    path = workdir / "vqpae.ckpt"
    trainer.save_checkpoint(path)
    return path


def _child_env(threads: int) -> dict[str, str]:
    env = dict(os.environ)
    paths = [str(REPO_ROOT / "src")]
    paths += sorted(str(p) for p in (REPO_ROOT / "plugins").glob("*/src"))
    env["PYTHONPATH"] = os.pathsep.join([*paths, *filter(None, [env.get("PYTHONPATH")])])
    env["OMP_NUM_THREADS"] = str(threads)
    return env


#: What every verb imports and loads before its work (``cli_startup_s``).
STARTUP = (
    "import lightning, torch, skelagnostic.cli.infer\n"
    "from skelagnostic.plugins import get_plugin_manager\n"
    "get_plugin_manager().aligner_classes()\n"
)


def _child_seconds(argv: list[str], threads: int, repeats: int) -> float:
    """Median wall time of ``python ARGV`` in a fresh process (that dies with this one)."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        proc = run_process([sys.executable, *argv], cwd=REPO_ROOT, env=_child_env(threads))
        times.append(time.perf_counter() - start)
        if proc.returncode != 0:
            raise RuntimeError(
                f"inference suite: 'python {' '.join(argv[:3])} ...' failed "
                f"(exit {proc.returncode}):\n{proc.stderr[-3000:]}"
            )
    return statistics.median(times)


def _stages(
    verb: str,
    read: Callable[[], tuple[Any, ...]],
    ckpt: Path,
    model_name: str,
    apply: Callable[[Any, tuple[Any, ...]], Any],
    out: Path,
    repeats: int,
) -> dict[str, float]:
    """Median seconds of the CLI's stages (read, load, model, write), run in-process."""
    from skelagnostic import write_bvh
    from skelagnostic.cli.infer import load_from_checkpoint

    inputs = read()
    aligner = load_from_checkpoint(ckpt, model_name)
    # as the CLI calls it: the methods switch gradients off themselves
    result = apply(aligner, inputs)
    model = timeit_median(lambda: apply(aligner, inputs), repeats, warmup=0)
    return {
        f"{verb}_read_s": timeit_median(read, repeats, warmup=0),
        f"{verb}_load_s": timeit_median(
            lambda: load_from_checkpoint(ckpt, model_name), repeats, warmup=0
        ),
        f"{verb}_model_s": model,
        f"{verb}_write_s": timeit_median(lambda: write_bvh(result, out), repeats, warmup=0),
    }


def run(size: str) -> list[Result]:
    """Run the suite at ``size`` and return its results."""
    from skelagnostic.baselines.keyframes import lerp_slerp
    from skelagnostic.baselines.names import name_copy
    from skelagnostic.cli.infer import _read, keyframes_from_options

    threads = int(os.environ.get(THREADS_ENV) or 1)
    torch.set_num_threads(threads)
    seconds, repeats = SECONDS[size], REPEATS[size]
    tag = f" ({seconds:g} s at {FPS:g} fps, {threads} thread(s))"
    results: list[Result] = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        walk22 = _clip("biped22", "walk", seconds, work / "walk22.bvh")
        rig31 = _clip("biped31", "idle", 1.0, work / "rig31.bvh")
        walk31 = _clip("biped31", "walk", seconds, work / "walk31.bvh", seed=1)
        run22 = _clip("biped22", "run", seconds, work / "run22.bvh", seed=2)
        dogs = work / "dogs"
        dogs.mkdir()
        for seed, gait in enumerate(("walk", "trot", "gallop")):
            _clip("quadruped", gait, seconds / 3, dogs / f"{gait}.bvh", seed=seed)
        opts: dict[str, str] = {}
        keys = keyframes_from_options(_read(walk31, opts).num_frames, str(EVERY), None)
        verbs = {
            "retarget": (
                ["retarget", str(walk22), str(rig31)],
                _humot(work),
                "humot",
                lambda: (_read(walk22, opts), _read(rig31, opts).skeleton),
                lambda a, x: a.retarget(*x),
                lambda x: name_copy(*x),
                "baselines.name_copy",
            ),
            "interpolate": (
                ["interpolate", str(walk31), f"every={EVERY}"],
                _pcmrl_interp(work),
                "pcmrl_interp",
                lambda: (_read(walk31, opts),),
                lambda a, x: a.interpolate(x[0], keys),
                lambda x: lerp_slerp(x[0], keys),
                "baselines.lerp_slerp",
            ),
            "transfer": (
                ["transfer", str(run22), str(dogs)],
                _vqpae(work),
                "vqpae",
                lambda: (_read(run22, opts), [_read(p, opts) for p in sorted(dogs.glob("*.bvh"))]),
                lambda a, x: a.transfer(*x),
                None,
                None,
            ),
        }
        startup = _child_seconds(["-c", STARTUP], threads, repeats)
        for verb, (argv, ckpt, name, read, apply, baseline, baseline_name) in verbs.items():
            out = work / f"{verb}_out.bvh"
            options = [f"ckpt={ckpt}", f"model={name}", f"out={out}", f"threads={threads}"]
            cli = _child_seconds(["-m", "skelagnostic.cli", *argv, *options], threads, repeats)
            stages = _stages(verb, read, ckpt, name, apply, work / f"{verb}_stage.bvh", repeats)
            results.append(Result(f"{verb}_cli_s" + tag, "s", cli))
            results.append(
                Result(
                    f"{verb}_meets_10s" + tag, "bool", float(cli < GOAL_S), higher_is_better=True
                )
            )
            for key, value in stages.items():
                if key.endswith("_model_s") and baseline is not None:
                    inputs = read()
                    base = timeit_median(lambda b=baseline, x=inputs: b(x), repeats, warmup=1)
                    results.append(Result(key + tag, "s", value, baseline_name, base))
                else:
                    results.append(Result(key + tag, "s", value))
        results.append(Result("cli_startup_s" + tag, "s", startup))
    return results
