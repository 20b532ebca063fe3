"""The Lightning aligner: a short real training run, checkpoints, encode/decode, CLI configs."""

from __future__ import annotations

from pathlib import Path

import lightning as L
import pytest
import torch
from skelagnostic_vqpae.aligner import PREVIOUS_DEFAULTS, VqpaeAligner
from skelagnostic_vqpae.data import VqpaeDataModule
from skelagnostic_vqpae.embed import embed_datasets
from skelagnostic_vqpae.losses import phase_rate_loss
from skelagnostic_vqpae.model import PhaseParameters

from skelagnostic import procedural
from skelagnostic.errors import SkelagnosticError

FPS = 20  # the frame rate of conftest.make_datamodule


def test_short_training_lowers_the_reconstruction_loss(trained: dict) -> None:
    before, after = trained["before"], trained["after"]
    names = trained["dm"].dataset_names
    for name in names:  # held-out clips: every dataset improves, the mean by a fifth
        assert after[f"val/rec/{name}"] < before[f"val/rec/{name}"], name
    mean = {
        k: sum(d[f"val/rec/{n}"] for n in names) / len(names)
        for k, d in (("before", before), ("after", after))
    }
    assert mean["after"] < 0.8 * mean["before"]
    assert 0.0 < after["val/usage"] <= 1.0
    assert all(torch.isfinite(torch.tensor(v)) for v in after.values())


def test_networks_per_dataset_and_one_codebook(trained: dict) -> None:
    model: VqpaeAligner = trained["model"]
    assert model.dataset_names == ["procedural/biped22", "procedural/quadruped"]
    assert model.codebook is not None and model.codebook.weight.shape == (8, 20)
    assert model.characters[0].pae.channels == 66 and model.characters[1].pae.channels == 63
    assert model.hparams["datasets"]["procedural/biped22"]["window"] == FPS + 1
    assert float(model.codebook.usage.sum()) > 0  # re-initialisation ran and tracked usage


def test_fit_writes_metrics_and_the_manifold_pictures(trained: dict) -> None:
    import json

    from PIL import Image

    root: Path = trained["root"]
    metrics = json.loads((root / "vqpae_metrics.json").read_text())
    names = trained["dm"].dataset_names
    assert metrics["split"] == "val"
    assert set(metrics["per_dataset"]) == set(metrics["codes_used"]) == set(names)
    assert 0.0 < metrics["usage"] <= 1.0 and 0.0 <= metrics["overlap"] <= metrics["usage"]
    train = metrics["train"]  # the same figures on the training clips
    assert set(train) == {"usage", "overlap", "per_dataset", "codes_used"}
    assert 0.0 < train["usage"] <= 1.0
    # the written overlap is the metric of the validation clips' codes, recomputed here
    model: VqpaeAligner = trained["model"]
    embeddings = embed_datasets(model, trained["dm"].datasets["val"], FPS)
    for name in names:
        codes = torch.cat([e.code for e in embeddings[name]])
        assert metrics["codes_used"][name] == int(codes.unique().numel())
        assert all(len(e) > 0 and e.fps == FPS and e.dataset == name for e in embeddings[name])
        pivots_sorted = embeddings[name][0]
        assert pivots_sorted.manifold.shape == (len(pivots_sorted), 10)
    for picture in ("vqpae_manifold.png", "vqpae_timing.png"):
        with Image.open(root / picture) as image:
            assert image.width > 200 and image.height > 100


def test_checkpoint_round_trip_encodes_identically(trained: dict) -> None:
    model: VqpaeAligner = trained["model"]
    loaded = VqpaeAligner.load_from_checkpoint(trained["ckpt"])
    motion, _ = procedural.generate("quadruped", "trot", seconds=2.0, fps=30, seed=5)
    a, b = model.encode(motion), loaded.encode(motion)
    assert torch.equal(a.z, b.z)
    assert torch.equal(a.extras["code"], b.extras["code"])


def test_checkpoint_without_new_options_loads_with_the_papers_settings(
    trained: dict, tmp_path: Path
) -> None:
    # checkpoints written before model.frequency_head existed were trained with "mlp"
    ckpt = torch.load(trained["ckpt"], map_location="cpu", weights_only=False)
    ckpt["hyper_parameters"]["frequency_head"] = "centroid_residual"
    newer = tmp_path / "newer.ckpt"
    torch.save(ckpt, newer)
    loaded = VqpaeAligner.load_from_checkpoint(newer)  # a saved option wins
    assert all(char.pae.frequency_head == "centroid_residual" for char in loaded.characters)
    assert loaded.hparams["lambda_phase_rate"] == ckpt["hyper_parameters"]["lambda_phase_rate"]
    del ckpt["hyper_parameters"]["frequency_head"]
    del ckpt["hyper_parameters"]["lambda_phase_rate"]
    old = tmp_path / "old.ckpt"
    torch.save(ckpt, old)
    loaded = VqpaeAligner.load_from_checkpoint(old)
    assert loaded.hparams["frequency_head"] == "mlp"
    assert all(char.pae.frequency_head == "mlp" for char in loaded.characters)
    assert loaded.hparams["lambda_phase_rate"] == 0.0  # trained without the phase-rate loss


