"""PC-MRL interpolation model: baselines, keyframe reproduction, training and reloading."""

from __future__ import annotations

import itertools
import math
from importlib.resources import files
from pathlib import Path

import lightning as L
import pytest
import torch
from skelagnostic_pcmrl.interp.aligner import PcmrlInterpAligner
from skelagnostic_pcmrl.interp.clips import gap_keys, random_keys, regular_keys
from skelagnostic_pcmrl.interp.data import PcmrlInterpDataModule
from skelagnostic_pcmrl.interp.keyframes import key_brackets, lerp_keys, slerp_keys
from skelagnostic_pcmrl.interp.rpa import bone_tails

from skelagnostic import Motion, procedural
from skelagnostic.baselines import lerp_slerp
from skelagnostic.core import quaternion as Q
from skelagnostic.errors import MotionError, SkelagnosticError
from skelagnostic.plugins import read_aligner_config

TINY = {"dim": 16, "heads": 2, "layers": 1, "ff_mult": 2, "max_relative": 16}


def _adamw(lr: float) -> dict:
    return {"_target_": "torch.optim.AdamW", "lr": lr, "weight_decay": 0.0}


def _warmup(steps: int) -> dict:
    return {"_target_": "skelagnostic.aligners.optim.linear_warmup", "steps": steps}


def _motion(seconds: float = 2.0, fps: float = 30.0, seed: int = 0) -> Motion:
    motion, _ = procedural.generate("biped31", "walk", seconds=seconds, fps=fps, seed=seed)
    return motion.convert_units("m")


def _tiny(residual: bool = False, window: int = 32, **options: object) -> PcmrlInterpAligner:
    torch.manual_seed(0)
    skel = procedural.skeleton("biped31").scaled(0.01)
    return PcmrlInterpAligner(
        **TINY, residual=residual, skeleton=skel.to_dict(), fps=30.0, window=window, **options
    ).eval()


def test_paper_defaults() -> None:
    config = read_aligner_config(files("skelagnostic_pcmrl.conf") / "pcmrl_interp.yaml")["model"]
    assert config["dim"] == 512 and config["heads"] == 8
    assert config["layers"] == 6 and config["optimizer"]["lr"] == 1e-4
    assert config["scheduler"]["steps"] == 10000 and config["w_fk"] == 0.1
    assert config["w_quat"] == 0.1 and config["residual"] is False


def test_key_brackets_by_hand() -> None:
    keys = torch.tensor([[True, False, False, False, True, False, True]])
    prev, nxt, w = key_brackets(keys)
    assert prev.tolist() == [[0, 0, 0, 0, 4, 4, 6]]
    assert nxt.tolist() == [[0, 4, 4, 4, 4, 6, 6]]
    assert w[0].tolist() == pytest.approx([0, 0.25, 0.5, 0.75, 0, 0.5, 0])
    x = torch.tensor([[0.0, 9, 9, 9, 8.0, 9, 2.0]])[..., None]
    assert lerp_keys(x, keys)[0, :, 0].tolist() == pytest.approx([0, 2, 4, 6, 8, 5, 2])


def test_slerp_keys_by_hand() -> None:
    keys = torch.tensor([[True, False, True]])
    q = torch.zeros(1, 3, 1, 4)
    q[0, 0, 0] = torch.tensor([1.0, 0, 0, 0])
    q[0, 1, 0] = torch.tensor([0.0, 1, 0, 0])  # ignored (not a key)
    q[0, 2, 0] = torch.tensor([math.cos(math.pi / 4), 0, 0, math.sin(math.pi / 4)])  # 90 deg z
    mid = slerp_keys(q, keys)[0, 1, 0]
    assert mid.tolist() == pytest.approx(
        [math.cos(math.pi / 8), 0, 0, math.sin(math.pi / 8)], abs=1e-6
    )


def test_lerp_slerp_baseline_by_hand() -> None:
    motion = _motion(seconds=0.2)[:3]
    rot = motion.rotations.clone()
    rot[1] = torch.tensor([0.0, 0.0, 1.0, 0.0])  # garbage on the in-between frame
    root = motion.root_positions.clone()
    root[1] = torch.tensor([50.0, 50.0, 50.0])
    noisy = Motion(motion.skeleton, rot, root, motion.fps)
    out = lerp_slerp(noisy, [0, 2])
    assert torch.allclose(out.root_positions[1], (root[0] + root[2]) / 2)
    expected = Q.slerp(rot[0], rot[2], 0.5)
    dots = (out.rotations[1] * expected).sum(-1).abs()
    assert torch.allclose(dots, torch.ones_like(dots), atol=1e-6)
    assert torch.allclose(out.rotations[[0, 2]], rot[[0, 2]])


