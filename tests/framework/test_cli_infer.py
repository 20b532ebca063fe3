"""The inference verbs: skelagnostic retarget | interpolate | transfer."""

from __future__ import annotations

import shutil
from collections.abc import Callable, Sequence
from pathlib import Path

import pytest
import torch

import skelagnostic as sa
from skelagnostic import cli
from skelagnostic.analysis import foot_contacts
from skelagnostic.cli.infer import keyframes_from_options
from skelagnostic.core.quaternion import slerp
from skelagnostic.errors import SkelagnosticError
from skelagnostic.metrics.functional import foot_skate
from skelagnostic.plugins import LOAD_PLUGINS_ENV

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

# A third-party aligner declaring the two optional capabilities. Its methods are simple
# and exact (slerp between keys, replay of the first target clip), so the tests can
# check that the verbs pass the right arguments and write what the method returns.
KEYED = """
import torch
from skelagnostic import Motion
from skelagnostic.core.quaternion import slerp
from skelagnostic.plugins import hookimpl
from skelagnostic_example.aligner import ExampleAligner, ExampleDataModule


class Keyed(ExampleAligner):
    capabilities = ExampleAligner.capabilities | {"interpolate", "transfer"}

    def interpolate(self, motion, keyframes):
        rot, root = motion.rotations.clone(), motion.root_positions.clone()
        for a, b in zip(keyframes[:-1], keyframes[1:]):
            for t in range(a + 1, b):
                w = (t - a) / (b - a)
                rot[t] = slerp(rot[a], rot[b], torch.tensor(w, dtype=rot.dtype))
                root[t] = root[a] + w * (root[b] - root[a])
        return Motion(motion.skeleton, rot, root, motion.fps)

    def transfer(self, motion, targets):
        self.last_transitions = [10, 25]  # as if matched windows started there
        return targets[0][: motion.num_frames]


@hookimpl
def register_aligners(register):
    register("keyed", Keyed, ExampleDataModule, config={"model": {"hidden": 16, "latent": 4}})
"""


@pytest.fixture(scope="module")
def trained(
    tmp_path_factory: pytest.TempPathFactory, fit_example: Callable[[Path, Sequence[str]], Path]
) -> Path:
    """A run directory of the example aligner trained for one tiny epoch."""
    return fit_example(tmp_path_factory.mktemp("infer"), FAST)


@pytest.fixture
def clips(tmp_path: Path) -> Callable[[str, str], Path]:
    def make(kind: str, gait: str, seconds: float = 2.0) -> Path:
        motion, _ = sa.procedural.generate(kind, gait, seconds=seconds, fps=30)
        path = tmp_path / f"{kind}_{gait}.bvh"
        sa.write_bvh(motion, path)
        return path

    return make


@pytest.fixture
def keyed_plugin(example_plugin: Path, add_plugin, monkeypatch: pytest.MonkeyPatch) -> None:
    add_plugin("keyed", KEYED)
    monkeypatch.setenv(LOAD_PLUGINS_ENV, "example,keyed")


def test_retarget_writes_a_bvh_of_the_target_rig(
    example_plugin: Path, trained: Path, clips, tmp_path: Path, capsys
) -> None:
    source, target = clips("biped22", "walk"), clips("biped31", "run")
    out = tmp_path / "out" / "retargeted.bvh"
    gif = tmp_path / "out" / "side.gif"
    ckpt = trained / "checkpoints" / "last.ckpt"
    # model= is read from the run's config.yaml next to the checkpoint
    code = cli.main(
        [
            "retarget",
            str(source),
            str(target),
            f"ckpt={ckpt}",
            f"out={out}",
            f"render={gif}",
            "max_frames=4",
            "size=64",
        ]
    )
    assert code == 0, capsys.readouterr().err
    result = sa.read_bvh(out)
    assert result.skeleton.joint_names == sa.read_bvh(target).skeleton.joint_names
    assert result.num_frames == sa.read_bvh(source).num_frames
    assert torch.isfinite(result.global_positions()).all()
    assert gif.is_file() and str(out) in capsys.readouterr().out


def test_retarget_reads_and_writes_gltf_by_suffix(
    example_plugin: Path, trained: Path, clips, tmp_path: Path, capsys
) -> None:
    source_bvh, target = clips("biped22", "walk"), clips("biped31", "run")
    source = tmp_path / "source.gltf"
    sa.write_gltf(sa.read_bvh(source_bvh), source)
    ckpt = trained / "checkpoints" / "last.ckpt"
    results = {}
    for name, clip in (("r.glb", source), ("r.bvh", source_bvh)):
        out = tmp_path / name
        code = cli.main(["retarget", str(clip), str(target), f"ckpt={ckpt}", f"out={out}"])
        assert code == 0, capsys.readouterr().err
        results[name] = sa.io.read_motion(out)
    glb, bvh = results["r.glb"], results["r.bvh"]
    assert glb.skeleton.joint_names == sa.read_bvh(target).skeleton.joint_names
    assert glb.num_frames == bvh.num_frames == sa.read_bvh(source_bvh).num_frames
    # glTF input and output give the motion the BVH route gives (6-decimal BVH text)
    assert torch.allclose(glb.global_positions(), bvh.global_positions(), atol=1e-3)


