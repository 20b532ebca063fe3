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

from collections.abc import Callable
from typing import Any

from skelagnostic.plugins import hookimpl, read_model_config

#: The plugin's Hydra config package: ``model/`` (the aligners' defaults, with
#: ``_target_``), ``experiment/``.
CONFIG_PACKAGE = "skelagnostic_pcmrl.conf"

#: Default data of ``model=pcmrl`` (``skelagnostic fit model=pcmrl`` with no ``data=``):
#: procedural biped22 clips as the source ...
DEFAULT_DATA: dict[str, Any] = {
    "source": "procedural",
    "kinds": ["biped22"],
    "gaits": ["walk", "run"],
    "clips_per_gait": 3,
    "seconds": 6.0,
    "seed": 0,
}
#: ... and data-module keys for any data: the target skeleton (procedural biped31,
#: unpaired: no biped31 motion is ever seen), 32-frame windows.
DATA_OPTIONS: dict[str, Any] = {
    "target": "biped31",
    "target_units": None,
    "source_units": None,
    "window": 32,
    "stride": 8,
    "batch_size": 4,
}


@hookimpl
def register_aligners(register: Callable[..., Any]) -> None:
    """Register ``model=pcmrl`` (stage 1) and ``model=pcmrl_interp`` (stage 2)."""
    from skelagnostic_pcmrl.recon.aligner import PcmrlReconAligner
    from skelagnostic_pcmrl.recon.data import PcmrlReconDataModule

    register(
        "pcmrl",
        PcmrlReconAligner,
        PcmrlReconDataModule,
        config=read_model_config(CONFIG_PACKAGE, "pcmrl"),
        description="PC-MRL stage 1: unsupervised point-cloud reconstruction onto a target "
        "skeleton (model=pcmrl_interp: stage 2)",
        data=DEFAULT_DATA,
        data_options=DATA_OPTIONS,
    )
    from skelagnostic_pcmrl.interp.aligner import PcmrlInterpAligner
    from skelagnostic_pcmrl.interp.data import PcmrlInterpDataModule
    from skelagnostic_pcmrl.interp.defaults import INTERP_DATA_DEFAULTS, INTERP_DATA_OPTIONS

    register(
        "pcmrl_interp",
        PcmrlInterpAligner,
        PcmrlInterpDataModule,
        config=read_model_config(CONFIG_PACKAGE, "pcmrl_interp"),
        description="PC-MRL stage 2: FOQ keyframe interpolation on the target skeleton",
        data=INTERP_DATA_DEFAULTS,
        data_options=INTERP_DATA_OPTIONS,
    )


@hookimpl
def register_config_paths(register: Callable[..., Any]) -> None:
    """Ship ``experiment=pcmrl_quick``, ``pcmrl_paper`` and ``pcmrl_lafan1_cmu``."""
    register(f"pkg://{CONFIG_PACKAGE}")


@hookimpl
def register_evaluations(register: Callable[..., Any]) -> None:
    """Register ``pcmrl.reconstruction`` and ``pcmrl.interpolation`` (one default per stage)."""
    from skelagnostic_pcmrl.evaluation import interpolation_protocol, reconstruction_protocol

    register(
        "pcmrl.reconstruction",
        reconstruction_protocol,
        model="pcmrl",
        default=True,
        description="Table 2: temporal KNN and end-effector error of held-out clips "
        "retargeted onto the target, beside name-copy and primal-copy",
    )
    register(
        "pcmrl.interpolation",
        interpolation_protocol,
        model="pcmrl_interp",
        default=True,
        description="Table 1: L2P, L2Q, NPSS at keyframe gaps 5/15/30 of held-out clips, "
        "beside LERP/SLERP",
    )