def test_random_and_gap_keys() -> None:
    import random

    rng = random.Random(0)
    for _ in range(50):
        mask = random_keys(128, 5, 36, rng)
        assert mask[0] and mask[-1] and 5 <= int(mask.sum()) <= 36
    assert gap_keys(11, 5).nonzero().squeeze(1).tolist() == [0, 5, 10]
    assert gap_keys(12, 5).nonzero().squeeze(1).tolist() == [0, 5, 10, 11]


def test_regular_keys_have_one_gap_per_window_and_a_random_phase() -> None:
    import random

    rng = random.Random(1)
    gaps, phases = set(), set()
    for _ in range(200):
        mask = regular_keys(128, 5, 30, rng)
        frames = mask.nonzero().squeeze(1).tolist()
        assert frames[0] == 0 and frames[-1] == 127
        inner = frames[1:-1]
        steps = {b - a for a, b in itertools.pairwise(inner)}
        assert len(steps) == 1  # one gap g between the inner keys
        gap = steps.pop()
        assert 5 <= gap <= 30 and frames[1] <= gap  # first inner key within one gap
        assert 127 - frames[-2] <= gap
        gaps.add(gap)
        phases.add(frames[1] % gap)
    assert len(gaps) > 15 and len(phases) > 10  # both drawn, not fixed
    assert regular_keys(10, 3, 3, random.Random(0)).sum() >= 4


def test_key_mode_is_checked_and_used_by_the_training_windows() -> None:
    with pytest.raises(SkelagnosticError, match="key_mode"):
        PcmrlInterpDataModule(key_mode="every")
    with pytest.raises(SkelagnosticError, match="min_gap"):
        PcmrlInterpDataModule(key_mode="regular", min_gap=10, max_gap=5)
    dm = PcmrlInterpDataModule(
        fps=30,
        window=64,
        batch_size=4,
        samples_per_epoch=16,
        key_mode="regular",
        min_gap=7,
        max_gap=7,
        rpa_prob=0.0,
    )
    dm.setup("fit")
    for item in (dm.train_set[i] for i in range(16)):
        frames = item["keys"].nonzero().squeeze(1).tolist()
        inner = frames[1:-1]
        assert all(b - a == 7 for a, b in itertools.pairwise(inner))


@pytest.mark.parametrize(
    ("residual", "interm", "space"),
    [
        (False, "zero", "foq"),
        (True, "zero", "foq"),
        (False, "lerp", "foq"),
        (True, "lerp", "foq"),
        (True, "zero", "local"),
    ],
)
def test_interpolate_reproduces_keyframes(residual: bool, interm: str, space: str) -> None:
    model = _tiny(residual, interm_tokens=interm, residual_space=space)
    motion = _motion(seconds=3.0)  # 91 frames > window 32: chained chunks
    keys = [0, 7, 20, 33, 45, 60, 61, 90]
    out = model.interpolate(motion, keys)
    assert out.num_frames == motion.num_frames and out.skeleton == motion.skeleton
    assert out.fps == motion.fps
    assert torch.allclose(out.rotations[keys], motion.rotations[keys], atol=1e-6)
    assert torch.allclose(out.root_positions[keys], motion.root_positions[keys], atol=1e-6)
    assert torch.allclose(out.global_positions()[keys], motion.global_positions()[keys], atol=1e-5)
    # in-between frames are generated from the keys only: corrupting them changes nothing
    rot = motion.rotations.clone()
    inner = [t for t in range(motion.num_frames) if t not in keys]
    rot[inner] = Q.normalize(torch.randn(len(inner), motion.num_joints, 4, dtype=rot.dtype))
    corrupted = Motion(motion.skeleton, rot, motion.root_positions, motion.fps, units="m")
    again = model.interpolate(corrupted, keys)
    assert torch.allclose(again.global_positions(), out.global_positions(), atol=1e-5)
    if residual:  # zero-initialised residual: exactly the LERP/SLERP baseline
        lerp = lerp_slerp(motion, keys)
        assert torch.allclose(out.root_positions, lerp.root_positions, atol=1e-5)
        assert torch.allclose(out.global_positions(), lerp.global_positions(), atol=1e-4)


