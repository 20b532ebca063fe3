"""``model=vqpae`` trains as the authors do; ``experiment=vqpae_plus`` has our changes."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch
from skelagnostic_vqpae.aligner import PLUS_OPTIONS, PREVIOUS_DEFAULTS, VqpaeAligner
from skelagnostic_vqpae.schedule import (
    AUTHORS_MIN_LR,
    CyclicRestarts,
    authors_restarts,
    cyclic_restart_factors,
)

from skelagnostic.errors import SkelagnosticError

FIXTURE = Path(__file__).parents[1] / "fixtures" / "walkthedog" / "schedule.npz"

#: The authors' train_vq.py argument defaults (option.py) that the aligner expresses.
AUTHORS = {
    "latent": 10,  # --n_latent_channel
    "num_codes": 32,  # --num_embed_vq
    "kernel_size": 23,  # --kernel_size
    "phase_kernel": 23,  # VQAE.phase_conv uses --kernel_size
    "freq_layers": 7,  # --n_layers_fft
    "amp_layers": 5,  # --n_layers_state
    "beta": 0.25,  # --beta
    "lambda_vq": 1.0,  # --lambda_vq
    "optimizer": {
        "_target_": "torch.optim.AdamW",
        "_partial_": True,
        "lr": 1e-4,  # --learning_rate
        "weight_decay": 1e-4,  # --weight_decay
    },
    "scheduler": {
        "_target_": "skelagnostic_vqpae.schedule.authors_restarts",  # CyclicLRWithRestarts
        "_partial_": True,
        "period": 10,  # --restart_period
        "mult": 2,  # --restart_mult
    },
    "pose_layers": 8,  # --n_layers_phase_decoder
    "pose_lr": 1e-3,  # --lr_phase_decoder
    "lambda_phase_rate": 0.0,  # not in their objective
    "padding_mode": "zeros",  # Conv1d(padding='same')
    "spectrum": "power",  # rfft(y) / T * 2, squared magnitudes
    "freq_hidden_elu": True,  # MLP(..., last_activation=True)
    "decoder_centering": True,  # LN_v3 after the first deconvolution
    "center_windows": False,  # MSE(yPred, pae_input)
    "reinit_squared_distance": True,  # softmax over the squared distances
    "pose_mlp": "joint",  # the phase decoder's loss is in loss_total
    "frequency_head": "mlp",
}


def test_constructor_defaults_are_the_authors() -> None:
    hp = VqpaeAligner().hparams
    for key, value in AUTHORS.items():
        assert hp[key] == value, key


def test_plus_preset_holds_the_plus_options(vqpae_pm) -> None:
    from skelagnostic.cli.app import compose

    cfg = compose(
        ["model=vqpae", "experiment=vqpae_plus", "run_dir=/tmp/unused"], plugin_manager=vqpae_pm
    )
    default = compose(["model=vqpae", "run_dir=/tmp/unused"], plugin_manager=vqpae_pm)
    changed = {k for k in cfg.model if cfg.model[k] != default.model[k]}
    assert changed == set(PLUS_OPTIONS)
    for key, value in PLUS_OPTIONS.items():
        assert cfg.model[key] == value, key
        assert value != AUTHORS[key], f"{key} is the authors' value, not a change"
    assert cfg.data.pair_seconds == 0.1 and "pair_seconds" not in default.data  # 0: none


def test_schedule_equals_the_authors_scheduler() -> None:
    fixture = np.load(FIXTURE)
    cases = sorted(k for k in fixture.files if k.startswith("case"))
    assert cases
    for name in cases:
        c = name[4:]
        size, batch, period, mult, _, lr, wd = fixture[name].tolist()
        rates, decays = fixture[f"lr{c}"], fixture[f"weight_decay{c}"]
        param = torch.nn.Parameter(torch.zeros(1))
        optimizer = torch.optim.AdamW([param], lr=lr, weight_decay=wd)
        scheduler = CyclicRestarts(optimizer, int(size), int(batch), int(period), mult)
        for step in range(len(rates)):
            group = optimizer.param_groups[0]
            assert group["lr"] == pytest.approx(rates[step], rel=1e-6, abs=1e-15), (c, step)
            # (their fraction of the epoch is float32: torch.linspace)
            # torch's AdamW multiplies the decay by the rate; theirs does not
            assert group["lr"] * group["weight_decay"] == pytest.approx(
                decays[step], rel=1e-6, abs=1e-15
            ), (c, step)
            optimizer.step()
            scheduler.step()


def test_schedule_leaves_later_groups_alone_and_checks_its_arguments() -> None:
    a, b = torch.nn.Parameter(torch.zeros(1)), torch.nn.Parameter(torch.zeros(1))
    optimizer = torch.optim.AdamW(
        [
            {"params": [a], "lr": 1e-4, "weight_decay": 1e-4},
            {"params": [b], "lr": 1e-3, "weight_decay": 0.0},
        ]
    )
    scheduler = CyclicRestarts(optimizer, 64, 32, 1, 2, groups=1)
    for _ in range(2):
        optimizer.step()
        scheduler.step()
    assert optimizer.param_groups[0]["lr"] == pytest.approx(AUTHORS_MIN_LR)  # the restart step
    assert optimizer.param_groups[1]["lr"] == 1e-3
    assert optimizer.param_groups[1]["weight_decay"] == 0.0
    eta, length = cyclic_restart_factors(3, 64, 32, 1, 2)
    assert length == 2 and eta == pytest.approx(0.5 * (1 + math.cos(math.pi * 0.5 / 2)))
    with pytest.raises(SkelagnosticError, match="no batch"):
        cyclic_restart_factors(0, 16, 32, 1, 2)
    with pytest.raises(SkelagnosticError, match=r"model\.scheduler\.periodd is not an argument"):
        VqpaeAligner(
            scheduler={"_target_": "skelagnostic_vqpae.schedule.cosine_restarts", "periodd": 3}
        )
    with pytest.raises(SkelagnosticError, match=r"model\.scheduler\.period must be positive"):
        authors_restarts(torch.optim.AdamW([a], lr=1e-4), None, period=0)


def test_training_uses_the_authors_epoch(cache_dir: Path, tmp_path: Path, helpers: dict) -> None:
    """An epoch of the schedule is one pass over the smallest dataset, as in train_vq.py."""
    import lightning as L

    L.seed_everything(0, verbose=False)
    dm = helpers["datamodule"](cache_dir)
    model = VqpaeAligner(num_codes=8, kernel_size=7, pose_mlp="none")
    trainer = helpers["trainer"](tmp_path, 2, validate=False)
    trainer.fit(model, datamodule=dm)
    scheduler = trainer.lr_scheduler_configs[0].scheduler
    assert isinstance(scheduler, CyclicRestarts)
    assert scheduler.epoch_size == min(len(ds) for ds in dm.datasets["train"].values())
    assert scheduler.batch_size == dm.batch_size and scheduler.last_epoch == 2


def test_checkpoints_without_the_new_options_keep_their_previous_values(tmp_path: Path) -> None:
    """A checkpoint written before the defaults changed loads with the values it trained with."""
    specs = {"a": {"channels": 6, "window": 11, "fps": 10.0}}
    old = VqpaeAligner(num_codes=4, kernel_size=5, datasets=specs, **PREVIOUS_DEFAULTS)
    path = tmp_path / "old.ckpt"
    hparams = {k: v for k, v in old.hparams.items() if k not in PREVIOUS_DEFAULTS}
    torch.save(
        {
            "state_dict": old.state_dict(),
            "hyper_parameters": hparams,
            "pytorch-lightning_version": "2.4.0",
        },
        path,
    )
    loaded = VqpaeAligner.load_from_checkpoint(path, map_location="cpu", weights_only=True)
    for key, value in PREVIOUS_DEFAULTS.items():
        expected = 0.0 if key == "lambda_phase_rate" else value
        assert loaded.hparams[key] == expected, key
    x = torch.randn(3, 6, 11)
    old.eval()
    torch.testing.assert_close(
        loaded.embed_windows(x, 0)["reconstruction"], old.embed_windows(x, 0)["reconstruction"]
    )


def test_noreinit_preset_is_the_cpu2h_run_without_reinitialisation(vqpae_pm) -> None:
    from skelagnostic.cli.app import compose

    base = compose(
        ["model=vqpae", "experiment=vqpae_cpu2h", "run_dir=/tmp/unused"], plugin_manager=vqpae_pm
    )
    ablation = compose(
        ["model=vqpae", "experiment=vqpae_cpu2h_noreinit", "run_dir=/tmp/unused"],
        plugin_manager=vqpae_pm,
    )
    assert base.model.reinit is True and ablation.model.reinit is False
    assert base.model.pose_mlp == "joint"  # the authors' average-pose MLPs (report section 25)
    assert base.run_checkpoint == "last"  # the cosine cycle's end is the model, not best val
    ablation.model.reinit = True
    assert ablation == base
