"""Parity with the WalkTheDog authors' code: their run loaded by ``authors.load_run``.

The fixture (tests/fixtures/walkthedog/) was written by running the authors'
``VQAE`` and quantiser (scripts/fixtures/walkthedog_parity.py): a run
directory in the layout of their ``train_vq.py`` and, for given normalised
windows, the outputs of their network in eval mode.
"""

from __future__ import annotations

import json
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
    phase_decoder_files,
    read_args,
    to_authors_state,
    vqae_key_map,
)

from skelagnostic.core.motion import Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.errors import SkelagnosticError
from skelagnostic.io.bvh import read_bvh, write_bvh

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


# ---------------------------------------------------------------- phase decoders


@pytest.mark.parametrize("dataset", [0, 1])
def test_phase_decoders_equal_the_authors_outputs(
    model: VqpaeAligner, outputs: dict[str, np.ndarray], dataset: int
) -> None:
    points = torch.from_numpy(outputs[f"manifold{dataset}"])
    ours = model.average_pose(points, dataset).numpy()
    np.testing.assert_allclose(ours, outputs[f"pose{dataset}"], rtol=0, atol=TOL)
    spec = model.hparams["datasets"][model.dataset_names[dataset]]
    assert spec["pose_channels"] == outputs[f"pose{dataset}"].shape[1]
    assert spec["pose_features"] == ["Velocities", "Positions", "Rotations"]
    assert model.hparams["pose_mlp"] == "joint" and model.hparams["pose_layers"] == 3


def test_phase_decoder_files_follow_their_dataset_names(tmp_path: Path) -> None:
    run = _copy_run(tmp_path)
    assert {k: v.name for k, v in phase_decoder_files(run, 1).items()} == {
        "Datasets/human": "human_0000_Channels.pt",
        "Datasets/dog": "dog_0000_Channels.pt",
    }
    assert phase_decoder_files(run, 2) == {}
    (run / "human_0000_Channels.pt").unlink()
    (run / "dog_0000_Channels.pt").unlink()
    plain = load_run(run)
    assert plain.hparams["pose_mlp"] == "none"
    with pytest.raises(SkelagnosticError, match="not trained"):
        plain.average_pose(torch.zeros(1, 4), 0)


def test_the_authors_decoder_is_not_a_pose_for_decode(tmp_path: Path) -> None:
    run = _with_characters(tmp_path)
    loaded = load_run(run)
    human = read_bvh(run / "human.bvh")
    with pytest.raises(SkelagnosticError, match="their exporter's features"):
        loaded.decode(loaded.encode(human), human.skeleton)
    assert all(not g.name.startswith("pose_decoder") for g in loaded.export_graphs())


def test_an_unsupported_decoder_activation_is_named(tmp_path: Path) -> None:
    run = _copy_run(tmp_path)
    args = run / "args.txt"
    args.write_text(
        args.read_text().replace(
            "--activation_phase_decoder=LeakyReLU", "--activation_phase_decoder=ELU"
        )
    )
    with pytest.raises(SkelagnosticError, match="--activation_phase_decoder=ELU"):
        load_run(run)


# ------------------------------------------------- skeletons, normalisation, the CLI


def _chain(joints: int, fps: float, frames: int, seed: int) -> Motion:
    """A walking chain of ``joints`` joints with smooth periodic rotations."""
    names = [f"j{i}" for i in range(joints)]
    offsets = [[0.0, 0.0, 0.0]] + [[0.0, 0.2, 0.05 * i] for i in range(1, joints)]
    skeleton = Skeleton(names, [-1, *range(joints - 1)], offsets)
    t = torch.arange(frames, dtype=torch.float64) / fps
    g = torch.Generator().manual_seed(seed)
    phase = torch.rand(joints, generator=g, dtype=torch.float64)
    angle = 0.4 * torch.sin(2 * torch.pi * (1.5 * t[:, None] + phase))
    rotations = torch.zeros(frames, joints, 4, dtype=torch.float64)
    rotations[..., 0], rotations[..., 1] = torch.cos(angle / 2), torch.sin(angle / 2)
    root = torch.stack([torch.zeros_like(t), torch.full_like(t, 1.0), 1.2 * t], dim=1)
    return Motion(skeleton, rotations, root, fps)


