import numpy as np
import pytest
import torch

import skelagnostic as sa
from skelagnostic import procedural


@pytest.mark.parametrize("kind", procedural.KINDS)
def test_every_kind_and_gait(kind):
    morph = "quadruped" if kind == "quadruped" else "biped"
    for gait in procedural.GAITS[morph]:
        m, info = procedural.generate(kind, gait, seconds=2.0, fps=24, seed=5)
        assert m.num_frames == 49 and m.fps == 24 and m.units == "cm"
        assert m.skeleton.morphology == morph
        assert "other" not in m.skeleton.body_groups
        pos = m.global_positions()
        assert torch.isfinite(pos).all()
        # the character stays on the ground: lowest joint near y=0, no joint far below
        assert pos[..., 1].min() > -5.0 and pos[..., 1].min() < 12.0
        assert info["synthetic"] and info["phase"].shape == (49,)


@pytest.mark.parametrize(
    ("kind", "gait"),
    [("biped22", "walk"), ("biped17", "run"), ("quadruped", "trot"), ("quadruped", "gallop")],
)
def test_known_frequency_is_in_the_motion(kind, gait):
    m, info = procedural.generate(kind, gait, seconds=8.0, fps=60, seed=11)
    # dominant frequency of a foot's forward position relative to the root (in the facing
    # frame), found independently with an FFT
    sk = m.skeleton
    foot = next(j for j in sk.end_effectors() if sk.body_groups[j] == "left_leg")
    rel = m.global_positions()[:, foot] - m.root_positions
    local = sa.core.quaternion.rotate(sa.core.quaternion.inv(m.facing()), rel)
    signal = local[:, 2].numpy()
    signal = signal - signal.mean()
    spectrum = np.abs(np.fft.rfft(signal * np.hanning(len(signal))))
    freqs = np.fft.rfftfreq(len(signal), d=1 / 60)
    assert freqs[spectrum.argmax()] == pytest.approx(info["frequency"], abs=1.5 / 8.0)
    # the phase advances by frequency / fps each frame
    unwrapped = np.unwrap(info["phase"].numpy() * 2 * np.pi) / (2 * np.pi)
    np.testing.assert_allclose(np.diff(unwrapped), info["frequency"] / 60, atol=1e-5)


def test_deterministic_and_seed_dependent():
    a, _ = procedural.generate("biped31", "walk", seconds=1, seed=4)
    b, _ = procedural.generate("biped31", "walk", seconds=1, seed=4)
    c, _ = procedural.generate("biped31", "walk", seconds=1, seed=5)
    torch.testing.assert_close(a.rotations, b.rotations)
    assert not torch.allclose(a.rotations, c.rotations)


def test_explicit_parameters_and_noise():
    m, info = procedural.generate(
        "biped22", "walk", seconds=3, fps=30, frequency=1.25, speed=100, scale=1.0
    )
    assert info["frequency"] == 1.25 and info["speed"] == 100
    assert m.root_positions[-1, 2] - m.root_positions[0, 2] == pytest.approx(300, rel=1e-6)
    noisy, _ = procedural.generate(
        "biped22", "walk", seconds=3, fps=30, frequency=1.25, speed=100, scale=1.0, noise=2.0
    )
    diff = (noisy.rotations - m.rotations).abs().amax(dim=(0, 2))
    assert diff[0] < 1e-12 and diff[1:].max() > 1e-3  # the root is clean, limbs are noisy


def test_errors():
    with pytest.raises(sa.SkelagnosticError, match="unknown procedural skeleton 'octopus'"):
        procedural.generate("octopus")
    with pytest.raises(sa.SkelagnosticError, match="unknown gait 'gallop' for a biped"):
        procedural.generate("biped22", "gallop")
    with pytest.raises(sa.SkelagnosticError, match="positive"):
        procedural.generate("biped22", "walk", seconds=0)


def test_dataset_covers_kinds_and_gaits():
    clips = procedural.dataset(kinds=("biped22", "quadruped"), clips_per_gait=1, seconds=1)
    assert [(i["kind"], i["gait"]) for _, i in clips] == [
        ("biped22", "walk"),
        ("biped22", "run"),
        ("biped22", "idle"),
        ("quadruped", "walk"),
        ("quadruped", "trot"),
        ("quadruped", "gallop"),
        ("quadruped", "idle"),
    ]
    assert len({i["seed"] for _, i in clips}) == len(clips)
