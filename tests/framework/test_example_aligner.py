"""The example third-party aligner genuinely trains and retargets across topologies."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
import torch

import skelagnostic as sa
import skelagnostic.plugins as plugins
from skelagnostic.aligners import Latent
from skelagnostic.plugins import PluginManager
from skelagnostic.testing import AlignerContract

EXAMPLE_SRC = Path(__file__).resolve().parents[2] / "plugins" / "example-aligner" / "src"


@pytest.fixture
def model(example_plugin: Path):
    torch.manual_seed(0)
    return plugins.load_aligner("example", hidden=32, latent=8)


def test_training_lowers_the_loss(model, tmp_path: Path) -> None:
    from skelagnostic_example import ExampleDataModule

    from skelagnostic.data import ProceduralSource

    dm = ExampleDataModule(
        ProceduralSource(gaits=["walk"], clips_per_gait=1, seconds=2.0),
        window=16,
        stride=8,
        batch_size=8,
        cache_dir=tmp_path,
    )
    dm.setup()
    batch, _, _ = next(iter(dm.train_dataloader()))
    model.train()
    opt = model.configure_optimizers()
    losses = []
    for _ in range(60):
        loss = torch.stack([model._loss(b) for b in batch.values()]).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(float(loss.detach()))
    assert losses[-1] < 0.3 * losses[0]


def test_retarget_biped_to_quadruped(model) -> None:
    walk, _ = sa.procedural.generate("biped22", "walk", seconds=1.0, fps=30, seed=0)
    dog, _ = sa.procedural.generate("quadruped", "walk", seconds=1.0, fps=30, seed=0)
    out = model.retarget(walk, dog.skeleton)
    assert out.skeleton is dog.skeleton and out.num_frames == walk.num_frames
    assert out.fps == walk.fps and torch.isfinite(out.global_positions()).all()
    # the root follows the source path, scaled by the height ratio (ground plane)
    ratio = dog.skeleton.height() / walk.skeleton.height()
    torch.testing.assert_close(
        out.root_positions[:, [0, 2]].float(),
        walk.root_positions[:, [0, 2]].float() * ratio,
        atol=1e-3,
        rtol=1e-4,
    )


def test_decode_without_extras_stays_at_origin(model) -> None:
    dog, _ = sa.procedural.generate("quadruped", "trot", seconds=0.5, fps=30, seed=1)
    out = model.decode(Latent(torch.zeros(5, 8), fps=30.0), dog.skeleton)
    assert out.num_frames == 5
    assert float(out.root_positions[:, [0, 2]].abs().max()) < 1e-6


# pytest deprecated the contract's class-scoped fixture as an instance method (issue 48, item 9)
@pytest.mark.filterwarnings("error::pytest.PytestRemovedIn10Warning")
class TestExampleContract(AlignerContract):
    """The reusable third-party contract (skelagnostic.testing) on the example aligner."""

    aligner = "example"
    overrides = ("model.hidden=16", "model.latent=8", "data.seconds=2", "data.clips_per_gait=1")

    def plugin_manager(self) -> PluginManager:
        if str(EXAMPLE_SRC) not in sys.path:
            sys.path.insert(0, str(EXAMPLE_SRC))
        import skelagnostic_example.plugin as plugin

        pm = PluginManager(load_entrypoints=False)
        pm.register(plugin, "example", version="0.1.0", source="skelagnostic-example-aligner")
        return pm
