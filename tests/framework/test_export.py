"""``skelagnostic export`` and ``Aligner.export_graphs``: ONNX / TorchScript match PyTorch.

Every built-in aligner (and the example plugin) is built small, exported, and the
exported files are run (ONNX in onnxruntime, TorchScript with ``torch.jit.load``)
on windows cut from real clips at two batch/time sizes; the outputs must match
the aligner's own PyTorch methods within 1e-4. ``format=safetensors`` weights of a
trained run load back (``ckpt=``) to equal outputs (its errors:
``test_export_safetensors.py``).
"""

from __future__ import annotations

import json
import logging
import os
import stat
import sys
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

import skelagnostic as sa
from skelagnostic import cli
from skelagnostic.aligners.export import ExportError, export_aligner
from skelagnostic.aligners.weights import WEIGHTS_FILE
from skelagnostic.cli.app import ConfigError

ort = pytest.importorskip("onnxruntime")

REPO = Path(__file__).resolve().parents[2]
EXAMPLE_SRC = REPO / "plugins" / "example-aligner" / "src"
TOL = 1e-4
FAST = [
    "experiment=smoke",
    "data.seconds=2.0",
    "data.clips_per_gait=1",
    "data.window=16",
    "data.stride=8",
    "model.hidden=16",
    "model.latent=4",
    "trainer.max_epochs=1",
]

pytestmark = pytest.mark.slow


# ----------------------------------------------------------------------------- helpers
def run_file(path: Path, names: Sequence[str], inputs: Sequence[torch.Tensor]) -> list[np.ndarray]:
    """Run an exported file: ONNX in onnxruntime, TorchScript with torch.jit.load."""
    if path.suffix == ".onnx":
        session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
        assert [i.name for i in session.get_inputs()] == list(names)
        return session.run(None, {n: t.numpy() for n, t in zip(names, inputs, strict=True)})
    module = torch.jit.load(str(path))
    with torch.no_grad():
        out = module(*inputs)
    return [o.numpy() for o in (out if isinstance(out, tuple) else (out,))]


def assert_matches(
    got: Sequence[np.ndarray], want: Sequence[torch.Tensor], names: Sequence[str]
) -> None:
    assert len(got) == len(want)
    for name, g, w in zip(names, got, want, strict=True):
        w = w.detach().numpy()
        assert g.shape == w.shape, (name, g.shape, w.shape)
        if np.issubdtype(w.dtype, np.integer):
            assert np.array_equal(g, w), name
        else:
            err = float(np.abs(g - w).max())
            assert err <= TOL, f"{name}: max error {err:.3g}"


def check_sidecar(path: Path, fmt: str, inputs: Sequence[str], outputs: Sequence[str]) -> dict:
    meta = json.loads(path.read_text())
    assert meta["format"] == fmt
    assert (path.parent / meta["file"]).is_file()
    assert [i["name"] for i in meta["inputs"]] == list(inputs)
    assert [o["name"] for o in meta["outputs"]] == list(outputs)
    return meta


Case = Callable[[int, int], tuple[tuple[torch.Tensor, ...], tuple[torch.Tensor, ...]]]


def check_graph(
    out_dir: Path,
    name: str,
    fmt: str,
    inputs: Sequence[str],
    outputs: Sequence[str],
    case: Case,
    sizes: Sequence[tuple[int, int]],
) -> dict:
    """Exported graph ``name`` against PyTorch on ``case(batch, time)`` for each size."""
    meta = check_sidecar(out_dir / f"{name}.json", fmt, inputs, outputs)
    if fmt == "onnx":  # the file's interface is the sidecar's, dynamic axes by their labels
        session = ort.InferenceSession(
            str(out_dir / meta["file"]), providers=["CPUExecutionProvider"]
        )
        assert [o.shape for o in session.get_outputs()] == [o["shape"] for o in meta["outputs"]]
        assert [i.shape for i in session.get_inputs()] == [i["shape"] for i in meta["inputs"]]
    for batch, frames in sizes:
        args, want = case(batch, frames)
        assert_matches(run_file(out_dir / meta["file"], inputs, args), want, outputs)
    return meta


@pytest.fixture(scope="module")
def lafan(lafan_clip: Path) -> sa.Motion:
    return sa.read_bvh(lafan_clip)


def windows(x: torch.Tensor, batch: int, frames: int, step: int = 37) -> torch.Tensor:
    """``batch`` windows of ``frames`` frames of ``x [F, ...]``, starting ``step`` apart."""
    return torch.stack([x[i * step : i * step + frames] for i in range(batch)])


