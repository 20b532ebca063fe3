"""``model.optimizer`` and ``model.scheduler``: ``_partial_`` specs, resolved without Hydra."""

from __future__ import annotations

import functools
import importlib
import math
import sys
from pathlib import Path
from typing import Any

import pytest
import torch

from skelagnostic.aligners.optim import (
    check_specs,
    configure_optimization,
    cosine_lr,
    cyclic_lr,
    linear_warmup,
    resolve,
)
from skelagnostic.errors import SkelagnosticError

REPO = Path(__file__).resolve().parents[2]
ADAM = {"_target_": "torch.optim.Adam", "_partial_": True, "lr": 0.01}


def _params() -> list[torch.nn.Parameter]:
    return [torch.nn.Parameter(torch.zeros(3))]


def _rates(scheduler: Any, optimizer: torch.optim.Optimizer, steps: int) -> list[float]:
    rates = []
    for _ in range(steps):
        rates.append(optimizer.param_groups[0]["lr"])
        optimizer.step()
        scheduler.step()
    return rates


def test_a_spec_becomes_the_optimizer_it_names() -> None:
    opt = resolve({**ADAM, "betas": [0.5, 0.9]}, "model.optimizer", "params")(_params())
    assert isinstance(opt, torch.optim.Adam)
    assert opt.defaults["lr"] == 0.01 and tuple(opt.defaults["betas"]) == (0.5, 0.9)
    # a callable passes as it is, and _partial_ may be left out
    same = functools.partial(torch.optim.SGD, lr=0.3)
    assert resolve(same, "model.optimizer", "params") is same
    sgd = resolve({"_target_": "torch.optim.SGD", "lr": 0.3}, "f", "params")(_params())
    assert isinstance(sgd, torch.optim.SGD)


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ({"lr": 1}, r"model\.optimizer must be a mapping with _target_"),
        (3, r"model\.optimizer must be a mapping with _target_"),
        ({**ADAM, "_partial_": False}, r"model\.optimizer\._partial_=False: it must be true"),
        ({"_target_": "Adam"}, r"model\.optimizer\._target_='Adam' is not a dotted path"),
        ({"_target_": "torch.optim.Adamm"}, r"'torch\.optim\.Adamm': torch\.optim has no 'Adamm'"),
        ({"_target_": "nosuchpkg.Adam"}, r"'nosuchpkg\.Adam': cannot import it"),
        ({"_target_": "math.pi"}, r"'math\.pi' is not callable"),
        ({**ADAM, "lrr": 1}, r"model\.optimizer\.lrr is not an argument of torch\.optim\.Adam"),
        ({**ADAM, "params": []}, r"model\.optimizer\.params is not an argument"),
    ],
)
def test_bad_specs_name_the_key(spec: Any, message: str) -> None:
    with pytest.raises(SkelagnosticError, match=message):
        resolve(spec, "model.optimizer", "params")


def test_a_nested_target_is_found() -> None:
    make = resolve(
        {"_target_": "torch.optim.lr_scheduler.StepLR", "step_size": 2}, "s", "optimizer"
    )
    opt = torch.optim.SGD(_params(), lr=1.0)
    assert isinstance(make(opt), torch.optim.lr_scheduler.StepLR)


def test_check_specs_copies_to_plain_data() -> None:
    from types import MappingProxyType

    optimizer, scheduler = check_specs(MappingProxyType({**ADAM, "betas": (0.5, 0.9)}), None)
    assert optimizer == {**ADAM, "betas": [0.5, 0.9]} and type(optimizer) is dict
    assert scheduler is None


def test_configure_passes_the_run_quantities_a_schedule_names() -> None:
    seen: dict[str, Any] = {}

    def schedule(optimizer: Any, steps_per_epoch: int, total_steps: int, trainer: Any) -> Any:
        seen.update(steps_per_epoch=steps_per_epoch, total_steps=total_steps, trainer=trainer)
        return torch.optim.lr_scheduler.LambdaLR(optimizer, lambda s: 1.0)

    class Trainer:  # what the quantities are read from
        estimated_stepping_batches = 40
        accumulate_grad_batches = 1
        num_training_batches = 8
        max_epochs = 5

    trainer = Trainer()
    out = configure_optimization(ADAM, schedule, _params(), trainer)
    assert seen == {"steps_per_epoch": 8, "total_steps": 40, "trainer": trainer}
    assert out["lr_scheduler"]["interval"] == "step"
    assert configure_optimization(ADAM, None, _params()).__class__ is torch.optim.Adam


