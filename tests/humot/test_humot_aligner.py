import json

import lightning as L
import pytest
import torch
from skelagnostic_humot.aligner import (
    PAPER_OPTIMIZER,
    PAPER_SCHEDULER,
    HumotAligner,
    infer_units,
    leg_length,
)
from skelagnostic_humot.data import HumotDataModule

import skelagnostic as sa
from skelagnostic.data import ProceduralSource
from skelagnostic.errors import SkelagnosticError


def _datamodule(tmp_path, kinds=("biped22", "biped17"), batch_size=8):
    source = ProceduralSource(
        kinds=list(kinds), gaits=["walk", "run"], clips_per_gait=1, seconds=2.0
    )
    return HumotDataModule(
        [source], cache_dir=tmp_path / "cache", batch_size=batch_size, val_fraction=0.5
    )


def test_bad_hyper_parameters_are_named():
    with pytest.raises(SkelagnosticError, match=r"model\.p_major"):
        HumotAligner(p_major=1.5)
    with pytest.raises(SkelagnosticError, match=r"model\.optimizer\.lrr is not an argument"):
        HumotAligner(optimizer={"_target_": "torch.optim.Adam", "lrr": 1e-3})
    with pytest.raises(SkelagnosticError, match=r"model\.scheduler\._target_='nope\.x'"):
        HumotAligner(scheduler={"_target_": "nope.x"})
    # the cycle's bounds are checked when the schedule is built, before any step
    model = HumotAligner(optimizer={**PAPER_OPTIMIZER, "lr": 1e-3})
    with pytest.raises(SkelagnosticError, match=r"model\.optimizer\.lr=0\.001 must be in"):
        model.configure_optimizers()


def test_training_lowers_the_loss_on_a_batch(humot_small):
    torch.manual_seed(0)
    model = HumotAligner(**humot_small)
    motion = sa.procedural.generate("biped22", "walk", seconds=2.0, fps=30)[0]
    world = motion.global_positions().float()[None, :30] / 100
    world = torch.cat([world, motion.global_positions().float()[None, 30:60] / 100])
    topo = model.topology(motion.skeleton)
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    model.train()
    losses = []
    # 60 steps: with one XCA map per frame (the default) the loss leaves its first plateau
    # after ~30 steps on this batch (0.43 -> 0.28 at 30, 0.06 at 60; per chunk: 0.09 at 30)
    for _ in range(60):
        loss = model.chunk_loss(world, topo, subsample=False)["loss"]
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert losses[-1] < 0.5 * losses[0]


def test_subsampled_loss_is_finite_and_differentiable(humot_small):
    torch.manual_seed(0)
    model = HumotAligner(**humot_small).train()
    motion = sa.procedural.generate("biped31", "run", seconds=1.0, fps=30)[0]
    out = model.chunk_loss(
        motion.global_positions().float()[None, :30].expand(4, -1, -1, -1) / 100,
        model.topology(motion.skeleton),
    )
    assert torch.isfinite(out["loss"]) and out["blc"] >= 0
    out["loss"].backward()


def test_cyclic_learning_rate(tmp_path, humot_small):
    model = HumotAligner(**humot_small, scheduler={**PAPER_SCHEDULER, "period_epochs": 2})
    dm = _datamodule(tmp_path)
    trainer = L.Trainer(
        max_epochs=4,
        accelerator="cpu",
        logger=False,
        enable_checkpointing=False,
        enable_progress_bar=False,
        limit_val_batches=0,
        default_root_dir=tmp_path,
    )
    lrs = []

    class Record(L.Callback):
        def on_train_batch_start(self, trainer, pl_module, batch, batch_idx):
            lrs.append(trainer.optimizers[0].param_groups[0]["lr"])

    trainer.callbacks.append(Record())
    trainer.fit(model, datamodule=dm)
    per_epoch = len(lrs) // 4
    assert lrs[0] == pytest.approx(1e-5)
    assert max(lrs) == pytest.approx(1e-4) and lrs.index(max(lrs)) == per_epoch  # half period
    assert lrs[2 * per_epoch] == pytest.approx(1e-5)  # full period: 2 epochs