def test_interpolate_rescales_unknown_units() -> None:
    model = _tiny()
    motion = _motion(seconds=1.0)
    keys = [0, 10, 30]
    in_m = model.interpolate(motion, keys)
    cm = motion.scaled(100.0)
    cm.units = None  # unknown: the skeleton height picks the closest unit (cm)
    in_cm = model.interpolate(cm, keys)
    assert torch.allclose(in_cm.global_positions(), 100.0 * in_m.global_positions(), atol=1e-3)
    # a somewhat bigger body in unknown units is taken as metres (not shrunk)
    big = motion.scaled(1.3)
    big.units = None
    assert model._scale_to_training(big) == 1.0


def test_interpolate_rejects_bad_input() -> None:
    model = _tiny()
    motion = _motion(seconds=1.0)
    with pytest.raises(MotionError, match="start at 0 and end"):
        model.interpolate(motion, [0, 10])
    with pytest.raises(MotionError, match="strictly increasing"):
        model.interpolate(motion, [0, 10, 10, 30])
    other, _ = procedural.generate("biped22", "walk", seconds=1.0, fps=30)
    with pytest.raises(MotionError, match="hierarchy"):
        model.interpolate(other, [0, other.num_frames - 1])
    with pytest.raises(SkelagnosticError, match="no skeleton"):
        PcmrlInterpAligner(**TINY).interpolate(motion, [0, 30])


def test_datamodule_checks_units_and_hierarchy(tmp_path: Path) -> None:
    from skelagnostic.data.sources import ProceduralSource

    class _Raw(ProceduralSource):
        def load(self, clip):  # type: ignore[no-untyped-def]
            return self._generate()[clip.id]  # centimetres, not converted

    dm = PcmrlInterpDataModule(sources=[_Raw(kinds=("biped31",), gaits=("walk",))], window=32)
    with pytest.raises(SkelagnosticError, match="metres"):
        dm.setup("fit")
    dm = PcmrlInterpDataModule(
        sources=[ProceduralSource(kinds=("biped31", "biped22"), gaits=("walk",))], window=32
    )
    with pytest.raises(SkelagnosticError, match="hierarchy"):
        dm.setup("fit")


def test_fit_a_few_steps_and_reload(tmp_path: Path) -> None:
    L.seed_everything(0)
    dm = PcmrlInterpDataModule(
        fps=30,
        window=32,
        batch_size=4,
        samples_per_epoch=16,
        min_keys=3,
        max_keys=8,
        rpa_prob=1.0,
        test_fraction=0.25,
    )
    model = PcmrlInterpAligner(**TINY, optimizer=_adamw(1e-3), scheduler=_warmup(2))
    trainer = L.Trainer(
        max_epochs=2,
        accelerator="cpu",
        logger=False,
        default_root_dir=tmp_path,
        enable_progress_bar=False,
        enable_model_summary=False,
    )
    trainer.fit(model, datamodule=dm)
    assert trainer.global_step == 8
    assert math.isfinite(float(trainer.callback_metrics["val/loss"]))
    assert model.hparams.skeleton is not None and model.hparams.window == 32
    ckpt = tmp_path / "model.ckpt"
    trainer.save_checkpoint(ckpt)
    loaded = PcmrlInterpAligner.load_from_checkpoint(ckpt, map_location="cpu").eval()
    model.eval()
    motion = dm.clips["val"][0]
    clip = Motion(dm.skeleton, _local(motion), motion.root, 30.0)[:40]
    a = model.interpolate(clip, [0, 13, 39])
    b = loaded.interpolate(clip, [0, 13, 39])
    assert torch.allclose(a.global_positions(), b.global_positions(), atol=1e-6)
    test = trainer.test(loaded, datamodule=dm, verbose=False)
    assert len(dm.clips["test"]) == 1 and len(dm.clips["val"]) == 1
    assert math.isfinite(test[0]["test/loss"])


