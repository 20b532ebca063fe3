"""Hook implementations of the HuMoT plugin (entry point ``humot`` in group ``skelagnostic``)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from skelagnostic.plugins import hookimpl

#: The paper's hyper-parameters (App. A.3-A.5): the ``model/humot`` config.
DEFAULT_CONFIG: dict[str, Any] = {
    "dim": 128,
    "latent": 128,
    "blocks": 4,
    "heads": 8,
    "kernel_size": 5,
    "mlp_ratio": 4.0,
    "layer_scale": 1.0,
    "lambda_blc": 0.5,
    "subsampling": True,
    "p_major": 0.1,
    "p_other": 0.5,
    "lr_min": 1e-5,
    "lr_max": 1e-4,
    "lr_period_epochs": 10.0,
    "betas": [0.9, 0.999],
    "chunk": 30,
}


@hookimpl
def register_aligners(register: Callable[..., Any]) -> None:
    """Register ``model=humot``."""
    from skelagnostic_humot.aligner import HumotAligner
    from skelagnostic_humot.data import HumotDataModule

    register(
        "humot",
        HumotAligner,
        HumotDataModule,
        config=DEFAULT_CONFIG,
        description="HuMoT: topology-agnostic XCiT autoencoder for human retargeting",
    )


@hookimpl
def register_config_paths(register: Callable[..., Any]) -> None:
    """Ship ``experiment=humot_quick``."""
    register("pkg://skelagnostic_humot.conf")