def test_cyclic_learning_rate_with_max_steps(tmp_path, humot_small):
    """``max_steps`` without ``max_epochs``: the period still counts the loader's batches."""
    model = HumotAligner(**humot_small, scheduler={**PAPER_SCHEDULER, "period_epochs": 2})
    dm = _datamodule(tmp_path, batch_size=4)
    trainer = L.Trainer(
        max_steps=3,
        accelerator="cpu",
        logger=False,
        enable_checkpointing=False,
        enable_progress_bar=False,
        limit_val_batches=0,
        default_root_dir=tmp_path,
    )
    trainer.fit(model, datamodule=dm)
    per_epoch = max(len(x) for x in dm.train_dataloader().iterables.values())
    assert per_epoch > 1
    scheduler = trainer.lr_scheduler_configs[0].scheduler
    assert scheduler.total_size == 2 * per_epoch  # one full period = 2 epochs of batches


def test_save_and_load(tmp_path, humot_small):
    torch.manual_seed(0)
    model = HumotAligner(**humot_small)
    dm = _datamodule(tmp_path)
    from skelagnostic.callbacks import FitSummary  # what `skelagnostic fit` adds

    trainer = L.Trainer(
        max_epochs=1,
        accelerator="cpu",
        logger=False,
        enable_progress_bar=False,
        limit_train_batches=1,
        limit_val_batches=1,
        default_root_dir=tmp_path,
        callbacks=[FitSummary(name="humot")],
    )
    trainer.fit(model, datamodule=dm)
    ckpt = tmp_path / "model.ckpt"
    trainer.save_checkpoint(ckpt)
    loaded = HumotAligner.load_from_checkpoint(ckpt, map_location="cpu").eval()
    model.eval()
    motion = sa.procedural.generate("biped17", "walk", seconds=1.5)[0]
    a = model.encode(motion, units="cm")
    b = loaded.encode(motion, units="cm")
    assert torch.allclose(a.z, b.z, atol=1e-6)
    assert (tmp_path / "humot_retarget.gif").exists()
    assert "val/mpjpe_cm" in json.loads((tmp_path / "humot_metrics.json").read_text())


def test_infer_units():
    assert infer_units(sa.procedural.generate("biped22", "walk", seconds=0.1)[0].skeleton) == "cm"
    assert infer_units(sa.Skeleton(["a"], [-1], [[0, 0, 0]]), "m") == "m"
    with pytest.raises(SkelagnosticError, match="units"):
        infer_units(sa.Skeleton(["a"], [-1], [[0, 0, 0]]), "furlong")


def test_leg_length():
    sk = sa.procedural.generate("biped17", "walk", seconds=0.1)[0].skeleton
    from skelagnostic_humot.template import skeleton_template

    t = skeleton_template(sk)
    expected = float(
        (t[sk.index("LKnee")] - t[sk.index("LHip")]).norm()
        + (t[sk.index("LFoot")] - t[sk.index("LKnee")]).norm()
    )
    assert leg_length(t, sk) == pytest.approx(expected)


@pytest.mark.data
@pytest.mark.parametrize(
    ("source", "target", "frames"),
    [
        ("cmu/131_01.bvh", "lafan1/Lafan1_example.bvh", 120),  # 1 s at 120 fps, CMU units -> cm
        ("lafan1/Lafan1_example.bvh", "xia_cmu/angry_13_000.bvh", 30),  # 1 s at 30 fps, cm -> CMU
    ],
)
def test_retarget_between_real_skeletons(
    shared_data, tmp_path, source, target, frames, humot_small
):
    """``retarget(motion, skeleton)`` alone (what ``skelagnostic retarget`` calls) on real rigs."""
    torch.manual_seed(0)
    model = HumotAligner(**humot_small).eval()
    src = sa.read_bvh(shared_data / "human" / source)[:frames]
    dst = sa.read_bvh(shared_data / "human" / target).skeleton
    out = model.retarget(src, dst)
    assert out.skeleton is dst and out.fps == 30.0
    assert out.num_frames == src.resample(30.0).num_frames
    assert torch.isfinite(out.global_positions()).all()
    # bone lengths come from the target rig (rotations fitted, lengths exact)
    pos = out.global_positions()
    for p, c in dst.bones():
        assert torch.allclose(
            (pos[:, c] - pos[:, p]).norm(dim=-1),
            dst.offsets[c].norm().expand(len(pos)).to(pos),
            atol=1e-4,
        )
    sa.write_bvh(out, tmp_path / "retargeted.bvh")
    back = sa.read_bvh(tmp_path / "retargeted.bvh")
    assert back.skeleton.joint_names == dst.joint_names
    assert torch.allclose(
        back.global_positions().float(), out.global_positions().float(), atol=1e-2
    )


