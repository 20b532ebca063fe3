"""The HTML viewer in a real browser: headless Chromium driven by selenium.

Chromium and chromedriver come from Debian (``.ci/run`` installs them when
missing); the tests skip only when they, or selenium, are not installed.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

import skelagnostic as sa
from skelagnostic.core.motion import UNITS
from skelagnostic.viz import StickFigure
from skelagnostic.viz.browser import ViewerBrowser, browser_available
from skelagnostic.viz.html import build_payload, clip_colors, to_html

pytestmark = pytest.mark.skipif(
    browser_available() is not None,
    reason=f"no headless browser: {browser_available()}",
)

FRAME = 37


@pytest.fixture(scope="module")
def motions() -> list[sa.Motion]:
    human, _ = sa.procedural.generate("biped22", "walk", seconds=2.0, fps=30, seed=0)
    dog, _ = sa.procedural.generate("quadruped", "trot", seconds=2.0, fps=30, seed=1)
    return [human, dog]


@pytest.fixture(scope="module")
def browser():
    with ViewerBrowser(size=(900, 560)) as chromium:
        yield chromium


def _project(points: np.ndarray, camera: dict) -> np.ndarray:
    """World points [N, 3] -> CSS pixel coordinates [N, 2] with the page's camera."""
    view = np.asarray(camera["view"]).reshape(4, 4).T  # three.js stores column-major
    projection = np.asarray(camera["projection"]).reshape(4, 4).T
    homogeneous = np.hstack([points, np.ones((len(points), 1))])
    clip = homogeneous @ (projection @ view).T
    ndc = clip[:, :3] / clip[:, 3:]
    left, top, width, height = camera["rect"]
    return np.stack([left + (ndc[:, 0] + 1) / 2 * width, top + (1 - ndc[:, 1]) / 2 * height], 1)


def _colour_mask(image: np.ndarray, colours: list[str], tolerance: int = 10) -> np.ndarray:
    mask = np.zeros(image.shape[:2], dtype=bool)
    for colour in colours:
        rgb = np.array([int(colour[i : i + 2], 16) for i in (1, 3, 5)])
        mask |= (np.abs(image.astype(int) - rgb) <= tolerance).all(axis=-1)
    return mask


def test_skeletons_are_drawn_where_forward_kinematics_puts_them(motions, browser, tmp_path):
    page = tmp_path / "view.html"
    to_html(motions, names=["human", "dog"], out=page, keyframes=[0, 30, 59])
    payload = build_payload(motions, names=["human", "dog"])
    browser.open(page)
    assert browser.console_errors() == []
    assert browser.call("frame") == 0

    browser.step_to(FRAME)
    assert browser.call("frame") == FRAME
    browser.driver.find_element("tag name", "body").send_keys("h")  # hide labels and legend
    browser.driver.execute_async_script(
        "const done = arguments[0]; requestAnimationFrame(() => requestAnimationFrame(done));")
    image = browser.screenshot()
    camera = browser.call("camera")
    assert browser.console_errors() == []

    boxes = []
    for k, motion in enumerate(motions):
        assert browser.call("clipFrame", k) == FRAME
        fk = motion.global_positions()[FRAME].double().numpy() * UNITS[motion.units]
        world = fk + np.asarray(payload["clips"][k]["sideOffset"])
        # the page draws the decoded positions at its offset: FK within the quantisation step
        drawn = np.asarray(browser.call("joints", k))
        assert np.abs(drawn - world).max() <= max(payload["clips"][k]["step"]) + 1e-6
        pixels = _project(world, camera)
        assert np.allclose(pixels, np.asarray(browser.call("project", k)), atol=0.5)
        boxes.append((pixels.min(axis=0) - 8, pixels.max(axis=0) + 8))

    (x0a, _), (x1a, _) = boxes[0]
    (x0b, _), (x1b, _) = boxes[1]
    assert x1a < x0b or x1b < x0a, "side by side: the clips do not overlap on screen"
    ys, xs = np.mgrid[: image.shape[0], : image.shape[1]]
    left, top, width, height = camera["rect"]
    canvas = (xs >= left) & (xs < left + width) & (ys >= top) & (ys < top + height)
    for k, (low, high) in enumerate(boxes):
        colours = [clip_colors(k)[g] for g in set(motions[k].skeleton.body_groups)]
        mask = _colour_mask(image, colours) & canvas  # the timeline marks use the colours too
        inside = (xs >= low[0]) & (xs <= high[0]) & (ys >= low[1]) & (ys <= high[1])
        assert (mask & inside).sum() >= 150, f"clip {k}: too few pixels of its colours"
        assert (mask & ~inside).sum() <= 0.02 * mask.sum(), f"clip {k}: its colours outside"


def test_controls_play_and_switch_layout(motions, browser, tmp_path):
    page = tmp_path / "view.html"
    to_html(motions, out=page, mode="overlay", follow=False, speed=4.0)
    payload = build_payload(motions)
    browser.open(page)
    assert browser.driver.execute_script("return document.getElementById('layout').value") == (
        "overlay")
    for k in range(2):
        assert np.allclose(browser.call("offset", k), payload["clips"][k]["overlayOffset"])
    browser.driver.find_element("id", "play").click()
    browser._wait(lambda: browser.call("frame") > 20, 20.0, "playback did not advance")
    browser.driver.find_element("id", "play").click()
    paused = browser.call("frame")
    browser.driver.execute_async_script(
        "const done = arguments[0]; setTimeout(done, 200);")
    assert browser.call("frame") == paused
    from selenium.webdriver.support.ui import Select

    Select(browser.driver.find_element("id", "layout")).select_by_value("side")
    for k in range(2):
        assert np.allclose(browser.call("offset", k), payload["clips"][k]["sideOffset"])
    assert browser.console_errors() == []


@pytest.mark.slow
def test_ten_one_minute_clips_open_and_play_smoothly(browser, tmp_path):
    rng = np.random.default_rng(0)
    frames, joints = 60 * 30, 22
    figures = []
    for k in range(10):
        path = np.cumsum(rng.normal(0, 0.02, (frames, 1, 3)), axis=0) * [1, 0, 1]
        pose = rng.uniform(0, 1.7, (1, joints, 3))
        figures.append(StickFigure(path + pose, parents=[-1, *range(joints - 1)], fps=30.0,
                                   name=f"clip {k}"))
    page = tmp_path / "ten.html"
    to_html(figures, out=page, units="m")
    start = time.monotonic()
    browser.open(page)
    print(f"opened in {time.monotonic() - start:.2f} s")
    assert time.monotonic() - start < 15.0
    browser.driver.find_element("id", "play").click()
    first = browser.call("frame")
    draws_per_second = browser.driver.execute_async_script(
        "const done = arguments[0]; let n = 0; const t0 = performance.now();"
        "function count() { n++; if (performance.now() - t0 < 2000) requestAnimationFrame(count);"
        " else done(1000 * n / (performance.now() - t0)); }"
        "requestAnimationFrame(count);")
    advanced = browser.call("frame") - first
    print(f"{draws_per_second:.1f} draws/s, {advanced} frames in 2 s")
    browser.driver.find_element("id", "play").click()
    assert draws_per_second >= 8.0  # software WebGL on a busy shared CPU (idle: ~28; a GPU: 60)
    assert advanced >= 40  # about 60 frames of the 30 fps clock in 2 s: real time
    assert browser.console_errors() == []
