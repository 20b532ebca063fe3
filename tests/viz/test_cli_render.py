"""``skelagnostic render``: the verb and the option back end shared with other verbs."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

import skelagnostic as sa
from skelagnostic.cli.render import main, parse_arguments, render_from_options
from skelagnostic.errors import SkelagnosticError


@pytest.fixture(scope="module")
def bvh_files(tmp_path_factory):
    """A procedural human (30 fps, 1 s) and dog (60 fps, 0.5 s) written as BVH."""
    root = tmp_path_factory.mktemp("bvh")
    human, _ = sa.procedural.generate(kind="biped31", gait="walk", seconds=1.0, fps=30, seed=0)
    dog, _ = sa.procedural.generate(kind="quadruped", gait="trot", seconds=0.5, fps=60, seed=0)
    sa.write_bvh(human, root / "human.bvh")
    sa.write_bvh(dog, root / "dog.bvh")
    return root / "human.bvh", root / "dog.bvh"


def test_gif_and_sheet(bvh_files, tmp_path, capsys):
    human, dog = bvh_files
    out, sheet = tmp_path / "anim.gif", tmp_path / "sheet.png"
    code = main(
        [
            str(human),
            str(dog),
            f"out={out}",
            f"sheet={sheet}",
            "fps=10",
            "size=90x70",
            "frames=3",
            "trajectory=true",
            "labels=h,d",
        ]
    )
    assert code == 0
    assert capsys.readouterr().out.split() == [str(out), str(sheet)]
    with Image.open(out) as gif:
        assert gif.size == (180, 70)
        assert gif.n_frames == 11  # the longer clip lasts 1 s; 10 fps
    with Image.open(sheet) as image:
        assert image.size == (3 * 180 + 2 * 4, 70)


def test_start_end_overlay_and_png_output(bvh_files, tmp_path):
    human, _ = bvh_files
    out = tmp_path / "cut.gif"
    assert (
        main(
            [
                str(human),
                str(human),
                f"out={out}",
                "mode=overlay",
                "start=0.2",
                "end=0.5",
                "size=64",
                "elev=30",
                "azim=-90",
                "follow=yes",
            ]
        )
        == 0
    )
    with Image.open(out) as gif:
        assert gif.size == (64, 64)
        assert gif.n_frames == 10  # 0.2 .. 0.5 s at 30 fps
    png = tmp_path / "only.png"
    assert main([str(human), f"out={png}", "frames=2", "columns=1", "size=40x30"]) == 0
    with Image.open(png) as image:
        assert image.size == (40, 2 * 30 + 4)


def test_max_frames(bvh_files, tmp_path):
    human, _ = bvh_files
    out = tmp_path / "few.gif"
    assert main([str(human), f"out={out}", "max_frames=4", "size=32"]) == 0
    with Image.open(out) as gif:
        assert gif.n_frames == 4


@pytest.mark.parametrize(
    ("words", "message"),
    [
        (["a.bvh", "colour=red"], "unknown option"),
        (["out=x.gif"], "no input"),
        (["{human}", "fps=fast"], "fps='fast' is not a number"),
        (["{human}", "frames=2.5"], "frames='2.5' is not an integer"),
        (["{human}", "size=big"], "size='big'"),
        (["{human}", "trajectory=maybe"], "true/false"),
        (["{human}", "mode=grid"], "mode"),
        (["{human}", "start=5"], "past the end"),
        (["{human}", "start=0.5", "end=0.2"], "start < end"),
        (["{human}", "out=a.avi"], "unsupported format"),
        (["{human}", "fps=1", "fps=2"], "twice"),
        (["missing.bvh"], "missing.bvh"),
    ],
)
def test_errors_exit_2_with_a_message(bvh_files, tmp_path, capsys, monkeypatch, words, message):
    monkeypatch.chdir(tmp_path)
    words = [w.format(human=bvh_files[0]) for w in words]
    assert main(words) == 2
    err = capsys.readouterr().err
    assert err.startswith("skelagnostic render: error:")
    assert message in err
    assert not list(tmp_path.glob("*.gif"))


def test_help(capsys):
    assert main(["--help"]) == 0
    text = capsys.readouterr().out
    assert "usage: skelagnostic render" in text and "mode" in text and "sheet" in text
    assert main([]) == 2


def test_parse_arguments_keeps_paths_with_equals_signs():
    assert parse_arguments(["dir/a=b.bvh", "out=x.gif"]) == (["dir/a=b.bvh"], {"out": "x.gif"})
    with pytest.raises(SkelagnosticError, match="twice"):
        parse_arguments(["out=a", "out=b"])


def test_render_from_options_for_other_verbs(bvh_files, tmp_path):
    motion = sa.read_bvh(bvh_files[1])
    # a verb whose out= is a BVH asks for render=...; unrelated options are ignored
    options = {"out": "result.bvh", "render": str(tmp_path / "r.gif"), "size": "32", "w": "1"}
    assert render_from_options([motion], options, out_key="render") == [tmp_path / "r.gif"]
    assert render_from_options([motion], {"out": "result.bvh"}, out_key="render") == []


@pytest.mark.data
def test_real_clips_from_the_command_line(shared_data, tmp_path, ink):
    out = tmp_path / "real.gif"
    cmu = shared_data / "human" / "cmu" / "131_03.bvh"
    dog = shared_data / "dog" / "mann" / "D1_010_KAN01_002.bvh"
    assert main([str(cmu), str(dog), f"out={out}", "end=0.3", "fps=10", "size=100x120"]) == 0
    with Image.open(out) as gif:
        assert gif.size == (200, 120) and gif.n_frames == 4
        frame = np.asarray(gif.convert("RGB"))
    assert ink(frame[:, :100]) > 50 and ink(frame[:, 100:]) > 50


def test_options_are_parsed_into_render_arguments(monkeypatch, tmp_path):
    import skelagnostic.viz

    calls = []
    monkeypatch.setattr(
        skelagnostic.viz, "render_motion", lambda motions, out, **kw: calls.append(kw) or out
    )
    options = {
        "out": "a.gif",
        "mode": "overlay",
        "fps": "12.5",
        "size": "100x80",
        "elev": "20",
        "azim": "-45",
        "trajectory": "on",
        "follow": "no",
        "labels": "x, y",
        "max_frames": "40",
        "frames": "5",
        "columns": "2",
    }
    assert render_from_options(["m1", "m2"], options) == ["a.gif"]
    assert calls == [
        {
            "sheet_frames": 5,
            "columns": 2,
            "progress": True,
            "key": "out",
            "mode": "overlay",
            "fps": 12.5,
            "elev": 20.0,
            "azim": -45.0,
            "size": (100, 80),
            "max_frames": 40,
            "trajectory": True,
            "follow": False,
            "labels": ["x", "y"],
        }
    ]


def test_out_html_writes_the_viewer_with_labels_and_mode(bvh_files, tmp_path, capsys):
    from skelagnostic.viz.html import decode_payload

    human, dog = bvh_files
    out = tmp_path / "view.html"
    assert main([str(human), str(dog), f"out={out}", "labels=h,d", "mode=overlay"]) == 0
    assert capsys.readouterr().out.split() == [str(out)]
    page = out.read_text(encoding="utf-8")
    assert '"name":"h"' in page and '"name":"d"' in page and '"mode":"overlay"' in page
    positions = decode_payload(page)
    assert [p.shape[0] for p in positions] == [31, 31]
    fk = sa.read_bvh(human).global_positions().double().numpy() * 0.01  # procedural: cm
    assert np.abs(positions[0] - fk).max() < 1e-4


def test_html_option_next_to_a_gif_and_cut_marks(bvh_files, tmp_path):
    from skelagnostic.viz.html import decode_payload

    human, _ = bvh_files
    motion = sa.read_bvh(human)
    gif, page = tmp_path / "a.gif", tmp_path / "a.html"
    written = render_from_options(
        [motion, motion],
        {"out": str(gif), "html": str(page), "start": "0.2", "size": "48", "max_frames": "3"},
        keyframes={0: [0, 5, 6, 20], 1: [30]},
        transitions={1: [10]},
    )
    assert written == [page, gif] and gif.is_file()
    text = page.read_text(encoding="utf-8")
    # start=0.2 s cuts 6 frames at 30 fps: marks move with the cut, earlier ones are dropped
    assert '"keyframes":[0,14]' in text and '"keyframes":[24]' in text
    assert '"transitions":[4]' in text
    assert decode_payload(text)[0].shape[0] == 31 - 6


def test_html_option_must_be_an_html_path(bvh_files, tmp_path, capsys):
    human, _ = bvh_files
    assert main([str(human), f"out={tmp_path / 'a.gif'}", f"html={tmp_path / 'a.png'}"]) == 2
    assert "option html=" in capsys.readouterr().err
