"""skelagnostic.viz.to_html without a browser: payload, size, units, marks, colours."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

import skelagnostic as sa
from skelagnostic.core.motion import UNITS
from skelagnostic.viz import RenderError, StickFigure, to_html
from skelagnostic.viz.html import build_payload, clip_colors, decode_payload, guess_units


@pytest.fixture(scope="module")
def walk() -> sa.Motion:
    motion, _ = sa.procedural.generate("biped22", "walk", seconds=2.0, fps=30, seed=0)
    return motion


@pytest.fixture(scope="module")
def trot() -> sa.Motion:
    motion, _ = sa.procedural.generate("quadruped", "trot", seconds=1.0, fps=60, seed=1)
    return motion


def _data(page: str) -> dict:
    match = re.search(
        r'<script type="application/json" id="skelagnostic-data">(.*?)</script>', page, flags=re.S
    )
    assert match is not None
    return json.loads(match.group(1))


def test_sixty_seconds_of_22_joints_at_30_fps_stay_under_2_mb(tmp_path):
    rng = np.random.default_rng(0)
    frames = 60 * 30
    walk_path = np.cumsum(rng.normal(0, 0.02, (frames, 1, 3)), axis=0) * [1, 0, 1]
    positions = walk_path + rng.uniform(0, 1.8, (1, 22, 3)) + rng.normal(0, 0.01, (frames, 22, 3))
    figure = StickFigure(positions, parents=[-1, *range(21)], fps=30.0, name="long")
    out = tmp_path / "long.html"
    page = to_html(figure, out=out, units="m")
    assert out.read_text(encoding="utf-8") == page
    assert out.stat().st_size < 2_000_000
    decoded = decode_payload(page)[0]
    assert decoded.shape == (frames, 22, 3)
    step = np.asarray(_data(page)["clips"][0]["step"])
    assert (np.abs(decoded - positions) <= step / 2 + 1e-9).all()
    assert step.max() < 1e-3  # better than a millimetre over a 60 s path


def test_decoded_positions_equal_forward_kinematics_in_metres(walk, trot):
    page = to_html([walk, trot], names=["walk", "trot"])
    decoded = decode_payload(page)
    payload = _data(page)
    for motion, positions, clip in zip((walk, trot), decoded, payload["clips"], strict=True):
        fk = motion.global_positions().double().numpy() * UNITS[motion.units]  # cm -> m, y-up
        assert clip["units"] == "cm" and clip["frames"] == motion.num_frames
        assert clip["fps"] == motion.fps
        assert np.abs(positions - fk).max() <= max(clip["step"]) / 2 + 1e-9
        assert np.abs(positions - fk).max() < 1e-4


def test_names_colours_and_marks_are_in_the_page(walk, trot):
    page = to_html(
        [walk, trot],
        names=["human", "dog"],
        keyframes={0: [0, 15, 59]},
        transitions=[None, [20, 41]],
        title="A & B",
    )
    payload = _data(page)
    human, dog = payload["clips"]
    assert (human["name"], dog["name"]) == ("human", "dog")
    assert human["joints"] == walk.skeleton.joint_names
    assert dog["groups"] == dog_groups(trot)
    assert human["groupColors"] == clip_colors(0) and dog["color"] == clip_colors(1)["spine"]
    assert human["color"] != dog["color"]
    assert len(set(clip_colors(0).values())) == len(clip_colors(0))  # one colour per body group
    assert (human["keyframes"], dog["keyframes"]) == ([0, 15, 59], [])
    assert (human["transitions"], dog["transitions"]) == ([], [20, 41])
    assert "<title>A &amp; B</title>" in page


def dog_groups(motion: sa.Motion) -> list[str]:
    return list(motion.skeleton.body_groups)


def test_page_is_self_contained_and_ships_three_js_with_its_license(walk):
    page = to_html(walk)
    assert not re.search(r"<(script|link|img)[^>]+(src|href)=", page)  # nothing fetched
    assert "Copyright 2010-2022 Three.js Authors" in page and "OrbitControls" in page
    assert page.count("</script>") == page.count("<script")
    from importlib import resources

    assets = resources.files("skelagnostic.viz").joinpath("assets")
    assert "MIT License" in assets.joinpath("three.LICENSE").read_text()


def test_up_axis_and_units_are_normalised_to_metres_y_up():
    # a z-up stick in millimetres: 1.7 m tall along +z
    positions = np.array([[[100.0, 200.0, 0.0], [100.0, 200.0, 1700.0]]] * 3)
    figure = StickFigure(positions, parents=[-1, 0], up_axis="z", name="zup")
    assert guess_units(figure) == "mm"
    decoded = decode_payload(build_payload(figure))[0]
    assert np.allclose(decoded[0], [[0.1, 0.0, -0.2], [0.1, 1.7, -0.2]], atol=1e-4)


def test_units_are_guessed_for_bipeds_and_quadrupeds(walk, trot):
    human = StickFigure.from_motion(walk)
    dog = StickFigure.from_motion(trot)
    assert (guess_units(human), guess_units(dog)) == ("cm", "cm")
    human.positions = human.positions * UNITS["cm"] / UNITS["cmu"]
    assert guess_units(human) == "cmu"
    walk_without_units = sa.Motion(walk.skeleton, walk.rotations, walk.root_positions, walk.fps)
    assert build_payload(walk_without_units)["clips"][0]["units"] == "cm"
    assert build_payload(walk, units="m")["clips"][0]["units"] == "m"  # explicit wins


def test_side_by_side_lanes_do_not_overlap(walk, trot):
    payload = build_payload([walk, walk, trot])
    axis = payload["laneAxis"]
    starts = [
        positions[0, 0] + np.asarray(clip["sideOffset"])
        for positions, clip in zip(decode_payload(payload), payload["clips"], strict=True)
    ]
    lanes = sorted(start[axis] for start in starts)
    assert np.diff(lanes).min() >= payload["height"]
    other = 2 - axis
    assert np.allclose([s[other] for s in starts], 0.0, atol=1e-3)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"mode": "grid"}, "mode must be one of"),
        ({"units": "furlong"}, "unknown unit 'furlong'"),
        ({"keyframes": [[0, 99]]}, "outside clip"),
        ({"transitions": {3: [1]}}, "clip index 3 is out of range"),
        ({"out": "view.gif"}, "an .html file"),
        ({"speed": 0.0}, "speed must be a positive number"),
    ],
)
def test_bad_arguments_name_the_argument(walk, kwargs, message):
    with pytest.raises(RenderError, match=re.escape(message)):
        to_html(walk, **kwargs)


def test_inline_json_holds_no_markup_and_reads_back_every_name():
    """``<``, ``>``, ``&``, U+2028/2029 are JSON escapes: no name ends or comments out the block."""
    names = ["<!--<script>", "</script><img src=x onerror=alert(1)>", "a & b", "l\u2028p\u2029"]
    pose = np.zeros((2, len(names), 3))
    pose[..., 1] = np.arange(len(names))
    figures = [StickFigure(pose, parents=[-1, 0, 1, 2], joint_names=names) for _ in range(2)]
    page = to_html(figures, names=names[:2], units="m")
    start = page.index('<script type="application/json" id="skelagnostic-data">')
    block = page[start:].split(">", 1)[1].split("</script>", 1)[0]
    assert not set(block) & {"<", ">", "&", "\u2028", "\u2029"}
    data = _data(page)
    assert [clip["name"] for clip in data["clips"]] == names[:2]
    assert data["clips"][0]["joints"] == names
    # the viewer's own script comes after the data block, outside any comment
    assert page.index("window.skelagnostic = {") > start + len(block)
    assert page.count("<script") == page.count("</script>")
