"""HuMoT's ablations (paper Sec. 4, "Ours - no SJS", "Ours - no BLC") at an equal budget.

Protocol ``humot.ablations`` (``skelagnostic evaluate model=humot ckpt_path=RUN
protocol=humot.ablations [+protocol_options.steps=N]``): the evaluated run's
configuration is trained again from one initialisation for the same number of
optimiser steps on the run's training clips, once per variant of
:data:`ABLATIONS`:

* ``full``: the run's hyperparameters unchanged (the reference, retrained at the
  same budget as the others);
* ``no_subsampling``: ``subsampling=False``, the paper's "no SJS";
* ``no_bone_length_loss``: ``lambda_blc=0``, the paper's "no BLC".

Every variant, the evaluated checkpoint itself (:data:`~skelagnostic.evaluation.MODEL`)
and the ground-truth baselines of
:func:`~skelagnostic_humot.evaluation.reconstruction.reconstruction`
are then measured on the held-out clips: the reconstruction MPJPE on the clip's
own template (Table 2), the temporal bone-length consistency of the reconstruction
(Eq. 2, over the bones of non-zero length; what the BLC loss targets) and the
MPJPE of joint upsampling from half of the joints (Fig. 9; what subsampling
trains for).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import lightning as L
import torch

from skelagnostic.aligners import quiet_trainer
from skelagnostic.evaluation import MODEL, Evaluation, EvaluationError, HeldOut
from skelagnostic.metrics.functional import bone_length_consistency
from skelagnostic_humot.aligner import HumotAligner
from skelagnostic_humot.data import prepare_chunks
from skelagnostic_humot.evaluation.reconstruction import (
    chunks_of,
    reconstruction,
    run_network,
    upsampling_curve,
)

__all__ = ["ABLATIONS", "METRICS", "ablation_protocol", "train_variant"]

#: ``variant -> hyperparameters it changes``; ``full`` is the run's configuration.
ABLATIONS: dict[str, dict[str, Any]] = {
    "full": {},
    "no_subsampling": {"subsampling": False},
    "no_bone_length_loss": {"lambda_blc": 0.0},
}

#: The metrics of :func:`ablation_protocol`.
METRICS: dict[str, str] = {
    "mpjpe_cm": "MPJPE of 1 s chunks decoded on their own template, cm, lower is better",
    "blc_x1e3": "temporal bone-length consistency of the reconstruction (Eq. 2) x 1000, "
    "lower is better",
    "upsampling_half_cm": "MPJPE on all joints when half of them are encoded (Fig. 9), cm, "
    "lower is better",
}

#: Default optimiser steps per variant (``+protocol_options.steps``).
DEFAULT_STEPS = 200


def train_variant(
    hparams: Mapping[str, Any],
    changes: Mapping[str, Any],
    datamodule: Any,
    steps: int,
    seed: int = 0,
    root_dir: Path | None = None,
) -> HumotAligner:
    """A HuMoT with ``hparams`` updated by ``changes``, trained ``steps`` optimiser steps.

    The network is initialised from ``seed`` (the changes of :data:`ABLATIONS` leave
    the architecture alone, so every variant starts from the same weights) and
    trained on ``datamodule``'s training split without validation, logging or
    checkpoints.

    Args:
        hparams: Constructor arguments (the evaluated aligner's ``hparams``).
        changes: The arguments the variant changes.
        datamodule: The run's HuMoT data module.
        steps: Optimiser steps.
        seed: Seed of the initial weights and of the training order.
        root_dir: Lightning's ``default_root_dir`` (nothing is written there but
            Lightning's own bookkeeping).

    Returns:
        The trained aligner, in eval mode.
    """
    L.seed_everything(seed, verbose=False)
    model = HumotAligner(**{**dict(hparams), **dict(changes)})
    trainer = quiet_trainer(
        max_steps=steps,
        max_epochs=-1,
        accelerator="cpu",
        devices=1,
        limit_val_batches=0,
        num_sanity_val_steps=0,
        default_root_dir=root_dir,
    )
    with torch.enable_grad():
        trainer.fit(model, datamodule=datamodule)
    return model.eval()


def _measure(model: HumotAligner, chunks: torch.Tensor, clip: Any) -> dict[str, float]:
    sk = clip.skeleton
    topo = model.topology(sk)
    pos, tmpl = prepare_chunks(chunks, topo, sk.up_axis)
    rec = run_network(model, pos, tmpl, tmpl)
    # Eq. 2 divides by the true length: bones of zero length (CMU's hip joints) are left out
    bones = [
        (p, c)
        for p, c in topo.skeleton.bones()
        if bool(((pos[..., c, :] - pos[..., p, :]).norm(dim=-1) > 1e-6).all())
    ]
    blc = bone_length_consistency(rec.double(), pos.double(), bones)
    up = upsampling_curve(model, chunks, topo, fractions=(0.5,), up_axis=sk.up_axis)
    return {
        "mpjpe_cm": 100 * float((rec - pos).norm(dim=-1).mean()),
        "blc_x1e3": 1000 * float(blc),
        "upsampling_half_cm": up["mpjpe_cm"][0],
    }


def ablation_protocol(
    aligner: HumotAligner,
    held: HeldOut,
    out_dir: Path,
    steps: int = DEFAULT_STEPS,
    seed: int = 0,
    variants: Mapping[str, Mapping[str, Any]] | None = None,
) -> Evaluation:
    """``humot.ablations``: the variants of :data:`ABLATIONS` beside the run and the baselines.

    Args:
        aligner: The evaluated HuMoT (its hyperparameters define ``full``).
        held: The held-out clips; ``held.datamodule`` (the run's data module)
            provides the training clips of the variants.
        out_dir: The evaluation's directory (Lightning's root directory of the variants).
        steps: Optimiser steps of every variant (``+protocol_options.steps=N``).
        seed: Seed of the variants' common initial weights.
        variants: ``name -> changed hyperparameters`` (default :data:`ABLATIONS`).

    Returns:
        Rows per held-out human clip with the methods ``model`` (the checkpoint),
        one per variant and the ``mean_pose`` / ``mean_pose_on_trajectory`` baselines.

    Raises:
        EvaluationError: ``steps`` is not positive, a variant changes an unknown
            hyperparameter, or there is no data module to train on.
    """
    if not isinstance(steps, int) or isinstance(steps, bool) or steps < 1:
        raise EvaluationError(
            f"humot.ablations: protocol_options.steps must be a positive integer, got {steps!r}"
        )
    variants = dict(ABLATIONS if variants is None else variants)
    hparams = dict(aligner.hparams)
    for name, changes in variants.items():
        unknown = sorted(set(changes) - set(hparams))
        if unknown:
            raise EvaluationError(
                f"humot.ablations: variant {name!r} changes {unknown}, which are not "
                f"HumotAligner arguments ({sorted(hparams)})"
            )
    if held.datamodule is None:
        raise EvaluationError(
            "humot.ablations trains the variants on the run's training clips: the held-out "
            "clips came without their data module"
        )
    notes = [
        f"variants retrained from one initialisation (seed {seed}) for {steps} optimiser steps "
        "each on the run's training clips: "
        + "; ".join(f"{n}: {dict(c) or 'the run configuration'}" for n, c in variants.items()),
        "model is the evaluated checkpoint at its own budget; baselines use the ground truth "
        "(mean_pose: the chunk's temporal mean pose; mean_pose_on_trajectory: its mean "
        "root-relative pose along the true root path)",
    ]
    clips = []
    for clip in held.clips:
        if clip.skeleton.morphology != "biped":
            notes.append(f"skipped non-human clip {clip.name}")
            continue
        chunks = chunks_of(clip, aligner.hparams.chunk)
        if not len(chunks):
            notes.append(f"skipped {clip.name}: shorter than one chunk at 30 fps")
            continue
        clips.append((clip, chunks))
    if not clips:
        raise EvaluationError("humot.ablations: no held-out human clip of at least one chunk")
    models = {MODEL: aligner}
    for name, changes in variants.items():
        models[name] = train_variant(
            hparams, changes, held.datamodule, steps, seed, out_dir / "ablations"
        )
    rows = []
    for clip, chunks in clips:
        values = {name: _measure(model, chunks, clip) for name, model in models.items()}
        base = reconstruction(
            aligner, chunks, aligner.topology(clip.skeleton), clip.skeleton.up_axis
        )
        values["mean_pose"] = {"mpjpe_cm": base["mean_pose_cm"]}
        values["mean_pose_on_trajectory"] = {"mpjpe_cm": base["mean_pose_on_trajectory_cm"]}
        rows.append({"clip": str(clip.name), "chunks": len(chunks), "values": values})
    return Evaluation(
        dict(METRICS),
        rows,
        extra={"steps": steps, "seed": seed, "variants": variants},
        notes=notes,
    )