def test_retarget_scales_the_trajectory_by_leg_length(monkeypatch, humot_small):
    torch.manual_seed(0)
    model = HumotAligner(**humot_small).eval()
    motion = sa.procedural.generate("biped22", "walk", seconds=2.0)[0]
    latent = model.encode(motion, units="cm")
    # a decoder that outputs centred zeros leaves only the (scaled) chunk centres
    monkeypatch.setattr(
        model.net.decoder,
        "forward",
        lambda z, t, m=None: z.new_zeros(z.shape[0], z.shape[1], t.shape[1], 3),
    )
    same = model.decode_positions(latent, motion.skeleton, motion.skeleton.bone_lengths() / 100)
    big = motion.skeleton.scaled(2.0)
    double = model.decode_positions(latent, big, big.bone_lengths() / 100)
    assert torch.allclose(double, 2 * same, atol=1e-5)
    # with the source's own size the centres are the source's major-joint means
    major = model.topology(motion.skeleton).major
    from skelagnostic_humot.template import motion_positions

    pos = motion_positions(motion.resample(30.0)).float() / 100
    # frames before the second chunk (which starts at frame 15) see the first chunk only
    assert torch.allclose(same[:15, 0], pos[:30, major].mean(dim=(0, 1)).expand(15, 3), atol=1e-4)


def test_upsample_joints_rejects_foreign_joints(humot_small):
    model = HumotAligner(**humot_small).eval()
    motion = sa.procedural.generate("biped17", "walk", seconds=0.5)[0]
    other = sa.procedural.generate("biped22", "walk", seconds=0.5)[0].skeleton
    with pytest.raises(SkelagnosticError, match="not in the full skeleton"):
        model.upsample_joints(motion, other)
    sub = motion.skeleton.subset([n for n in motion.skeleton.joint_names if "Elbow" not in n])
    sub_motion = sa.Motion(
        sub,
        motion.rotations[:, [motion.skeleton.index(n) for n in sub.joint_names]],
        motion.root_positions,
        motion.fps,
    )
    up = model.upsample_joints(sub_motion, motion.skeleton, units="cm")
    assert up.skeleton is motion.skeleton


def test_fit_cli_writes_checkpoint_metrics_and_render(humot_pm, tmp_path):
    from skelagnostic.cli.app import compose, run

    cfg = compose(
        [
            "model=humot",
            "experiment=humot_quick",
            f"run_dir={tmp_path}",
            f"data.cache_dir={tmp_path / 'cache'}",
            "model.dim=32",
            "model.latent=16",
            "model.blocks=1",
            "model.heads=4",
            "trainer.max_epochs=1",
            "trainer.limit_train_batches=1",
            "trainer.limit_val_batches=1",
            "data.seconds=2.0",
        ],
        plugin_manager=humot_pm,
    )
    assert cfg.data.window == 30 and cfg.data.stride == 6
    metrics = run(cfg, humot_pm)
    assert "val/loss" in metrics
    assert (tmp_path / "checkpoints" / "last.ckpt").exists()
    assert (tmp_path / "csv" / "metrics.csv").exists()
    assert (tmp_path / "humot_retarget.gif").exists()
    model = humot_pm.aligner("humot").module.load_from_checkpoint(
        tmp_path / "checkpoints" / "last.ckpt", map_location="cpu"
    )
    assert model.hparams.dim == 32
