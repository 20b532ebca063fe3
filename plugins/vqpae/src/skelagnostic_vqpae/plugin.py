"""WalkTheDog VQ-PAE: a phase manifold shared across characters (human, dog, ...).

Hook implementations of the ``vqpae`` plugin (entry point ``skelagnostic: vqpae``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from skelagnostic.plugins import hookimpl, read_model_config

#: The plugin's Hydra config package: ``model/`` (the aligners' defaults, with
#: ``_target_``), ``experiment/``, ``data/``.
CONFIG_PACKAGE = "skelagnostic_vqpae.conf"

#: ``data/vqpae``, the default data of ``skelagnostic fit model=vqpae`` (no ``data=``):
#: procedural humans (LaFAN1-like, 22 joints) and quadrupeds (a dog, 21 joints), one dataset
#: each, every gait but idle, 4 clips of 8 s per gait (one clip in five held out).
DEFAULT_DATA: dict[str, Any] = {
    "source": "procedural",
    "kinds": ["biped22", "quadruped"],
    "gaits": None,
    "clips_per_gait": 4,
    "seconds": 8.0,
    "seed": 0,
}

#: Data-module keys of the authors' preprocessing (supplement 2.2), whatever the data:
#: 60 fps, 1 s windows (61 frames) centred on every frame.
DATA_OPTIONS: dict[str, Any] = {"fps": 60, "window_seconds": 1.0, "stride": 1}


@hookimpl
def register_aligners(register: Callable[..., Any]) -> None:
    """Register ``model=vqpae``: :class:`~skelagnostic_vqpae.aligner.VqpaeAligner`."""
    from skelagnostic_vqpae.aligner import VqpaeAligner
    from skelagnostic_vqpae.data import VqpaeDataModule

    register(
        "vqpae",
        VqpaeAligner,
        VqpaeDataModule,
        config=read_model_config(CONFIG_PACKAGE, "vqpae"),
        description="WalkTheDog VQ-PAE: phase manifold shared across characters (human, dog, ...)",
        data=DEFAULT_DATA,
        data_options=DATA_OPTIONS,
    )


@hookimpl
def register_datasets(register: Callable[..., Any]) -> None:
    """``data.source=human_dog`` and ``data.source=styles`` (one dataset per part)."""
    from skelagnostic_vqpae.data import human_dog_source, styles_source

    register("human_dog", human_dog_source, "a human dataset preset + the MANN dog (VQ-PAE)")
    register("styles", styles_source, "one dataset per motion style of a BVH directory (VQ-PAE)")


@hookimpl
def register_config_paths(register: Callable[..., Any]) -> None:
    """Ship ``experiment=vqpae_human_dog`` and ``experiment=vqpae_stylized``."""
    register(f"pkg://{CONFIG_PACKAGE}")


@hookimpl
def register_evaluations(register: Callable[..., Any]) -> None:
    """Register ``vqpae.manifold`` (the default of ``model=vqpae``) and ``vqpae.transfer``."""
    from skelagnostic_vqpae.protocols.manifold import manifold_protocol
    from skelagnostic_vqpae.protocols.transfer import transfer_protocol

    register(
        "vqpae.manifold",
        manifold_protocol,
        model="vqpae",
        default=True,
        description="shared codes (vs chance), phase linearity and average-pose error "
        "(vs the mean pose, all and locomotion frames) of held-out clips; Tables 1 and 2 "
        "per character; phase and frequency on held-out procedural gaits",
    )
    register(
        "vqpae.transfer",
        transfer_protocol,
        model="vqpae",
        description="held-out clips of the first character re-enacted by the second "
        "(frequency-scaled motion matching): gait-frequency error and ratio, foot-contact "
        "rhythm against the source's, smoothness vs unscaled motion matching",
    )


@hookimpl
def register_checkpoint_readers(register: Callable[..., Any]) -> None:
    """``ckpt=authors:<dir>``: a run directory of the WalkTheDog authors' ``train_vq.py``."""
    from skelagnostic_vqpae.authors import load_run

    register(
        "authors",
        load_run,
        model="vqpae",
        description="a run directory of the WalkTheDog authors' train_vq.py "
        "(skelagnostic_vqpae.authors.load_run)",
    )