def test_preferred_arguments_only_where_taken_and_not_set() -> None:
    opt = configure_optimization(ADAM, None, _params(), prefer={"foreach": True, "nope": 1})
    assert opt.defaults["foreach"] is True
    chosen = configure_optimization(
        {**ADAM, "foreach": False}, None, _params(), prefer={"foreach": True}
    )
    assert chosen.defaults["foreach"] is False


def test_cyclic_lr_is_the_triangle_between_lr_and_max_lr() -> None:
    opt = torch.optim.Adam(_params(), lr=1e-5)
    rates = _rates(cyclic_lr(opt, max_lr=1e-4, period_epochs=2, steps_per_epoch=5), opt, 11)
    assert rates[0] == pytest.approx(1e-5) and rates[10] == pytest.approx(1e-5)
    assert rates[5] == pytest.approx(1e-4) and max(rates) == rates[5]  # half period: 1 epoch
    assert rates[2] == pytest.approx(1e-5 + 0.4 * 9e-5)
    with pytest.raises(SkelagnosticError, match=r"model\.optimizer\.lr=0\.001 must be in"):
        cyclic_lr(torch.optim.Adam(_params(), lr=1e-3), max_lr=1e-4, period_epochs=2)
    with pytest.raises(SkelagnosticError, match=r"model\.scheduler\.period_epochs must be > 0"):
        cyclic_lr(opt, max_lr=1e-4, period_epochs=0)


def test_linear_warmup_then_constant() -> None:
    opt = torch.optim.AdamW(_params(), lr=0.4)
    rates = _rates(linear_warmup(opt, 4), opt, 6)
    assert rates == pytest.approx([0.1, 0.2, 0.3, 0.4, 0.4, 0.4])
    opt = torch.optim.AdamW(_params(), lr=0.4)
    assert _rates(linear_warmup(opt, 0), opt, 2) == pytest.approx([0.4, 0.4])
    with pytest.raises(SkelagnosticError, match=r"model\.scheduler\.steps must be >= 0"):
        linear_warmup(opt, -1)


def test_cosine_lr_ends_at_min_lr() -> None:
    opt = torch.optim.SGD(_params(), lr=1.0)
    rates = _rates(cosine_lr(opt, total_steps=4, min_lr=0.2), opt, 5)
    expected = [0.2 + 0.8 * (1 + math.cos(math.pi * s / 4)) / 2 for s in range(5)]
    assert rates == pytest.approx(expected)


# ---------------------------------------------------------- every built-in aligner
def _aligner(name: str) -> type:
    module, cls = {
        "humot": ("skelagnostic_humot.aligner", "HumotAligner"),
        "pcmrl": ("skelagnostic_pcmrl.recon.aligner", "PcmrlReconAligner"),
        "pcmrl_interp": ("skelagnostic_pcmrl.interp.aligner", "PcmrlInterpAligner"),
        "example": ("skelagnostic_example.aligner", "ExampleAligner"),
        "vqpae": ("skelagnostic_vqpae.aligner", "VqpaeAligner"),
    }[name]
    for folder in ("humot", "pcmrl", "example-aligner", "vqpae"):
        path = str(REPO / "plugins" / folder / "src")
        if path not in sys.path:
            sys.path.append(path)
    return getattr(importlib.import_module(module), cls)


@pytest.mark.parametrize(
    ("name", "options"),
    [
        ("humot", {"dim": 16, "latent": 8, "blocks": 1, "heads": 2, "kernel_size": 3}),
        (
            "pcmrl_interp",
            {"dim": 16, "heads": 2, "layers": 1, "ff_mult": 2, "max_relative": 8, "fps": 30.0},
        ),
        ("example", {"hidden": 8, "latent": 4}),
        ("pcmrl", {"dim": 16, "temporal_dim": 32}),
        ("vqpae", {"datasets": {"a": {"channels": 6, "window": 11, "fps": 10.0}}}),
    ],
)
def test_model_optimizer_lr_is_the_initial_rate_of_every_aligner(name: str, options: dict) -> None:
    cls = _aligner(name)
    if name == "pcmrl_interp":  # its network needs the skeleton
        from skelagnostic import procedural

        options["skeleton"] = procedural.skeleton("biped31").to_dict()
    model = cls(**options, optimizer={**cls().hparams.optimizer, "lr": 3e-5})
    out = model.configure_optimizers()
    optimizer = out["optimizer"] if isinstance(out, dict) else out
    rate = optimizer.param_groups[0]["lr"]
    if name == "pcmrl_interp":  # the warm-up's first step is lr / steps
        rate *= model.hparams.scheduler["steps"]
    assert rate == pytest.approx(3e-5)
