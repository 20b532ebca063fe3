"""The reusable aligner contract (skelagnostic.testing) on ``model=vqpae`` at a tiny size."""

from __future__ import annotations

from skelagnostic.plugins import PluginManager
from skelagnostic.testing import AlignerContract


class TestVqpaeContract(AlignerContract):
    aligner = "vqpae"
    overrides = (
        "model.num_codes=8",
        "model.kernel_size=7",
        "data.fps=20",
        "data.stride=4",
        "data.seconds=3",
        "data.clips_per_gait=2",
        "data.gaits=[walk]",
    )
    steps = 2

    def plugin_manager(self) -> PluginManager:
        from skelagnostic_vqpae import plugin

        pm = PluginManager(load_entrypoints=False)
        pm.register(plugin, "vqpae", source="tests")
        return pm
