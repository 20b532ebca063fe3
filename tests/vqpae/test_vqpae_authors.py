"""Parity with the WalkTheDog authors' code: their run loaded by ``authors.load_run``.

The fixture (tests/fixtures/walkthedog/) was written by running the authors'
``VQAE`` and quantiser (scripts/fixtures/walkthedog_parity.py): a run
directory in the layout of their ``train_vq.py`` and, for given normalised
windows, the outputs of their network in eval mode.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import torch
from skelagnostic_vqpae.aligner import VqpaeAligner
from skelagnostic_vqpae.authors import (
    authors_state_order,
    load_run,
    read_args,
    to_authors_state,
    vqae_key_map,
)

from skelagnostic.core.skeleton import Skeleton
from skelagnostic.errors import SkelagnosticError

FIXTURE = Path(__file__).resolve().parents[1] / "fixtures" / "walkthedog"
TOL = 1e-4


@pytest.fixture(scope="module")
def outputs() -> dict[str, np.ndarray]:
    with np.load(FIXTURE / "outputs.npz") as data:
        return dict(data)


@pytest.fixture(scope="module")
def model() -> VqpaeAligner:
    return load_run(FIXTURE / "run")


def test_run_loads_as_their_network(model: VqpaeAligner) -> None:
    assert model.dataset_names == ["human", "dog"]
    pae = model.characters[0].pae
    assert (pae.channels, pae.window, pae.latent) == (15, 31, 4)
    assert pae.phase_conv.kernel_size == (23,)
    assert pae.spectrum == "power" and pae.encoder[0].padding_mode == "zeros"
    assert model.codebook is not None and model.codebook.weight.shape == (8, 8)
    assert not model.training


@pytest.mark.parametrize("dataset", [0, 1])
def test_embed_windows_equals_the_authors_outputs(
    model: VqpaeAligner, outputs: dict[str, np.ndarray], dataset: int
) -> None:
    x = torch.from_numpy(outputs[f"x{dataset}"])
    ours = model.embed_windows(x, dataset)
    np.testing.assert_array_equal(ours["code"].numpy(), outputs[f"code{dataset}"])
    assert len(np.unique(outputs[f"code{dataset}"])) > 1  # the fixture exercises the codebook
    dphase = ours["phase"].numpy() - outputs[f"phase{dataset}"]
    assert np.abs(dphase - np.round(dphase)).max() < TOL  # circular difference, in cycles
    for key, theirs in (
        ("frequency", "frequency"),
        ("manifold", "manifold"),
        ("reconstruction", "reconstruction"),
    ):
        np.testing.assert_allclose(
            ours[key].numpy(), outputs[f"{theirs}{dataset}"], rtol=0, atol=TOL, err_msg=key
        )
    np.testing.assert_allclose(
        to_authors_state(ours["amplitude"]).numpy(), outputs[f"state{dataset}"], rtol=0, atol=TOL
    )


def test_embed_windows_takes_dataset_names_and_rejects_unknown_ones(
    model: VqpaeAligner, outputs: dict[str, np.ndarray]
) -> None:
    x = torch.from_numpy(outputs["x1"][:2])
    assert torch.equal(model.embed_windows(x, "dog")["code"], model.embed_windows(x, 1)["code"])
    with pytest.raises(SkelagnosticError, match="unknown dataset 'cat'"):
        model.embed_windows(x, "cat")
    with pytest.raises(SkelagnosticError, match="out of range"):
        model.embed_windows(x, 2)


def test_state_order_round_trips() -> None:
    theirs = torch.arange(8.0)
    ours = theirs[authors_state_order(4)]
    assert ours.tolist() == [1, 3, 5, 7, 0, 2, 4, 6]  # sine coefficients, then cosine ones
    assert torch.equal(to_authors_state(ours), theirs)


def test_key_map_covers_their_state_dict() -> None:
    state = torch.load(FIXTURE / "run" / "1_0_1Channels.pt", weights_only=True)
    assert set(vqae_key_map(7, 5)) == set(state) - {"tpi", "args"}


def _copy_run(tmp_path: Path) -> Path:
    run = tmp_path / "run"
    shutil.copytree(FIXTURE / "run", run)
    return run


def test_latest_complete_epoch_is_loaded(tmp_path: Path, outputs: dict[str, np.ndarray]) -> None:
    run = _copy_run(tmp_path)
    for i in (0, 1):
        shutil.copy(run / f"1_{i}_1Channels.pt", run / f"3_{i}_1Channels.pt")
    shutil.copy(run / "1_1Channels_VQ.pt", run / "3_1Channels_VQ.pt")
    shutil.copy(run / "1_0_1Channels.pt", run / "4_0_1Channels.pt")  # epoch 4 is incomplete
    shutil.copy(run / "1_1Channels_VQ.pt", run / "4_1Channels_VQ.pt")
    state = torch.load(run / "3_1Channels_VQ.pt", weights_only=True)
    state["vqs.0.embedding.weight"] = state["vqs.0.embedding.weight"].flip(0)
    torch.save(state, run / "3_1Channels_VQ.pt")
    codes = load_run(run).embed_windows(torch.from_numpy(outputs["x0"]), 0)["code"].numpy()
    np.testing.assert_array_equal(codes, 7 - outputs["code0"])


KEY = "freq_fc.layers.3.weight"


def _narrow(state: dict[str, torch.Tensor]) -> None:
    state[KEY] = state[KEY][:, :4]


def _drop(state: dict[str, torch.Tensor]) -> None:
    del state[KEY]


def _extra(state: dict[str, torch.Tensor]) -> None:
    state["extra.weight"] = torch.zeros(1)


def _flat_grid(state: dict[str, torch.Tensor]) -> None:
    state["args"] = torch.zeros_like(state["args"])


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (_narrow, r"1_1_1Channels\.pt: 'freq_fc\.layers\.3\.weight' has shape \[16, 4\]"),
        (_drop, r"1_1_1Channels\.pt has no key 'freq_fc\.layers\.3\.weight'"),
        (_extra, r"1_1_1Channels\.pt has unexpected keys \['extra\.weight'\]"),
        (_flat_grid, r"1_1_1Channels\.pt: 'args' \(the time grid\) must increase"),
    ],
)
def test_errors_name_the_file_and_key(
    tmp_path: Path, edit: Callable[[dict[str, torch.Tensor]], None], message: str
) -> None:
    run = _copy_run(tmp_path)
    path = run / "1_1_1Channels.pt"
    state = torch.load(path, weights_only=True)
    edit(state)
    torch.save(state, path)
    with pytest.raises(SkelagnosticError, match=message):
        load_run(run)


def test_missing_files_and_unsupported_options(tmp_path: Path) -> None:
    run = _copy_run(tmp_path)
    (run / "1_1Channels_VQ.pt").unlink()
    with pytest.raises(SkelagnosticError, match="no complete epoch"):
        load_run(run)
    with pytest.raises(SkelagnosticError, match=r"1_1Channels_VQ\.pt not found"):
        load_run(run, epoch=1)
    args = run / "args.txt"
    args.write_text(args.read_text().replace("--use_vq=1", "--use_vq=2"))
    with pytest.raises(SkelagnosticError, match=r"args\.txt: --use_vq=2 is not supported"):
        load_run(run)
    with pytest.raises(SkelagnosticError, match="not a directory"):
        load_run(tmp_path / "nowhere")
    assert read_args(args)["load"] == "Datasets/human,Datasets/dog"


def test_a_run_without_skeletons_says_so(model: VqpaeAligner) -> None:
    skeleton = Skeleton(["hips", "head"], [-1, 0], [[0.0, 0.0, 0.0], [0.0, 0.5, 0.0]])
    with pytest.raises(SkelagnosticError, match="no trained dataset has the topology"):
        model.dataset_of(skeleton)


def test_rebuilds_from_its_hyperparameters(
    model: VqpaeAligner, outputs: dict[str, np.ndarray]
) -> None:
    """What a Lightning checkpoint of the loaded aligner stores is enough to rebuild it."""
    again = VqpaeAligner(**model.hparams)
    again.load_state_dict(model.state_dict())
    x = torch.from_numpy(outputs["x1"])
    ours, theirs = again.eval().embed_windows(x, 1), model.embed_windows(x, 1)
    for key in ("phase", "frequency", "code", "amplitude", "reconstruction"):
        assert torch.allclose(ours[key].double(), theirs[key].double(), rtol=0, atol=1e-6), key