def test_encode_gives_one_embedding_per_frame(trained: dict) -> None:
    model: VqpaeAligner = trained["model"]
    motion, _ = procedural.generate("biped22", "walk", seconds=2.0, fps=40, seed=3)
    latent = model.encode(motion)
    frames = 2 * FPS + 1  # resampled to the dataset frame rate
    assert latent.fps == FPS
    assert latent.z.shape == (frames, 10)
    for key, shape in {
        "phase": (frames,),
        "frequency": (frames,),
        "code": (frames,),
        "amplitude": (frames, 20),
    }.items():
        assert latent.extras[key].shape == shape
    assert bool((latent.extras["frequency"] > 0).all())


def test_encode_dataset_is_forward_dataset_without_the_decoder(trained: dict) -> None:
    model: VqpaeAligner = trained["model"].eval()
    seen = set()
    for kind in ("biped22", "quadruped"):  # each dataset's own network and codebook view
        motion, _ = procedural.generate(kind, "walk", seconds=2.0, fps=FPS, seed=4)
        k = model.dataset_of(motion.skeleton)
        seen.add(k)
        windows, _ = model._windows(k, motion)
        with torch.no_grad():
            _, full = model.forward_dataset(k, windows)
            alone = model.encode_dataset(k, windows)
        for field in ("phase", "frequency", "code", "amplitude", "manifold"):
            assert torch.equal(getattr(alone, field), getattr(full, field)), (kind, field)
    assert seen == {0, 1}
    with pytest.raises(SkelagnosticError, match="no datasets yet"):
        VqpaeAligner().encode_dataset(0, torch.zeros(1, 3, 5))


def test_decode_gives_the_average_pose_on_the_skeleton(trained: dict) -> None:
    model: VqpaeAligner = trained["model"]
    motion, _ = procedural.generate("quadruped", "trot", seconds=1.0, fps=FPS, seed=2)
    out = model.decode(model.encode(motion), motion.skeleton)
    assert out.skeleton is motion.skeleton
    assert out.num_frames == motion.num_frames
    assert bool(torch.isfinite(out.global_positions()).all())


def test_encode_and_decode_work_in_the_clips_length_units(trained: dict) -> None:
    """The model sees a clip in metres, as the data sources gave it in training.

    A clip in centimetres or millimetres (stated, or guessed from its height, as
    ``read_bvh`` leaves it) embeds like the same clip in metres, and the average
    pose comes back in the units of the skeleton it is decoded onto.
    """
    model: VqpaeAligner = trained["model"].eval()
    metres, _ = procedural.generate("biped22", "walk", seconds=2.0, fps=FPS, seed=5)
    metres = metres.to_metres()
    cm = metres.convert_units("cm")
    guessed = cm.scaled(1.0)
    guessed.units = None  # what read_bvh gives: the unit is guessed from the height
    ref = model.encode(metres)
    for other in (cm, guessed, metres.convert_units("mm")):
        latent = model.encode(other)
        assert torch.allclose(latent.z, ref.z, atol=1e-5)
        for key in ("phase", "frequency", "amplitude"):
            assert torch.allclose(latent.extras[key], ref.extras[key], atol=1e-5), key
        assert torch.equal(latent.extras["code"], ref.extras["code"])
    out_m = model.decode(ref, metres.skeleton)
    out_cm = model.decode(ref, cm.skeleton)
    assert (out_m.units, out_cm.units) == ("m", "cm")
    assert torch.allclose(out_cm.global_positions(), 100 * out_m.global_positions(), atol=1e-6)
    assert torch.allclose(out_m.rotations, out_cm.rotations, atol=1e-9)


def test_unknown_skeleton_is_rejected(trained: dict) -> None:
    motion, _ = procedural.generate("biped17", "walk", seconds=1.0, fps=FPS, seed=1)
    with pytest.raises(SkelagnosticError, match="no trained dataset"):
        trained["model"].encode(motion)


def test_untrained_pose_mlp_cannot_decode(trained: dict) -> None:
    loaded = VqpaeAligner.load_from_checkpoint(trained["ckpt"])
    for char in loaded.characters:
        char.pose_fitted.fill_(False)
    motion, _ = procedural.generate("biped22", "walk", seconds=1.0, fps=FPS, seed=1)
    with pytest.raises(SkelagnosticError, match="average-pose MLP"):
        loaded.decode(loaded.encode(motion), motion.skeleton)