def test_interpolate_keeps_keys_and_passes_them(
    keyed_plugin: None, trained: Path, clips, tmp_path: Path, capsys
) -> None:
    clip = clips("biped22", "walk")
    out = tmp_path / "inbetween.bvh"
    ckpt = trained / "checkpoints" / "last.ckpt"
    code = cli.main(
        ["interpolate", str(clip), f"ckpt={ckpt}", "model=keyed", "every=15", f"out={out}"]
    )
    assert code == 0, capsys.readouterr().err
    source, result = sa.read_bvh(clip), sa.read_bvh(out)
    assert source.num_frames == 61
    keys = [0, 15, 30, 45, 60]
    assert keyframes_from_options(source.num_frames, "15", None) == keys
    q = lambda m: m.rotations.double()  # noqa: E731
    dot = (q(source)[keys] * q(result)[keys]).sum(-1).abs()
    assert torch.allclose(dot, torch.ones_like(dot), atol=1e-6)
    # frame 7 is the slerp half-way (7/15) between keys 0 and 15
    expected = slerp(q(source)[0], q(source)[15], torch.tensor(7 / 15, dtype=torch.float64))
    dot = (expected * q(result)[7]).sum(-1).abs()
    assert torch.allclose(dot, torch.ones_like(dot), atol=1e-5)


@pytest.mark.data
def test_cleanup_footlock_stops_the_feet_of_an_interpolation_sliding(
    keyed_plugin: None, trained: Path, lafan_clip: Path, tmp_path: Path, capsys
) -> None:
    ckpt = trained / "checkpoints" / "last.ckpt"
    outs = {}
    for cleanup in ("none", "footlock"):
        outs[cleanup] = tmp_path / f"{cleanup}.bvh"
        words = ["interpolate", str(lafan_clip), f"ckpt={ckpt}", "model=keyed", "every=12"]
        code = cli.main([*words, f"cleanup={cleanup}", f"out={outs[cleanup]}"])
        assert code == 0, capsys.readouterr().err
    plain, locked = (sa.read_bvh(outs[c]) for c in ("none", "footlock"))
    contacts, feet = foot_contacts(plain)
    sk = plain.skeleton
    kw = {"fps": plain.fps, "up_axis": sk.up_axis, "feet": feet}
    before = foot_skate(plain.global_positions(), contacts, **kw)
    after = foot_skate(locked.global_positions(), contacts, **kw)
    assert after < 0.5 * before  # slerp between keys slides the feet; the lock pins them
    assert torch.equal(locked.root_positions, plain.root_positions)


def test_transfer_reads_target_directories(
    keyed_plugin: None, trained: Path, clips, tmp_path: Path, capsys
) -> None:
    source = clips("biped22", "walk")
    dog_dir = tmp_path / "dog"
    dog_dir.mkdir()
    shutil.move(str(clips("quadruped", "trot", 3.0)), dog_dir / "a.bvh")
    out = tmp_path / "transfer.bvh"
    code = cli.main(
        [
            "transfer",
            str(source),
            str(dog_dir),
            "model=keyed",
            f"ckpt={trained / 'checkpoints' / 'last.ckpt'}",
            f"out={out}",
        ]
    )
    assert code == 0, capsys.readouterr().err
    result = sa.read_bvh(out)
    assert result.skeleton.num_joints == sa.read_bvh(dog_dir / "a.bvh").skeleton.num_joints
    assert result.num_frames == sa.read_bvh(source).num_frames


def test_interpolate_and_transfer_mark_keys_and_transitions_in_the_viewer(
    keyed_plugin: None, trained: Path, clips, tmp_path: Path, capsys
) -> None:
    from skelagnostic.viz.html import decode_payload

    clip = clips("biped22", "walk")
    ckpt = f"ckpt={trained / 'checkpoints' / 'last.ckpt'}"
    page = tmp_path / "keys.html"
    code = cli.main(
        [
            "interpolate",
            str(clip),
            ckpt,
            "model=keyed",
            "every=20",
            f"out={tmp_path / 'a.bvh'}",
            f"html={page}",
        ]
    )
    assert code == 0, capsys.readouterr().err
    text = page.read_text(encoding="utf-8")
    assert text.count('"keyframes":[0,20,40,60]') == 2  # input and result
    assert '"name":"input"' in text and '"name":"interpolate"' in text
    assert str(page) in capsys.readouterr().out

    dog = clips("quadruped", "trot", 3.0)
    page = tmp_path / "transfer.html"
    code = cli.main(
        [
            "transfer",
            str(clip),
            str(dog),
            ckpt,
            "model=keyed",
            f"out={tmp_path / 'b.bvh'}",
            f"render={page}",
        ]
    )
    assert code == 0, capsys.readouterr().err
    text = page.read_text(encoding="utf-8")
    assert '"transitions":[10,25]' in text and '"name":"transfer"' in text
    assert [p.shape[1] for p in decode_payload(text)] == [22, 21]