def _with_characters(tmp_path: Path) -> Path:
    """The fixture run with ``human.bvh`` (5 joints), ``dog.bvh`` (4) and their statistics."""
    run = _copy_run(tmp_path)
    for name, joints, seed in (("human", 5, 0), ("dog", 4, 1)):
        write_bvh(_chain(joints, 30.0, 90, seed), run / f"{name}.bvh")
        np.savez(
            run / f"{name}_normalization.npz",
            mean=np.zeros(3 * joints),
            std=np.full(3 * joints, 0.5),
        )
    return run


def test_skeletons_and_normalisation_from_the_run_directory(tmp_path: Path) -> None:
    run = _with_characters(tmp_path)
    loaded = load_run(run)
    human, dog = read_bvh(run / "human.bvh"), read_bvh(run / "dog.bvh")
    assert loaded.dataset_of(human.skeleton) == 0 and loaded.dataset_of(dog.skeleton) == 1
    assert torch.equal(loaded.characters[1].input_std, torch.full((12,), 0.5))
    latent = loaded.encode(human)
    assert latent.z.shape == (90, 4) and latent.fps == 30.0
    (run / "dog_normalization.npz").unlink()
    with pytest.raises(SkelagnosticError, match=r"dog_normalization\.npz is missing"):
        load_run(run)
    write_bvh(_chain(3, 30.0, 10, 0), run / "dog.bvh")
    with pytest.raises(SkelagnosticError, match=r"dog\.bvh has 3 joints"):
        load_run(run)


def test_cli_transfer_and_load_aligner_read_authors_runs(tmp_path: Path, vqpae_cli) -> None:
    from skelagnostic.plugins import load_aligner

    run = _with_characters(tmp_path)
    source = tmp_path / "walk.bvh"
    write_bvh(_chain(5, 30.0, 120, 2), source)
    target = tmp_path / "dog_walk.bvh"  # the fixture's dog runs at 0.2 Hz: 15 s of it
    write_bvh(_chain(4, 30.0, 450, 3), target)
    out = tmp_path / "out.bvh"
    code = vqpae_cli(["transfer", str(source), str(target), f"ckpt=authors:{run}", f"out={out}"])
    assert code == 0
    result = read_bvh(out)
    assert result.skeleton.num_joints == 4 and result.num_frames > 0
    aligner = load_aligner("vqpae", f"authors:{run}")
    assert aligner.dataset_names == ["human", "dog"] and not aligner.training
    with pytest.raises(SkelagnosticError, match="no checkpoint reader 'nosuch'"):
        load_aligner("vqpae", f"nosuch:{run}")
    with pytest.raises(SkelagnosticError, match="takes no hyperparameter overrides"):
        load_aligner("vqpae", f"authors:{run}", lr=1.0)


def test_cli_evaluate_reads_an_authors_run(tmp_path: Path, vqpae_cli, capsys) -> None:
    """``evaluate ckpt_path=authors:<dir>`` runs a protocol on the held-out clips of data=."""
    run = _with_characters(tmp_path)
    clips = tmp_path / "clips"
    clips.mkdir()
    for k in range(5):
        write_bvh(_chain(5, 30.0, 90, 10 + k), clips / f"human_{k}.bvh")
        write_bvh(_chain(4, 30.0, 90, 20 + k), clips / f"dog_{k}.bvh")
    code = vqpae_cli(
        [
            "evaluate",
            f"ckpt_path=authors:{run}",
            "data=bvh",
            f"data.paths=[{clips}]",
            "data.fps=30",
            "protocol=vqpae.manifold",
            f"run_dir={tmp_path / 'eval'}",
        ]
    )
    err = capsys.readouterr().err
    assert code == 0, err
    report = json.loads((tmp_path / "eval" / "evaluation.json").read_text())
    # the data module's datasets ("bvh/...") are not the run's characters: no training codes
    assert "codes_shared_training" not in report["extra"]["table2"]
    assert any(n.startswith("codes_shared_training") and "omitted" in n for n in report["notes"])
    code = vqpae_cli(
        [
            "validate",
            f"ckpt_path=authors:{run}",
            "data=bvh",
            f"data.paths=[{clips}]",
            f"run_dir={tmp_path / 'val'}",
        ]
    )
    assert code == 1 and "read by evaluate and the inference verbs" in capsys.readouterr().err