def test_reinit_switch_off_keeps_codebook_usage_untracked(
    cache_dir: Path, tmp_path: Path, helpers: dict
) -> None:
    L.seed_everything(0, verbose=False)
    model = VqpaeAligner(num_codes=8, kernel_size=7, reinit=False, pose_mlp="none")
    helpers["trainer"](tmp_path, 3).fit(model, datamodule=helpers["datamodule"](cache_dir))
    assert model.codebook is not None
    assert float(model.codebook.usage.abs().sum()) == 0.0


def test_phase_rate_loss_ties_the_frequency_to_the_phase_advance(
    cache_dir: Path, tmp_path: Path, helpers: dict
) -> None:
    import numpy as np

    L.seed_everything(0, verbose=False)
    model = VqpaeAligner(num_codes=8, kernel_size=7, pose_mlp="none", lambda_phase_rate=1.0)
    dm = helpers["datamodule"](cache_dir)
    trainer = helpers["trainer"](tmp_path, 2, validate=False)
    trainer.fit(model, datamodule=dm)
    assert "train/phase_rate/procedural/biped22" in trainer.callback_metrics
    batch = next(iter(dm.train_dataloader()))[0]["procedural/quadruped"]
    k = model.dataset_names.index("procedural/quadruped")
    model.train()
    _, params = model.forward_dataset(k, batch["features"])

    def rate_loss(p: PhaseParameters) -> torch.Tensor:
        """The aligner's phase-rate loss of this batch (its current ``phase_rate_grad``)."""
        pae, mode = model.characters[k].pae, model.hparams.phase_rate_grad
        return phase_rate_loss(pae, "procedural/quadruped", batch, p, mode)

    loss = rate_loss(params)
    # the same figure computed here from the two windows' phases and frequencies
    _, partner = model.forward_dataset(k, batch["shifted"])
    p1, p2 = params.phase.detach().double().numpy(), partner.phase.detach().double().numpy()
    f1 = params.frequency.detach().double().numpy()
    f2 = partner.frequency.detach().double().numpy()
    shift = batch["shift"].double().numpy()
    ok = shift != 0
    assert ok.mean() > 0.5
    advance = np.angle(np.exp(2j * np.pi * (p2 - p1))) / (2 * np.pi)  # wrapped, in cycles
    rate = advance[ok] * FPS / shift[ok]
    expected = 0.5 * (np.abs(f1[ok] - rate).mean() + np.abs(f2[ok] - rate).mean())
    assert float(loss.detach()) == pytest.approx(expected, rel=1e-4)
    # it trains the frequency, not the phase: the phase difference is the detached target
    pae = model.characters[k].pae

    def grads(mode: str) -> tuple[float, ...]:
        model.hparams["phase_rate_grad"] = mode
        model.zero_grad()
        _, fresh = model.forward_dataset(k, batch["features"])
        rate_loss(fresh).backward()
        return tuple(
            float(0 if w.grad is None else w.grad.abs().sum())
            for w in (
                pae.freq_mlp[0].weight,
                pae.phase_conv.weight,
                pae.encoder[0].weight,
                pae.amp_mlp[0].weight,
            )
        )

    freq, timing, encoder, amplitude = grads("network")
    assert freq > 0 and timing > 0 and encoder > 0 and amplitude == 0
    freq, timing, encoder, amplitude = grads("timing")  # the timing branch, not the latent
    assert freq > 0 and timing > 0 and encoder == 0 and amplitude == 0
    freq, timing, encoder, amplitude = grads("head")  # the frequency MLP alone
    assert freq > 0 and timing == 0 and encoder == 0 and amplitude == 0
    # every mode computes the same loss value
    values = []
    for mode in ("network", "timing", "head"):
        model.hparams["phase_rate_grad"] = mode
        with torch.no_grad():
            _, fresh = model.forward_dataset(k, batch["features"])
            values.append(float(rate_loss(fresh)))
    assert values == pytest.approx([values[0]] * 3, rel=1e-5)


def test_phase_rate_loss_without_partner_windows_is_a_clear_error(
    cache_dir: Path, tmp_path: Path, helpers: dict
) -> None:
    model = VqpaeAligner(num_codes=8, kernel_size=7, pose_mlp="none", lambda_phase_rate=1.0)
    dm = helpers["datamodule"](cache_dir)
    dm.pair_seconds, dm.pair_shift = 0.0, 0
    with pytest.raises(SkelagnosticError, match=r"data\.pair_seconds > 0"):
        helpers["trainer"](tmp_path, 1, validate=False).fit(model, datamodule=dm)


