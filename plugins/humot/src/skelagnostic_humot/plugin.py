"""HuMoT: topology-agnostic transformer autoencoder, retargeting between human skeletons.

Hook implementations of the HuMoT plugin (entry point ``humot`` in group ``skelagnostic``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from skelagnostic.plugins import hookimpl, read_model_config

#: The plugin's Hydra config package: ``model/`` (the aligners' defaults, with
#: ``_target_``), ``experiment/``.
CONFIG_PACKAGE = "skelagnostic_humot.conf"

#: ``data/humot``, the default data of ``skelagnostic fit model=humot`` (no ``data=``):
#: procedural humans of three topologies (22, 31 and 17 joints), walking and running, 4 clips
#: of 2 s per topology (one held out for validation). Sized for the CPU budget of the issue
#: (under 5 minutes on 2 cores): the trainer's default 10 epochs are 10 steps of the
#: paper-size network (one batch of 18 chunks per topology; a step of 64 chunks costs
#: ~0.4 TFLOP). Ten steps show that the pipeline runs end to end (checkpoint, metrics,
#: rendered retargeting), not a trained model: ``experiment=humot_quick`` is the CPU
#: configuration that learns (docs/reports/humot.md).
DEFAULT_DATA: dict[str, Any] = {
    "source": "procedural",
    "kinds": ["biped22", "biped31", "biped17"],
    "gaits": ["walk", "run"],
    "clips_per_gait": 2,
    "seconds": 2.0,
    "seed": 0,
}

#: Data-module keys of the paper's preprocessing (Sec. 3.4.1), whatever the data:
#: 30 Hz, 1 s chunks overlapping by 24 frames.
DATA_OPTIONS: dict[str, Any] = {"fps": 30, "window": 30, "stride": 6}


@hookimpl
def register_aligners(register: Callable[..., Any]) -> None:
    """Register ``model=humot``."""
    from skelagnostic_humot.aligner import HumotAligner
    from skelagnostic_humot.data import HumotDataModule

    register(
        "humot",
        HumotAligner,
        HumotDataModule,
        config=read_model_config(CONFIG_PACKAGE, "humot"),
        description="HuMoT: topology-agnostic XCiT autoencoder for human retargeting",
        data=DEFAULT_DATA,
        data_options=DATA_OPTIONS,
    )


@hookimpl
def register_datasets(register: Callable[..., Any]) -> None:
    """``data.source=humot_mix``: a real human corpus plus procedural humans."""
    from skelagnostic_humot.data import corpus_and_procedural_source

    register(
        "humot_mix",
        corpus_and_procedural_source,
        "a human dataset preset (with its test split) + procedural humans of other "
        "topologies (HuMoT)",
    )


@hookimpl
def register_config_paths(register: Callable[..., Any]) -> None:
    """Ship ``data=humot_mix`` and the ``experiment=humot_*`` presets."""
    register(f"pkg://{CONFIG_PACKAGE}")


@hookimpl
def register_evaluations(register: Callable[..., Any]) -> None:
    """Register ``humot.reconstruction`` (the default), ``humot.retarget``, ``humot.ablations``."""
    from skelagnostic_humot.ablations import ablation_protocol
    from skelagnostic_humot.evaluation.reconstruction import reconstruction_protocol
    from skelagnostic_humot.evaluation.retarget import retarget_protocol

    register(
        "humot.reconstruction",
        reconstruction_protocol,
        model="humot",
        default=True,
        description="Table 2 reconstruction of held-out clips beside mean-pose baselines; "
        "denoising and joint-upsampling curves (Fig. 8, 9)",
    )
    register(
        "humot.retarget",
        retarget_protocol,
        model="humot",
        description="cycle retargeting error of held-out clips via another rig beside "
        "name-copy and primal-copy baselines; paired procedural retargeting",
    )
    register(
        "humot.ablations",
        ablation_protocol,
        model="humot",
        description="the paper's ablations (no joint subsampling, no bone-length loss) and the "
        "full model retrained at an equal budget (+protocol_options.steps=N, default 200) on the "
        "run's training clips, measured on held-out clips beside the checkpoint and baselines",
    )
