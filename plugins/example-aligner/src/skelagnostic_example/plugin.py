"""Example third-party aligner: a per-joint GRU autoencoder (the tutorial's package).

Hook implementations of the example plugin (the ``skelagnostic`` entry point).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from skelagnostic.plugins import hookimpl, read_model_config

#: The plugin's Hydra config package: ``model/example.yaml`` (the aligner's defaults,
#: with ``_target_``) and ``experiment/``.
CONFIG_PACKAGE = "skelagnostic_example.conf"


@hookimpl
def register_aligners(register: Callable[..., Any]) -> None:
    """Register ``model=example``."""
    from skelagnostic_example.aligner import ExampleAligner, ExampleDataModule

    register(
        "example",
        ExampleAligner,
        ExampleDataModule,
        config=read_model_config(CONFIG_PACKAGE, "example"),
        description="per-joint GRU autoencoder over root-local positions (tutorial example)",
    )


@hookimpl
def register_config_paths(register: Callable[..., Any]) -> None:
    """Ship ``experiment=example_quick``."""
    register(f"pkg://{CONFIG_PACKAGE}")


def reconstruction(aligner: Any, held_out: Any, out_dir: Any) -> Any:
    """Encode-decode pose error on held-out clips, beside the mean-pose baselines."""
    from skelagnostic.evaluation import RECONSTRUCTION_METRICS, Evaluation, reconstruction_rows

    rows = reconstruction_rows(
        held_out.clips, lambda m: aligner.decode(aligner.encode(m), m.skeleton)
    )
    return Evaluation(dict(RECONSTRUCTION_METRICS), rows)


@hookimpl
def register_evaluations(register: Callable[..., Any]) -> None:
    """Register ``protocol=example.reconstruction`` (the default of ``model=example``)."""
    register("example.reconstruction", reconstruction, model="example", default=True)