def test_bad_options_are_rejected() -> None:
    with pytest.raises(SkelagnosticError, match="lambda_phase_rate"):
        VqpaeAligner(lambda_phase_rate=-1.0)
    with pytest.raises(SkelagnosticError, match="phase_rate_grad"):
        VqpaeAligner(phase_rate_grad="decoder")
    with pytest.raises(SkelagnosticError, match="pose_mlp"):
        VqpaeAligner(pose_mlp="sometimes")
    with pytest.raises(SkelagnosticError, match="num_codes"):
        VqpaeAligner(num_codes=0)
    with pytest.raises(SkelagnosticError, match="no datasets yet"):
        VqpaeAligner().forward_dataset(0, torch.zeros(1, 3, 5))


def test_cli_run_with_the_registered_plugin(vqpae_pm, tmp_path: Path, cache_dir: Path) -> None:
    from skelagnostic.cli.app import compose, run

    cfg = compose(
        [
            "model=vqpae",
            f"run_dir={tmp_path}",
            "experiment=smoke",
            "callbacks=none",
            "logger=none",
            "model.num_codes=8",
            "model.kernel_size=7",
            f"data.cache_dir={cache_dir}",
            "data.seconds=2.0",
        ],
        plugin_manager=vqpae_pm,
    )
    metrics = run(cfg, vqpae_pm)
    assert "val/overlap" in metrics and "train/loss" in metrics
    assert (tmp_path / "config.yaml").exists()


def test_cli_run_with_ema_averages_every_network(vqpae_pm, tmp_path: Path, cache_dir: Path) -> None:
    """The networks are built from the data before callbacks=ema copies the model."""
    from skelagnostic.cli.app import compose, run

    cfg = compose(
        [
            "model=vqpae",
            f"run_dir={tmp_path}",
            "experiment=smoke",
            "callbacks=ema",
            "logger=none",
            "model.num_codes=8",
            "model.kernel_size=7",
            f"data.cache_dir={cache_dir}",
            "data.seconds=2.0",
        ],
        plugin_manager=vqpae_pm,
    )
    run(cfg, vqpae_pm)
    ckpt = torch.load(tmp_path / "checkpoints" / "last.ckpt", weights_only=False)
    assert set(ckpt["current_model_state"]) <= set(ckpt["state_dict"])
    assert len(ckpt["state_dict"]) > 10


@pytest.mark.parametrize(
    ("experiment", "codes", "source"),
    [("vqpae_human_dog", 32, "human_dog"), ("vqpae_stylized", 64, "styles")],
)
def test_experiment_presets_compose(vqpae_pm, experiment: str, codes: int, source: str) -> None:
    from skelagnostic.cli.app import build_datamodule, compose

    cfg = compose(
        ["model=vqpae", f"experiment={experiment}", "run_dir=/tmp/unused"], plugin_manager=vqpae_pm
    )
    assert cfg.model.num_codes == codes
    assert cfg.data.source == source
    assert cfg.data.fps == 60 and cfg.data.stride == 1 and cfg.data.batch_size == 32
    assert cfg.model.optimizer.lr == 1e-4 and cfg.model.optimizer.weight_decay == 1e-4
    # the paper's objective: the phase-rate loss (on in vqpae_plus) slows code sharing
    assert cfg.model.lambda_phase_rate == 0.0
    assert cfg.data.pair_seconds == 0.0  # so no partner windows are gathered
    # the settings they were measured with: the previous defaults
    for key, value in PREVIOUS_DEFAULTS.items():
        if key == "scheduler":  # the cosine schedule, at the preset's own period
            assert cfg.model.scheduler._target_ == value["_target_"]
        elif key != "lambda_phase_rate":
            assert cfg.model[key] == value, key
    if Path(str(cfg.data.get("root", cfg.data.get("human_root")))).exists():
        dm = build_datamodule(cfg, vqpae_pm)
        assert isinstance(dm, VqpaeDataModule) and dm.window == 61 and dm.pair_shift == 0


def test_fit_without_data_uses_procedural_biped_and_quadruped(vqpae_pm) -> None:
    from skelagnostic.cli.app import build_datamodule, compose

    cfg = compose(["model=vqpae", "run_dir=/tmp/unused"], plugin_manager=vqpae_pm)
    assert cfg.data.source == "procedural"
    assert list(cfg.data.kinds) == ["biped22", "quadruped"]
    assert cfg.data.fps == 60 and cfg.data.window_seconds == 1.0 and cfg.data.stride == 1
    assert cfg.model.padding_mode == "zeros" and not cfg.model.center_windows  # the authors'
    dm = build_datamodule(cfg, vqpae_pm)
    assert isinstance(dm, VqpaeDataModule) and dm.window == 61 and dm.stride == 1
    override = compose(
        ["model=vqpae", "run_dir=/tmp/unused", "data.fps=30"], plugin_manager=vqpae_pm
    )
    assert override.data.fps == 30