def test_ema_averages_the_network_built_from_the_data(tmp_path: Path) -> None:
    """callbacks=ema copies the model before setup(): configure_model builds the network first."""
    from lightning.pytorch.callbacks import ModelCheckpoint

    from skelagnostic.callbacks import EMAWeights

    L.seed_everything(0)
    dm = PcmrlInterpDataModule(
        fps=30,
        window=32,
        batch_size=4,
        samples_per_epoch=16,
        min_keys=3,
        max_keys=8,
        val_fraction=0.0,
    )
    model = PcmrlInterpAligner(**TINY, residual=True, optimizer=_adamw(1e-2), scheduler=_warmup(1))
    trainer = L.Trainer(
        max_epochs=1,
        accelerator="cpu",
        logger=False,
        limit_val_batches=0,
        default_root_dir=tmp_path,
        enable_progress_bar=False,
        enable_model_summary=False,
        callbacks=[EMAWeights(decay=0.5), ModelCheckpoint(dirpath=tmp_path, save_last=True)],
    )
    trainer.fit(model, datamodule=dm)
    ckpt_path = tmp_path / "last.ckpt"  # written during training (at the end both agree)
    ckpt = torch.load(ckpt_path, weights_only=False)
    averaged, raw = ckpt["state_dict"], ckpt["current_model_state"]
    net_keys = [k for k in raw if k.startswith("net.")]
    assert net_keys and set(net_keys) <= set(averaged)
    assert any(not torch.equal(averaged[k], raw[k]) for k in net_keys)
    loaded = PcmrlInterpAligner.load_from_checkpoint(ckpt_path, map_location="cpu")
    assert torch.equal(loaded.state_dict()["net.head.weight"], averaged["net.head.weight"])


def _local(clip) -> torch.Tensor:  # type: ignore[no-untyped-def]
    from skelagnostic.core.kinematics import local_from_global

    return local_from_global(clip.global_rotations, clip.skeleton.parents)


@pytest.mark.parametrize("layout", ["skelagnostic", "authors"])
def test_training_reduces_the_loss(layout: str) -> None:
    """A few dozen steps on one batch must fit it better than the start (not a no-op)."""
    torch.manual_seed(0)
    dm = PcmrlInterpDataModule(fps=30, window=32, batch_size=8, samples_per_epoch=8, rpa_prob=0.0)
    dm.setup("fit")
    batch = next(iter(dm.train_dataloader()))
    model = PcmrlInterpAligner(
        **TINY, skeleton=dm.skeleton.to_dict(), fps=30.0, window=32, layout=layout
    )
    assert model.net is not None and model.net.layout == layout
    opt = torch.optim.AdamW(model.parameters(), lr=3e-3)
    first = model._losses(batch)[0].item()
    for _ in range(40):
        opt.zero_grad()
        loss, _ = model._losses(batch)
        loss.backward()
        opt.step()
    assert model._losses(batch)[0].item() < 0.5 * first


def _turned(motion: Motion, angle: float) -> Motion:
    """``motion`` turned by ``angle`` about its up axis (around the origin)."""
    axis = torch.zeros(4, dtype=motion.rotations.dtype)
    axis[0], axis[1 + motion.skeleton.up_index] = math.cos(angle / 2), math.sin(angle / 2)
    rot = motion.rotations.clone()
    rot[:, 0] = Q.mul(axis.expand_as(rot[:, 0]), rot[:, 0])
    root = Q.rotate(axis.expand(motion.num_frames, 4), motion.root_positions)
    return Motion(motion.skeleton, rot, root, motion.fps, units=motion.units)


@pytest.mark.parametrize("canonical", [True, False])
def test_canonical_heading_makes_interpolation_turn_with_the_input(canonical: bool) -> None:
    model = _tiny()  # direct output, random weights: far from the baseline
    model.hparams.canonical_heading = canonical
    motion = _motion(seconds=2.0)
    keys = [0, 15, 30, 45, motion.num_frames - 1]
    out = model.interpolate(motion, keys)
    turned = model.interpolate(_turned(motion, 1.1), keys)
    expected = _turned(out, 1.1).global_positions()
    if canonical:  # the prediction turns with the input, exactly
        assert torch.allclose(turned.global_positions(), expected, atol=1e-4)
    else:  # without it the network sees another input and predicts something else
        assert (turned.global_positions() - expected).abs().max() > 1e-2


