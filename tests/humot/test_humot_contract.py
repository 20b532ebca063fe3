"""The reusable aligner contract (skelagnostic.testing) on ``model=humot`` at a tiny size."""

from __future__ import annotations

from skelagnostic.plugins import PluginManager
from skelagnostic.testing import AlignerContract


class TestHumotContract(AlignerContract):
    aligner = "humot"
    overrides = (
        "model.dim=16",
        "model.latent=8",
        "model.blocks=1",
        "model.heads=2",
        "model.kernel_size=3",
        "data.seconds=1.5",
        "data.clips_per_gait=2",
        "data.kinds=[biped22,biped17]",
        "data.gaits=[walk]",
    )
    steps = 2

    def plugin_manager(self) -> PluginManager:
        import skelagnostic_humot.plugin as plugin

        pm = PluginManager(load_entrypoints=False)
        pm.register(plugin, "humot", version="0.1.0", source="skelagnostic-humot")
        return pm
