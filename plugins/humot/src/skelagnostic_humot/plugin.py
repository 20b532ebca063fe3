"""HuMoT: topology-agnostic transformer autoencoder, retargeting between human skeletons.

Hook implementations of the HuMoT plugin (entry point ``humot`` in group ``skelagnostic``).
"""

from __future__ import annotations

from importlib.resources import files

from skelagnostic.plugins import (
    RegisterAligner,
    RegisterConfigPath,
    RegisterDataset,
    RegisterEvaluation,
    hookimpl,
)

#: The plugin's config package: ``<aligner>.yaml`` (each aligner's whole config: model
#: defaults with ``_target_``, default data, data options) and ``experiment/``.
CONFIG_PACKAGE = "skelagnostic_humot.conf"


@hookimpl
def register_aligners(register: RegisterAligner) -> None:
    """Register ``model=humot`` (by reference: imported when first used)."""
    register(
        "humot",
        "skelagnostic_humot.aligner:HumotAligner",
        "skelagnostic_humot.data:HumotDataModule",
        config=files(CONFIG_PACKAGE) / "humot.yaml",
        description="HuMoT: topology-agnostic XCiT autoencoder for human retargeting",
    )


@hookimpl
def register_datasets(register: RegisterDataset) -> None:
    """``data.source=humot_mix``: a real human corpus plus procedural humans."""
    register(
        "humot_mix",
        "skelagnostic_humot.data:corpus_and_procedural_source",
        "a human dataset preset (with its test split) + procedural humans of other "
        "topologies (HuMoT)",
    )


@hookimpl
def register_config_paths(register: RegisterConfigPath) -> None:
    """Ship ``data=humot_mix`` and the ``experiment=humot_*`` presets."""
    register(f"pkg://{CONFIG_PACKAGE}")


@hookimpl
def register_evaluations(register: RegisterEvaluation) -> None:
    """Register ``humot.reconstruction`` (the default), ``humot.retarget``, ``humot.ablations``."""
    register(
        "humot.reconstruction",
        "skelagnostic_humot.evaluation.reconstruction:reconstruction_protocol",
        model="humot",
        default=True,
        description="Table 2 reconstruction of held-out clips beside mean-pose baselines; "
        "denoising and joint-upsampling curves (Fig. 8, 9)",
    )
    register(
        "humot.retarget",
        "skelagnostic_humot.evaluation.retarget:retarget_protocol",
        model="humot",
        description="cycle retargeting error of held-out clips via another rig beside "
        "name-copy and primal-copy baselines; paired procedural retargeting",
    )
    register(
        "humot.ablations",
        "skelagnostic_humot.ablations:ablation_protocol",
        model="humot",
        description="the paper's ablations (no joint subsampling, no bone-length loss) and the "
        "full model retrained at an equal budget (+protocol_options.steps=N, default 200) on the "
        "run's training clips, measured on held-out clips beside the checkpoint and baselines",
    )