def test_window_heading_is_equivariant_and_needs_left_and_right() -> None:
    from skelagnostic_pcmrl.interp.keyframes import window_heading
    from skelagnostic_pcmrl.points import group_of_joints

    motion = _motion(seconds=1.0)
    skel = motion.skeleton
    grot = motion.global_rotations()[None]
    heading = window_heading(
        grot,
        motion.root_positions[None],
        skel.offsets,
        group_of_joints(skel),
        skel.parents,
        skel.up_index,
    )
    turned = _turned(motion, -0.7)
    again = window_heading(
        turned.global_rotations()[None],
        turned.root_positions[None],
        skel.offsets,
        group_of_joints(skel),
        skel.parents,
        skel.up_index,
    )
    turn = torch.tensor([math.cos(-0.35), 0.0, math.sin(-0.35), 0.0], dtype=heading.dtype)
    assert torch.allclose(Q.mul(turn, heading[0]).abs(), again[0].abs(), atol=1e-5)
    no_sides = torch.zeros(skel.num_joints, dtype=torch.long)  # every joint on the spine
    same = window_heading(
        grot, motion.root_positions[None], skel.offsets, no_sides, skel.parents, skel.up_index
    )
    assert torch.allclose(same, Q.identity(1, dtype=same.dtype))


def _reloaded(model: PcmrlInterpAligner, tmp_path: Path) -> PcmrlInterpAligner:
    """``model`` saved as a Lightning checkpoint and loaded back."""
    trainer = L.Trainer(
        accelerator="cpu",
        logger=False,
        default_root_dir=tmp_path,
        enable_progress_bar=False,
        enable_model_summary=False,
    )
    trainer.strategy.connect(model)
    ckpt = tmp_path / "model.ckpt"
    trainer.save_checkpoint(ckpt)
    return PcmrlInterpAligner.load_from_checkpoint(ckpt).eval()


def test_canonical_heading_is_saved_with_the_checkpoint(tmp_path: Path) -> None:
    assert _tiny().hparams.canonical_heading is False  # the default (paper)
    torch.manual_seed(0)
    skel = procedural.skeleton("biped31").scaled(0.01)
    model = PcmrlInterpAligner(
        **TINY, canonical_heading=True, skeleton=skel.to_dict(), fps=30.0, window=32
    ).eval()
    loaded = _reloaded(model, tmp_path)
    assert loaded.hparams.canonical_heading is True
    motion = _turned(_motion(seconds=1.0), 0.4)
    keys = [0, 12, motion.num_frames - 1]
    assert torch.allclose(
        loaded.interpolate(motion, keys).global_positions(),
        model.interpolate(motion, keys).global_positions(),
        atol=1e-6,
    )


def test_lerp_tokens_see_the_baseline_pose_and_the_place_in_the_gap() -> None:
    """``interm_inputs`` = FK of the LERP/SLERP baseline (as :func:`lerp_slerp` computes it
    on its own) in the model's frame, plus ``w``, ``sin(pi w)`` and the gap length."""
    from skelagnostic_pcmrl.interp.keyframes import window_features
    from skelagnostic_pcmrl.interp.rpa import bone_tails

    motion = _motion(seconds=1.0)
    skel = motion.skeleton
    keys = [0, 4, 19, motion.num_frames - 1]
    mask = torch.zeros(1, motion.num_frames, dtype=torch.bool)
    mask[0, keys] = True
    feats = window_features(
        motion.global_rotations()[None],
        motion.root_positions[None],
        skel.offsets[None],
        bone_tails(skel).tails[None],
        mask,
        skel.parents,
        interm=True,
        max_relative=16,
    )
    num_j = skel.num_joints
    inputs = feats["interm_inputs"][0]
    assert inputs.shape == (motion.num_frames, 10 * num_j + 3)
    base = lerp_slerp(motion, keys).global_positions() - feats["center"][0]
    got = inputs[:, : 10 * num_j].reshape(motion.num_frames, num_j, 10)[..., :3]
    assert torch.allclose(got, base, atol=1e-5)
    # frame 10 lies 6/15 into the gap 4..19; frame 2 half-way into 0..4
    assert inputs[10, -3:].tolist() == pytest.approx([0.4, math.sin(0.4 * math.pi), 15 / 16])
    assert inputs[2, -3:].tolist() == pytest.approx([0.5, 1.0, 4 / 16])
    assert inputs[19, -3:].tolist() == pytest.approx([0.0, 0.0, 0.0])  # a key
    # the baseline FOQ is the FOQ of the baseline pose
    lerp_global = lerp_slerp(motion, keys).global_rotations()
    foq = Q.mul(lerp_global, Q.inv(lerp_global[:1]))
    got_foq = inputs[:, : 10 * num_j].reshape(motion.num_frames, num_j, 10)[..., 6:]
    dots = (got_foq * foq).sum(-1).abs()
    assert torch.allclose(dots, torch.ones_like(dots), atol=1e-5)


