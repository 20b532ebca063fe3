"""Denoising must be denoising (issue #45, item 4): the figures of a Fig. 8 curve, recomputed."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from skelagnostic_humot.aligner import HumotAligner
from skelagnostic_humot.evaluation.reconstruction import (
    denoising_figures,
    mean_denoising_curve,
    reconstruction_protocol,
)
from torch import nn

import skelagnostic as sa
from script_loader import load_script
from skelagnostic.evaluation import EvaluationError, HeldOut

results = load_script("scripts/results.py", "results_script")

SIGMA = [0.0, 1.0, 2.0, 4.0, 6.0, 8.0, 10.0]
#: The committed humot_cpu2h entry's seen-topology curve (rounded): the output ignores the input.
NOISY = [0.0, 1.594, 3.195, 6.383, 9.563, 12.778, 15.988]
FLAT = [15.140, 15.140, 15.144, 15.162, 15.178, 15.238, 15.303]


def test_an_output_that_ignores_its_input_is_below_the_noise_only_at_the_top():
    fig = denoising_figures({"sigma_cm": SIGMA, "input_mpjpe_cm": NOISY, "output_mpjpe_cm": FLAT})
    # levels from 4 cm: 4, 6, 8, 10; the output (15.16-15.30) is below the input only at 10
    assert fig["model"]["below_noise_from_4cm"] == 0.25
    assert fig["model"]["growth_over_noise"] == pytest.approx((15.303 - 15.140) / 15.988)
    # the identity returns the noisy input: never below it, grows with it
    assert fig["identity"] == {"below_noise_from_4cm": 0.0, "growth_over_noise": 1.0}


def test_a_denoiser_meets_both_criteria_and_the_levels_may_come_in_any_order():
    out = [1.0 + 0.2 * e for e in NOISY]  # below the input from 1.25 cm of input error up
    order = [3, 0, 6, 1, 5, 2, 4]
    curve = {
        "sigma_cm": [SIGMA[i] for i in order],
        "input_mpjpe_cm": [NOISY[i] for i in order],
        "output_mpjpe_cm": [out[i] for i in order],
    }
    fig = denoising_figures(curve)
    assert fig["model"]["below_noise_from_4cm"] == 1.0
    assert fig["model"]["growth_over_noise"] == pytest.approx(0.2)
    six = denoising_figures(curve, from_sigma_cm=6.0)
    assert set(six["model"]) == {"below_noise_from_6cm", "growth_over_noise"}


def test_bad_curves_are_refused():
    curve = {"sigma_cm": [0, 1, 2], "input_mpjpe_cm": [0, 1.6, 3.2], "output_mpjpe_cm": [1] * 3}
    with pytest.raises(EvaluationError, match="no noise level reaches 4 cm"):
        denoising_figures(curve)
    with pytest.raises(EvaluationError, match="does not grow"):
        denoising_figures({**curve, "sigma_cm": [0, 4, 8], "input_mpjpe_cm": [0, 0, 0]})
    with pytest.raises(EvaluationError, match="differ in length"):
        denoising_figures({**curve, "output_mpjpe_cm": [1, 2]})
    with pytest.raises(EvaluationError, match="other noise levels"):
        mean_denoising_curve([curve, {**curve, "sigma_cm": [0, 2, 4]}])


def test_the_mean_curve_is_the_mean_of_the_groups():
    a = {"sigma_cm": SIGMA, "input_mpjpe_cm": NOISY, "output_mpjpe_cm": FLAT}
    b = {"sigma_cm": SIGMA, "input_mpjpe_cm": [2 * e for e in NOISY], "output_mpjpe_cm": NOISY}
    mean = mean_denoising_curve([a, b])
    assert mean["input_mpjpe_cm"] == pytest.approx([1.5 * e for e in NOISY])
    halfway = [(f + e) / 2 for f, e in zip(FLAT, NOISY, strict=True)]
    assert mean["output_mpjpe_cm"] == pytest.approx(halfway)


def _expected(curves: list[dict[str, list[float]]]) -> dict[str, dict[str, float]]:
    """The figures of the groups' mean curve, in numpy."""
    sigma = np.asarray(curves[0]["sigma_cm"])
    noisy = np.mean([c["input_mpjpe_cm"] for c in curves], axis=0)
    out = np.mean([c["output_mpjpe_cm"] for c in curves], axis=0)
    top = sigma >= 4
    growth = noisy[-1] - noisy[0]  # the protocol's levels are ascending
    return {
        "model": {
            "below_noise_from_4cm": float(np.mean(out[top] < noisy[top])),
            "growth_over_noise": float((out[-1] - out[0]) / growth),
        },
        "identity": {"below_noise_from_4cm": 0.0, "growth_over_noise": 1.0},
    }


class _Smoother(nn.Module):
    """A stand-in network: a 3-frame moving average of each joint (a real denoiser).

    An untrained HuMoT's output hardly depends on its input (a flat curve, figures
    0 and 0); this one gives a curve that rises with the noise, below it.
    """

    def forward(self, motion, source_template, target_template, mask=None):
        del source_template, mask
        b, f, j, _ = motion.shape
        if target_template.shape[1] != j:  # joint upsampling: the template pose
            return target_template[:, None].expand(b, f, -1, -1)
        padded = torch.cat([motion[:, :1], motion, motion[:, -1:]], dim=1)
        return (padded[:, :-2] + padded[:, 1:-1] + padded[:, 2:]) / 3


def test_reconstruction_protocol_reports_the_figures_of_its_curves(tmp_path, humot_small):
    """Procedural clips of two topologies; the network is a temporal smoother."""
    model = HumotAligner(**humot_small).eval()
    model.net = _Smoother()
    a = sa.procedural.generate("biped22", "walk", seconds=1.0, fps=30, seed=7)[0]
    b = sa.procedural.generate("biped17", "run", seconds=1.0, fps=30, seed=8)[0]
    a.name, b.name = "a", "b"
    with torch.no_grad():
        out = reconstruction_protocol(model, HeldOut("test", [a, b]), tmp_path)
    curves = {name: c["denoising"] for name, c in out.extra["curves"].items()}
    assert len(curves) == 2
    expected = _expected(list(curves.values()))
    # a 3-frame average divides independent noise by sqrt(3) (a little less at the ends)
    assert expected["model"]["below_noise_from_4cm"] == 1.0
    assert expected["model"]["growth_over_noise"] == pytest.approx(3**-0.5, abs=0.06)
    for method, figures in expected.items():
        assert out.extra["denoising"][method] == pytest.approx(figures, rel=1e-9)
    for name, curve in curves.items():
        for method, figures in _expected([curve]).items():
            assert out.extra["denoising_by_group"][name][method] == pytest.approx(figures)
    # the results page quotes them as method -> number, beside the identity
    quoted = results.quoted_figure("q", "extra.denoising.growth_over_noise", {"extra": out.extra})
    assert quoted == pytest.approx(
        {m: f["growth_over_noise"] for m, f in expected.items()}, rel=1e-9
    )