def test_retarget_html_option(
    example_plugin: Path, trained: Path, clips, tmp_path: Path, capsys
) -> None:
    source, target = clips("biped22", "walk"), clips("biped31", "run")
    page = tmp_path / "retarget.html"
    code = cli.main(
        [
            "retarget",
            str(source),
            str(target),
            f"ckpt={trained / 'checkpoints' / 'last.ckpt'}",
            f"out={tmp_path / 'r.bvh'}",
            f"html={page}",
            "mode=overlay",
        ]
    )
    assert code == 0, capsys.readouterr().err
    text = page.read_text(encoding="utf-8")
    assert '"mode":"overlay"' in text and '"name":"retarget"' in text


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["interpolate", "{clip}", "ckpt={ckpt}", "every=5", "out={out}"],
            "does not support 'interpolate'",
        ),
        (["retarget", "{clip}", "ckpt={ckpt}", "out={out}"], "expected 2 input path(s), got 1"),
        (["retarget", "{clip}", "{clip}", "ckpt={ckpt}"], "missing option out="),
        (
            ["retarget", "{clip}", "{clip}", "ckpt={ckpt}", "out=x.gif"],
            "must be a .bvh, .glb or .gltf path",
        ),
        (
            ["retarget", "{clip}", "{clip}", "ckpt=nope.ckpt", "out={out}"],
            "ckpt: no checkpoint file 'nope.ckpt'",
        ),
        (["retarget", "{clip}", "{clip}", "ckpt={ckpt}", "model=nope", "out={out}"], "nope"),
        (
            ["retarget", "missing.bvh", "{clip}", "ckpt={ckpt}", "out={out}"],
            "missing.bvh: no such file",
        ),
        (
            ["interpolate", "{clip}", "ckpt={ckpt}", "keys=3,99", "out={out}"],
            "frame(s) [99] are outside the clip",
        ),
        (["interpolate", "{clip}", "ckpt={ckpt}", "out={out}"], "exactly one of every="),
        (
            ["retarget", "{clip}", "{clip}", "ckpt={ckpt}", "out={out}", "cleanup=footslide"],
            "option cleanup='footslide': must be footlock or none",
        ),
        (
            ["transfer", "{clip}", "{clip}", "ckpt={ckpt}", "out={out}", "speed=2"],
            "unknown option(s) speed=",
        ),
    ],
)
def test_verb_errors_are_one_line_and_write_nothing(
    example_plugin: Path,
    trained: Path,
    clips,
    tmp_path: Path,
    capsys,
    args: list[str],
    message: str,
) -> None:
    clip, out = clips("biped22", "walk"), tmp_path / "never.bvh"
    ckpt = trained / "checkpoints" / "last.ckpt"
    words = [a.format(clip=clip, ckpt=ckpt, out=out) for a in args]
    assert cli.main(words) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"skelagnostic {args[0]}: error:") and "\n" not in err
    assert message in err
    assert not out.exists()


def test_checkpoint_outside_a_run_needs_model(trained: Path, tmp_path: Path) -> None:
    from skelagnostic.cli.infer import load_from_checkpoint

    lone = tmp_path / "lone.ckpt"
    shutil.copy(trained / "checkpoints" / "last.ckpt", lone)
    with pytest.raises(SkelagnosticError, match="give model=NAME"):
        load_from_checkpoint(lone)


def test_help_lists_options(capsys) -> None:
    assert cli.main(["interpolate", "--help"]) == 0
    text = capsys.readouterr().out
    assert "\n  every " in text and "\n  keys " in text and "\n  render " in text
    assert cli.main(["retarget"]) == 2


def test_units_option_sets_the_input_units(clips, tmp_path: Path, capsys) -> None:
    from skelagnostic.cli.infer import _read

    clip = clips("biped22", "walk")
    assert _read(clip, {}).units is None
    assert _read(clip, {"units": "cm"}).units == "cm"
    with pytest.raises(SkelagnosticError, match=r"units='furlong'.*cmu"):
        _read(clip, {"units": "furlong"})
    ckpt = tmp_path / "missing.ckpt"
    code = cli.main(
        [
            "interpolate",
            str(clip),
            f"ckpt={ckpt}",
            "every=15",
            "units=cm",
            f"out={tmp_path / 'o.bvh'}",
        ]
    )
    assert code == 2 and "missing.ckpt" in capsys.readouterr().err  # units= is a known option
