"""PC-MRL: point-cloud reconstruction onto any target skeleton and keyframe interpolation.

Hook implementations of the PC-MRL plugin (entry point ``pcmrl`` in group ``skelagnostic``).

Two aligners, one per stage of the paper (one registered name has one module
and one data-module class, so the stages are two names):

* ``model=pcmrl``: stage 1, point cloud -> target-skeleton reconstruction
  (:class:`~skelagnostic_pcmrl.recon.aligner.PcmrlReconAligner`). ``model.stage``
  accepts only ``reconstruction`` and points to ``pcmrl_interp`` otherwise.
* ``model=pcmrl_interp``: stage 2, FOQ keyframe interpolation
  (``skelagnostic_pcmrl.interp.aligner.PcmrlInterpAligner``).
"""

from __future__ import annotations

from importlib.resources import files

from skelagnostic.plugins import (
    RegisterAligner,
    RegisterConfigPath,
    RegisterEvaluation,
    hookimpl,
)

#: The plugin's config package: ``<aligner>.yaml`` (each aligner's whole config: model
#: defaults with ``_target_``, default data, data options) and ``experiment/``.
CONFIG_PACKAGE = "skelagnostic_pcmrl.conf"


@hookimpl
def register_aligners(register: RegisterAligner) -> None:
    """Register ``model=pcmrl`` (stage 1) and ``model=pcmrl_interp`` (stage 2), by reference."""
    register(
        "pcmrl",
        "skelagnostic_pcmrl.recon.aligner:PcmrlReconAligner",
        "skelagnostic_pcmrl.recon.data:PcmrlReconDataModule",
        config=files(CONFIG_PACKAGE) / "pcmrl.yaml",
        description="PC-MRL stage 1: unsupervised point-cloud reconstruction onto a target "
        "skeleton (model=pcmrl_interp: stage 2)",
    )
    register(
        "pcmrl_interp",
        "skelagnostic_pcmrl.interp.aligner:PcmrlInterpAligner",
        "skelagnostic_pcmrl.interp.data:PcmrlInterpDataModule",
        config=files(CONFIG_PACKAGE) / "pcmrl_interp.yaml",
        description="PC-MRL stage 2: FOQ keyframe interpolation on the target skeleton",
    )


@hookimpl
def register_config_paths(register: RegisterConfigPath) -> None:
    """Ship ``experiment=pcmrl_quick``, ``pcmrl_paper`` and ``pcmrl_lafan1_cmu``."""
    register(f"pkg://{CONFIG_PACKAGE}")


@hookimpl
def register_evaluations(register: RegisterEvaluation) -> None:
    """Register ``pcmrl.reconstruction`` and ``pcmrl.interpolation`` (one default per stage)."""
    register(
        "pcmrl.reconstruction",
        "skelagnostic_pcmrl.evaluation:reconstruction_protocol",
        model="pcmrl",
        default=True,
        description="Table 2: temporal KNN and end-effector error of held-out clips "
        "retargeted onto the target, beside name-copy and primal-copy",
    )
    register(
        "pcmrl.interpolation",
        "skelagnostic_pcmrl.evaluation:interpolation_protocol",
        model="pcmrl_interp",
        default=True,
        description="Table 1: L2P, L2Q, NPSS at keyframe gaps 5/15/30 of held-out clips, "
        "beside LERP/SLERP",
    )
