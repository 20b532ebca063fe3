"""WalkTheDog VQ-PAE: a phase manifold shared across characters (human, dog, ...).

Hook implementations of the ``vqpae`` plugin (entry point ``skelagnostic: vqpae``).
"""

from __future__ import annotations

from importlib.resources import files

from skelagnostic.plugins import (
    RegisterAligner,
    RegisterCheckpointReader,
    RegisterConfigPath,
    RegisterDataset,
    RegisterEvaluation,
    hookimpl,
)

#: The plugin's config package: ``<aligner>.yaml`` (each aligner's whole config: model
#: defaults with ``_target_``, default data, data options), ``experiment/``, ``data/``.
CONFIG_PACKAGE = "skelagnostic_vqpae.conf"


@hookimpl
def register_aligners(register: RegisterAligner) -> None:
    """Register ``model=vqpae`` (by reference: imported when first used)."""
    register(
        "vqpae",
        "skelagnostic_vqpae.aligner:VqpaeAligner",
        "skelagnostic_vqpae.data:VqpaeDataModule",
        config=files(CONFIG_PACKAGE) / "vqpae.yaml",
        description="WalkTheDog VQ-PAE: phase manifold shared across characters (human, dog, ...)",
    )


@hookimpl
def register_datasets(register: RegisterDataset) -> None:
    """``data.source=human_dog`` and ``data.source=styles`` (one dataset per part)."""
    register(
        "human_dog",
        "skelagnostic_vqpae.data:human_dog_source",
        "a human dataset preset + the MANN dog (VQ-PAE)",
    )
    register(
        "styles",
        "skelagnostic_vqpae.data:styles_source",
        "one dataset per motion style of a BVH directory (VQ-PAE)",
    )


@hookimpl
def register_config_paths(register: RegisterConfigPath) -> None:
    """Ship ``experiment=vqpae_human_dog`` and ``experiment=vqpae_stylized``."""
    register(f"pkg://{CONFIG_PACKAGE}")


@hookimpl
def register_evaluations(register: RegisterEvaluation) -> None:
    """Register ``vqpae.manifold`` (the default of ``model=vqpae``) and ``vqpae.transfer``."""
    register(
        "vqpae.manifold",
        "skelagnostic_vqpae.protocols.manifold:manifold_protocol",
        model="vqpae",
        default=True,
        description="shared codes (vs chance), phase linearity and average-pose error "
        "(vs the mean pose, all and locomotion frames) of held-out clips; Tables 1 and 2 "
        "per character; phase and frequency on held-out procedural gaits",
    )
    register(
        "vqpae.transfer",
        "skelagnostic_vqpae.protocols.transfer:transfer_protocol",
        model="vqpae",
        description="held-out clips of the first character re-enacted by the second "
        "(frequency-scaled motion matching): gait-frequency error and ratio, foot-contact "
        "rhythm against the source's, smoothness vs unscaled motion matching",
    )


@hookimpl
def register_checkpoint_readers(register: RegisterCheckpointReader) -> None:
    """``ckpt=authors:<dir>``: a run directory of the WalkTheDog authors' ``train_vq.py``."""
    register(
        "authors",
        "skelagnostic_vqpae.authors:load_run",
        model="vqpae",
        description="a run directory of the WalkTheDog authors' train_vq.py "
        "(skelagnostic_vqpae.authors.load_run)",
    )