def test_interm_tokens_option_is_checked_and_saved(tmp_path: Path) -> None:
    assert _tiny().hparams.interm_tokens == "zero"  # the default (CITL, paper)
    with pytest.raises(SkelagnosticError, match="interm_tokens"):
        _tiny(interm_tokens="mean")
    with pytest.raises(SkelagnosticError, match="residual_space"):
        _tiny(residual_space="global")
    model = _tiny(interm_tokens="lerp")
    assert model.net is not None and model.net.interm_embed is not None
    loaded = _reloaded(model, tmp_path)
    assert loaded.hparams.interm_tokens == "lerp"
    motion = _motion(seconds=1.0)
    keys = [0, 12, motion.num_frames - 1]
    assert torch.allclose(
        loaded.interpolate(motion, keys).global_positions(),
        model.interpolate(motion, keys).global_positions(),
        atol=1e-6,
    )


def test_interpolate_batches_chunks_like_one_at_a_time() -> None:
    """Equal-length chunks run as one batch; each chunk is what it is alone (float64)."""
    model = _tiny(window=32).double()
    motion = _motion(seconds=6.0).to(dtype=torch.float64)  # 181 frames
    keys = [*range(0, 150, 10), 157, 165, 180]  # chunks of 30 frames, then shorter ones
    chunks = model._chunks(keys, 32)
    assert [(s, e) for s, e, _, _ in chunks][:2] == [(0, 30), (30, 60)]
    assert len({e - s for s, e, _, _ in chunks}) > 1  # several batches of different lengths
    batched = model.interpolate(motion, keys)
    # reference: every chunk through the network on its own, assembled by hand
    grot = motion.global_rotations()
    root = motion.root_positions
    offsets = motion.skeleton.offsets[None]
    tails = bone_tails(motion.skeleton).tails.to(torch.float64)[None]
    want_g, want_r = grot.clone(), root.clone()
    start = 0
    while start < motion.num_frames - 1:
        end = max(k for k in keys if k - start + 1 <= 32 and k > start)
        mask = torch.tensor([[t in keys for t in range(start, end + 1)]])
        with torch.no_grad():
            g, r = model.interpolate_window(
                grot[None, start : end + 1], root[None, start : end + 1], mask, offsets, tails
            )
        want_g[start : end + 1], want_r[start : end + 1] = g[0], r[0]
        start = end
    got = batched.global_rotations()
    assert torch.allclose(
        Q.mul(got, Q.inv(want_g))[..., 0].abs(), torch.ones_like(got[..., 0]), atol=1e-10
    )
    assert torch.allclose(batched.root_positions, want_r, atol=1e-10)
    model.interpolate_batch = 1  # one chunk per call: the same motion
    single = model.interpolate(motion, keys)
    assert torch.allclose(single.rotations, batched.rotations, atol=1e-10)


def test_a_batch_of_another_skeleton_is_refused_by_name() -> None:
    """The batch carries its skeleton; the model checks it against its own hierarchy."""
    dm = PcmrlInterpDataModule(fps=30, window=32, batch_size=4, samples_per_epoch=4, rpa_prob=0.0)
    dm.setup("fit")
    batch = next(iter(dm.train_dataloader()))
    assert batch["skeleton"] == dm.skeleton and batch["fps"] == 30.0
    model = PcmrlInterpAligner(**TINY, skeleton=dm.skeleton.to_dict(), fps=30.0, window=32)
    assert torch.isfinite(model._losses(batch)[0])
    other = {**batch, "skeleton": procedural.skeleton("biped22")}
    with pytest.raises(SkelagnosticError, match="another hierarchy than the model's"):
        model._losses(other)
    with pytest.raises(SkelagnosticError, match="carries no 'skeleton'"):
        model._losses({k: v for k, v in batch.items() if k != "skeleton"})