# ----------------------------------------------------------------------------- example
@pytest.fixture(scope="module")
def example_run(
    tmp_path_factory: pytest.TempPathFactory, fit_example: Callable[[Path, Sequence[str]], Path]
) -> Path:
    """A run of the example aligner trained for one tiny epoch on procedural motion."""
    return fit_example(tmp_path_factory.mktemp("export"), FAST)


@pytest.mark.parametrize("fmt", ["onnx", "torchscript"])
def test_example_exported_by_the_cli_matches_pytorch(
    example_plugin: Path,
    example_run: Path,
    lafan: sa.Motion,
    fmt: str,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from skelagnostic.cli.infer import load_from_checkpoint
    from skelagnostic.representations import GlobalPositions

    ckpt = example_run / "checkpoints" / "last.ckpt"
    out = tmp_path / fmt
    monkeypatch.setenv("EXPORT_OUT", str(tmp_path))  # path options expand $VARS
    before = torch.get_num_threads()
    try:
        code = cli.main(
            ["export", f"ckpt_path={ckpt}", f"format={fmt}", f"out=$EXPORT_OUT/{fmt}", "threads=1"]
        )
        assert code == 0, capsys.readouterr().err
        assert torch.get_num_threads() == 1
    finally:
        torch.set_num_threads(before)
    printed = capsys.readouterr().out.split()
    suffix = ".onnx" if fmt == "onnx" else ".pt"
    assert sorted(Path(p).name for p in printed) == sorted(
        ["encoder" + suffix, "encoder.json", "decoder" + suffix, "decoder.json"]
    )
    aligner = load_from_checkpoint(ckpt)  # model name from the run's config.yaml
    height = lafan.skeleton.height()
    positions = GlobalPositions(frame="root").encode(lafan).float() / height
    template = lafan.skeleton.template().float() / height
    other = sa.procedural.skeleton("quadruped")  # decoding onto another joint count
    other_template = other.template().float() / other.height()

    def encoder(batch: int, frames: int) -> Any:
        x, t = windows(positions, batch, frames), template.expand(batch, -1, -1)
        with torch.no_grad():
            return (x, t), (aligner.encode_positions(x, t),)

    def decoder(batch: int, frames: int) -> Any:
        _, (z,) = encoder(batch, frames)
        t = other_template.expand(batch, -1, -1)
        with torch.no_grad():
            return (z, t), (aligner.decode_positions(z, t),)

    sizes = [(2, 24), (3, 41), (1, 17)]
    meta = check_graph(out, "encoder", fmt, ["positions", "template"], ["z"], encoder, sizes)
    assert meta["inputs"][0]["shape"] == ["batch", "time", "joints", 3]
    assert meta["aligner"] == "example"
    check_graph(out, "decoder", fmt, ["z", "template"], ["positions"], decoder, sizes)


def test_onnx_export_prints_its_files_only_and_keeps_the_umask(
    example_plugin: Path, example_run: Path, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    # issue 48, item 8: 8 "torchvision is not installed" lines, a FutureWarning and
    # UserWarnings around the file names, and files of mode 0600 (others are 0644)
    ckpt = example_run / "checkpoints" / "last.ckpt"
    records: list[logging.LogRecord] = []
    handler = logging.Handler()
    handler.emit = records.append  # type: ignore[method-assign]
    torch_log = logging.getLogger("torch.onnx._internal.exporter._registration")
    torch_log.addHandler(handler)
    before, old = torch.get_num_threads(), os.umask(0o022)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            args = [
                "export",
                f"ckpt_path={ckpt}",
                "format=onnx",
                f"out={tmp_path / 'o'}",
                "threads=1",
            ]
            assert cli.main(args) == 0
    finally:
        torch_log.removeHandler(handler)
        os.umask(old)
        torch.set_num_threads(before)
    out, err = capfd.readouterr()
    assert "torchvision" not in err and "Warning" not in err, err
    assert not [r.getMessage() for r in records if "torchvision" in r.getMessage()]
    noise = [
        str(w.message)
        for w in caught
        if "LeafSpec" in str(w.message) or "axis name" in str(w.message)
    ]
    assert noise == []
    files = [Path(line) for line in out.split()]
    assert sorted(p.name for p in files) == [
        "decoder.json",
        "decoder.onnx",
        "encoder.json",
        "encoder.onnx",
    ]
    assert {stat.S_IMODE(p.stat().st_mode) for p in files} == {0o644}
    assert sorted((tmp_path / "o").iterdir()) == sorted(files)  # no temporary file left


def test_export_errors_are_one_line(
    example_plugin: Path,
    example_run: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    ckpt = example_run / "checkpoints" / "last.ckpt"
    assert cli.main(["export", "--help"]) == 0
    assert "format=onnx|torchscript" in capsys.readouterr().out
    assert cli.main(["export", f"ckpt_path={ckpt}", "format=tflite"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "format='tflite'" in err and "onnx, torchscript" in err
    assert cli.main(["export", "format=onnx"]) == 2
    assert "missing option ckpt_path=" in capsys.readouterr().err
    assert cli.main(["export", f"ckpt_path={ckpt}", "format=onnx", "threads=zero"]) == 2
    assert "option threads='zero': must be a positive integer" in capsys.readouterr().err
    monkeypatch.setitem(sys.modules, "onnxscript", None)  # as if not installed
    out = tmp_path / "out"
    assert cli.main(["export", f"ckpt_path={ckpt}", "format=onnx", f"out={out}"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "onnxscript" in err and "skelagnostic[export]" in err
    assert not out.exists()


def test_an_aligner_without_graphs_exports_nothing(example_plugin: Path, tmp_path: Path) -> None:
    from skelagnostic_example.aligner import ExampleAligner

    from skelagnostic.aligners import Aligner

    class Opaque(ExampleAligner):
        def export_graphs(self) -> list:
            return Aligner.export_graphs(self)  # the base class default

    out = tmp_path / "out"
    with pytest.raises(ExportError, match="Opaque exports no networks"):
        export_aligner(Opaque(hidden=8, latent=4), "onnx", out)
    assert not out.exists()


# ------------------------------------------------------------------------ safetensors
def outputs(aligner: torch.nn.Module, motion: sa.Motion) -> tuple[torch.Tensor, torch.Tensor]:
    """The example aligner's latent of ``motion`` and its decoding onto a quadruped."""
    from skelagnostic.representations import GlobalPositions

    height = motion.skeleton.height()
    positions = (GlobalPositions(frame="root").encode(motion).float() / height)[None]
    template = (motion.skeleton.template().float() / height)[None]
    other = sa.procedural.skeleton("quadruped")
    with torch.no_grad():
        z = aligner.encode_positions(positions, template)
        back = aligner.decode_positions(z, (other.template().float() / other.height())[None])
    return z, back


def test_export_then_load_back_gives_equal_outputs(
    example_plugin: Path,
    example_run: Path,
    lafan: sa.Motion,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    from skelagnostic.cli.infer import load_from_checkpoint

    st = pytest.importorskip("safetensors.torch")
    ckpt = example_run / "checkpoints" / "last.ckpt"
    out = tmp_path / "weights"
    assert cli.main(["export", f"ckpt={ckpt}", "format=safetensors", f"out={out}"]) == 0
    assert capsys.readouterr().out.split() == [str(out / WEIGHTS_FILE), str(out / "config.yaml")]
    assert sorted(p.name for p in out.iterdir()) == ["config.yaml", WEIGHTS_FILE]  # no temp file
    beside = OmegaConf.load(out / "config.yaml")  # the run's model and data nodes
    assert beside.model.name == "example" and beside.model.hidden == 16
    assert beside.data == OmegaConf.load(example_run / "config.yaml").data
    with st.safe_open(str(out / WEIGHTS_FILE), framework="pt") as handle:
        meta = handle.metadata()
    assert meta["model"] == "example"
    config = json.loads(meta["model_config"])  # the model config the run resolved
    assert (config["hidden"], config["latent"]) == (16, 4)

    original = load_from_checkpoint(ckpt)
    want = outputs(original, lafan)
    for where in (out, out / WEIGHTS_FILE):  # ckpt=<dir or file>; the model from the file
        loaded = load_from_checkpoint(where)
        assert type(loaded) is type(original) and not loaded.training
        for got, expected in zip(outputs(loaded, lafan), want, strict=True):
            assert torch.equal(got, expected)
    loaded = sa.load_aligner("example", checkpoint=out)
    for got, expected in zip(outputs(loaded, lafan), want, strict=True):
        assert torch.equal(got, expected)
    for key, value in original.state_dict().items():
        assert torch.equal(loaded.state_dict()[key], value), key


def test_evaluate_accepts_a_weights_file(
    example_plugin: Path,
    example_run: Path,
    tmp_path: Path,
    fit_example: Callable[..., Path],
) -> None:
    from skelagnostic.cli.infer import load_from_checkpoint

    file = export_aligner(
        load_from_checkpoint(example_run / "checkpoints" / "last.ckpt"),
        "safetensors",
        tmp_path / "w",
        "example",
    )[0]
    run = fit_example(tmp_path, [*FAST, f"ckpt_path={file.parent}"], task="evaluate")
    assert any(run.glob("*.json")), sorted(p.name for p in run.iterdir())
    # the Trainer verbs need a Lightning checkpoint (loop states, the data's statistics)
    with pytest.raises(ConfigError, match=r"weights file .*validate needs a run's Lightning"):
        fit_example(tmp_path, [*FAST, f"ckpt_path={file}"], task="validate")


# ------------------------------------------------------------------------------ HuMoT
@pytest.mark.parametrize("fmt", ["onnx", "torchscript"])
def test_humot_encoder_and_decoder_match_pytorch(
    lafan: sa.Motion, fmt: str, tmp_path: Path
) -> None:
    from skelagnostic_humot.aligner import HumotAligner, infer_units
    from skelagnostic_humot.data import prepare_chunks

    from skelagnostic.core.motion import UNITS

    torch.manual_seed(0)
    aligner = HumotAligner(dim=32, latent=16, blocks=1, heads=4).eval()
    export_aligner(aligner, fmt, tmp_path, "humot")
    world = lafan.global_positions().float() * UNITS[infer_units(lafan.skeleton)]
    topology = aligner.topology(lafan.skeleton)
    cmu = sa.read_bvh(REPO.parent / "shared" / "data" / "human" / "cmu" / "131_01.bvh")
    cmu_template = aligner.topology(cmu.skeleton).templates(
        cmu.skeleton.bone_lengths().float() * UNITS[infer_units(cmu.skeleton)]
    )

    def encoder(batch: int, frames: int) -> Any:
        pos, tmpl = prepare_chunks(windows(world, batch, frames), topology, lafan.skeleton.up_axis)
        with torch.no_grad():
            return (pos, tmpl), (aligner.net.encoder(pos, tmpl),)

    def decoder(batch: int, frames: int) -> Any:
        _, (z,) = encoder(batch, frames)
        tmpl = cmu_template[None].expand(batch, -1, -1)
        with torch.no_grad():
            return (z, tmpl), (aligner.net.decoder(z, tmpl),)

    sizes = [(2, 30), (3, 17), (1, 30)]
    meta = check_graph(tmp_path, "encoder", fmt, ["motion", "template"], ["z"], encoder, sizes)
    assert meta["metadata"]["chunk_frames"] == 30 and meta["metadata"]["units"] == "m"
    check_graph(tmp_path, "decoder", fmt, ["z", "template"], ["motion"], decoder, sizes)


# ----------------------------------------------------------------------------- VQ-PAE
@pytest.mark.parametrize("fmt", ["onnx", "torchscript"])
def test_vqpae_encoder_and_pose_decoder_match_pytorch(
    lafan: sa.Motion, fmt: str, tmp_path: Path
) -> None:
    from skelagnostic_vqpae.aligner import VqpaeAligner

    from skelagnostic.representations import RootLocalVelocities

    torch.manual_seed(0)
    skeleton = lafan.skeleton
    spec = {
        "channels": 3 * skeleton.num_joints,
        "window": 31,
        "fps": 30.0,
        "skeleton": skeleton.to_dict(),
    }
    aligner = VqpaeAligner(
        latent=4,
        num_codes=8,
        kernel_size=5,
        freq_layers=2,
        amp_layers=2,
        pose_layers=2,
        datasets={"lafan human": spec},
    ).eval()
    char = aligner.characters[0]
    feats = RootLocalVelocities().encode(lafan).float().flatten(1)
    char.input_mean.copy_(feats.mean(0))
    char.input_std.copy_(feats.std(0).clamp_min(1e-3))
    char.pose_fitted.fill_(True)
    export_aligner(aligner, fmt, tmp_path, "vqpae")
    all_windows, _ = aligner._windows(0, lafan)

    def encoder(batch: int, _frames: int) -> Any:
        x = all_windows[40 : 40 + 7 * batch : 7]
        with torch.no_grad():
            _, p = aligner.forward_dataset(0, x)
        return (x,), (p.phase, p.frequency, p.code, p.amplitude, p.manifold[..., 15])

    def decoder(batch: int, frames: int) -> Any:
        _, want = encoder(batch, frames)
        with torch.no_grad():
            return (want[4],), (char.pose(want[4]),)

    outputs = ["phase", "frequency", "code", "amplitude", "manifold"]
    sizes = [(2, 31), (5, 31), (1, 31)]  # the window length is fixed by the architecture
    meta = check_graph(tmp_path, "encoder_lafan_human", fmt, ["windows"], outputs, encoder, sizes)
    assert "window" in meta["fixed_axes"]
    assert meta["inputs"][0]["shape"] == ["batch", spec["channels"], 31]
    assert np.allclose(meta["metadata"]["normalisation"]["input_mean"], char.input_mean)
    assert meta["metadata"]["skeleton"]["joint_names"] == skeleton.joint_names
    meta = check_graph(
        tmp_path, "pose_decoder_lafan_human", fmt, ["manifold"], ["pose"], decoder, sizes
    )
    assert np.allclose(meta["metadata"]["normalisation"]["pose_std"], char.pose_std)


# ------------------------------------------------------------------------------ PC-MRL
@pytest.mark.parametrize("fmt", ["onnx", "torchscript"])
def test_pcmrl_reconstruction_matches_pytorch(lafan: sa.Motion, fmt: str, tmp_path: Path) -> None:
    from skelagnostic_pcmrl.points import global_to_local, sample_layout
    from skelagnostic_pcmrl.recon.aligner import PcmrlReconAligner

    from skelagnostic.core import quaternion as Q

    torch.manual_seed(0)
    aligner = PcmrlReconAligner(
        num_source_points=64,
        num_target_points=64,
        dim=16,
        stages=3,
        point_heads=2,
        temporal_layers=1,
        temporal_heads=2,
        target="biped22",
    ).eval()
    export_aligner(aligner, fmt, tmp_path, "pcmrl")
    metric = lafan.to_metres().to(torch.float32)
    layout = sample_layout(metric.skeleton, 64, 0.05, (), torch.Generator().manual_seed(1))
    cloud = layout.points(
        metric.global_rotations(), metric.global_positions(), metric.skeleton.offsets.float()
    )
    parents = aligner.target_skeleton.parents

    def case(batch: int, frames: int) -> Any:
        pts, groups = windows(cloud, batch, frames), layout.groups[None].expand(batch, -1)
        with torch.no_grad():
            out = aligner.reconstruct(pts, groups, 1)
        local = Q.normalize(global_to_local(out["rotations"], parents))
        return (pts, groups.contiguous()), (out["root"], out["rotations"], local, out["positions"])

    meta = check_graph(
        tmp_path,
        "reconstruction",
        fmt,
        ["points", "groups"],
        ["root", "global_rotations", "local_rotations", "positions"],
        case,
        [(2, 12), (3, 23), (1, 16)],
    )
    assert meta["metadata"]["target_skeleton"]["parents"] == list(parents)
    assert "points" in meta["fixed_axes"]


@pytest.mark.parametrize("fmt", ["onnx", "torchscript"])
def test_pcmrl_interpolation_matches_pytorch(lafan: sa.Motion, fmt: str, tmp_path: Path) -> None:
    from skelagnostic_pcmrl.interp.aligner import PcmrlInterpAligner
    from skelagnostic_pcmrl.interp.rpa import bone_tails

    torch.manual_seed(0)
    metric = lafan.to_metres().to(torch.float32)
    skeleton = metric.skeleton
    aligner = PcmrlInterpAligner(
        dim=16,
        heads=2,
        layers=1,
        ff_mult=2,
        max_relative=8,
        skeleton=skeleton.to_dict(),
        fps=30.0,
        window=16,
    ).eval()
    export_aligner(aligner, fmt, tmp_path, "pcmrl_interp")
    grot, root = metric.global_rotations().float(), metric.root_positions.float()
    offsets, tails = skeleton.offsets.float(), bone_tails(skeleton).tails.float()

    def case(batch: int, frames: int) -> Any:
        keys = torch.zeros(batch, frames, dtype=torch.bool)
        keys[:, 0] = keys[:, -1] = True
        for b in range(batch):  # a different key pattern per window
            keys[b, 3 + b : frames - 1 : 4 + b] = True
        args = (
            windows(grot, batch, frames),
            windows(root, batch, frames),
            keys,
            offsets.expand(batch, -1, -1).contiguous(),
            tails.expand(batch, -1, -1).contiguous(),
        )
        with torch.no_grad():
            return args, aligner.interpolate_window(*args)

    meta = check_graph(
        tmp_path,
        "interpolation",
        fmt,
        ["global_rotations", "root", "keys", "offsets", "tails"],
        ["out_global_rotations", "out_root"],
        case,
        [(2, 16), (3, 27), (1, 16)],
    )
    assert meta["metadata"]["training_window"] == 16
    assert np.allclose(meta["metadata"]["tails"], tails)
