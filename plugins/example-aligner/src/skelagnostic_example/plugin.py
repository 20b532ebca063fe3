"""Example third-party aligner: a per-joint GRU autoencoder (the tutorial's package).

Hook implementations of the example plugin (the ``skelagnostic`` entry point).
"""

from __future__ import annotations

from functools import partial
from importlib.resources import files
from typing import Any

from skelagnostic.plugins import (
    RegisterAligner,
    RegisterConfigPath,
    RegisterEvaluation,
    hookimpl,
)

#: The plugin's config package: ``example.yaml`` (the aligner's config: its defaults, with
#: ``_target_``) and ``experiment/``.
CONFIG_PACKAGE = "skelagnostic_example.conf"


@hookimpl
def register_aligners(register: RegisterAligner) -> None:
    """Register ``model=example`` by reference: the classes are imported when first used.

    So ``skelagnostic plugins`` and ``--help`` import neither them nor Lightning.
    """
    register(
        "example",
        "skelagnostic_example.aligner:ExampleAligner",
        "skelagnostic_example.aligner:ExampleDataModule",
        config=files(CONFIG_PACKAGE) / "example.yaml",
        description="per-joint GRU autoencoder over root-local positions (tutorial example)",
    )


@hookimpl
def register_config_paths(register: RegisterConfigPath) -> None:
    """Ship ``experiment=example_quick``."""
    register(f"pkg://{CONFIG_PACKAGE}")


def reconstruction(aligner: Any, held_out: Any, out_dir: Any) -> Any:
    """Encode-decode pose error on held-out clips, beside the mean-pose baselines."""
    from skelagnostic.evaluation import RECONSTRUCTION_METRICS, Evaluation, reconstruction_rows

    def reconstruct(motion: Any) -> Any:
        return aligner.decode(aligner.encode(motion), motion.skeleton)

    rows = reconstruction_rows(held_out.clips, reconstruct)
    outputs = {str(c.name): partial(reconstruct, c) for c in held_out.clips}
    return Evaluation(dict(RECONSTRUCTION_METRICS), rows, outputs=outputs)


@hookimpl
def register_evaluations(register: RegisterEvaluation) -> None:
    """Register ``protocol=example.reconstruction`` (the default of ``model=example``)."""
    register("example.reconstruction", reconstruction, model="example", default=True)
