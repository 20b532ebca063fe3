"""The reusable aligner contract (skelagnostic.testing) on ``model=pcmrl`` at a tiny size."""

from __future__ import annotations

from skelagnostic.plugins import PluginManager
from skelagnostic.testing import AlignerContract, ContractRun

#: PCMRL_TINY of tests/conftest.py as overrides (class attributes cannot take fixtures).
TINY = {
    "dim": 8,
    "stages": 2,
    "point_heads": 2,
    "temporal_dim": 16,
    "temporal_layers": 1,
    "temporal_heads": 2,
    "num_source_points": 64,
    "num_target_points": 128,
}


class TestPcmrlContract(AlignerContract):
    aligner = "pcmrl"
    overrides = (
        *(f"model.{k}={v}" for k, v in TINY.items()),
        "data.seconds=2",
        "data.clips_per_gait=2",
        "data.gaits=[walk]",
        "data.window=16",
    )
    steps = 2

    def plugin_manager(self) -> PluginManager:
        import skelagnostic_pcmrl.plugin as plugin

        pm = PluginManager(load_entrypoints=False)
        pm.register(plugin, "pcmrl", version="0.1.0", source="skelagnostic-pcmrl")
        return pm

    def target_skeleton(self, run: ContractRun, motion):
        """Stage 1 reconstructs onto its one trained target skeleton."""
        return run.model.target_skeleton


class TestPcmrlInterpContract(AlignerContract):
    aligner = "pcmrl_interp"
    overrides = (
        "model.dim=16",
        "model.heads=2",
        "model.layers=1",
        "model.ff_mult=2",
        "model.scheduler.steps=1",
        "data.seconds=3",
        "data.clips_per_gait=2",
        "data.window=32",
        "data.stride=16",
        "data.max_gap=10",
        "data.max_keys=8",
        "data.val_gap=8",
        "data.gaits=[walk]",
    )
    steps = 2

    def plugin_manager(self) -> PluginManager:
        import skelagnostic_pcmrl.plugin as plugin

        pm = PluginManager(load_entrypoints=False)
        pm.register(plugin, "pcmrl", version="0.1.0", source="skelagnostic-pcmrl")
        return pm
