"""The three.js page of ``docs/engines.md`` runs as written and plays a written clip.

``docs/snippets/threejs-player.html`` is the file the docs page includes (mkdocs'
snippets extension), so the page cannot drift from what is tested here. The test
serves it over HTTP from a folder holding a ``clip.glb`` written by
:func:`skelagnostic.io.write_motion` (what ``retarget ... out=clip.glb`` calls), in
headless Chromium. The page's import map points at a CDN; offline, the test
replaces only that map, with two small modules that re-export the vendored build
of the same three.js release (r147) and its GLTFLoader. Every other line of the
page runs unchanged. The joints' world positions in the page's own
``AnimationMixer`` must be ``Motion.global_positions`` within 1e-4 of the height.
"""

from __future__ import annotations

import functools
import http.server
import json
import re
import shutil
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

import skelagnostic as sa
from skelagnostic.io import write_motion
from skelagnostic.viz.browser import ViewerBrowser, browser_available

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(
        browser_available() is not None, reason=f"no headless browser: {browser_available()}"
    ),
]

REPO = Path(__file__).resolve().parents[2]
SNIPPET = REPO / "docs" / "snippets" / "threejs-player.html"
PAGE = REPO / "docs" / "engines.md"
THREE = REPO / "src" / "skelagnostic" / "viz" / "assets" / "three.min.js"
LOADER = REPO / "tests" / "assets" / "GLTFLoader.js"
IMPORT_MAP = re.compile(r'<script type="importmap">(.*?)</script>', re.S)


def _offline_page(html: str) -> str:
    """The page with its import map pointing at re-exports of the vendored three.js r147."""
    found = IMPORT_MAP.search(html)
    assert found, "the snippet has no import map"
    imports = json.loads(found.group(1))["imports"]
    # the page pins the release the test runs
    assert imports["three"].endswith("/three@0.147.0/build/three.module.js")
    assert imports["three/addons/"].endswith("/three@0.147.0/examples/jsm/")
    offline = {"imports": {"three": "./three.js", "three/addons/": "./addons/"}}
    scripts = '<script src="three.min.js"></script><script src="GLTFLoader.js"></script>'
    return (
        html[: found.start()]
        + scripts
        + f'<script type="importmap">{json.dumps(offline)}</script>'
        + html[found.end() :]
    )


def _serve(folder: Path) -> tuple[http.server.ThreadingHTTPServer, str]:
    handler = functools.partial(QuietHandler, directory=str(folder))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server, f"http://127.0.0.1:{server.server_address[1]}/"


class QuietHandler(http.server.SimpleHTTPRequestHandler):
    """A static file server that does not log each request to stderr."""

    def log_message(self, format: str, *args: object) -> None:
        pass


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Path, str]]:
    """A folder with the page, the vendored three.js and its re-exports, served over HTTP."""
    folder = tmp_path_factory.mktemp("engines")
    html = SNIPPET.read_text(encoding="utf-8")
    (folder / "index.html").write_text(_offline_page(html), encoding="utf-8")
    shutil.copy(THREE, folder / "three.min.js")
    shutil.copy(LOADER, folder / "GLTFLoader.js")
    names = sorted(set(re.findall(r"\bTHREE\.(\w+)", html)))
    (folder / "three.js").write_text(
        "".join(f"export const {n} = window.THREE.{n};\n" for n in names), encoding="utf-8"
    )
    (folder / "addons" / "loaders").mkdir(parents=True)
    (folder / "addons" / "loaders" / "GLTFLoader.js").write_text(
        "export const GLTFLoader = window.THREE.GLTFLoader;\n", encoding="utf-8"
    )
    server, url = _serve(folder)
    try:
        yield folder, url
    finally:
        server.shutdown()
        server.server_close()


def test_the_docs_page_includes_the_tested_snippet() -> None:
    text = PAGE.read_text(encoding="utf-8")
    assert '--8<-- "docs/snippets/threejs-player.html"' in text


#: Joint world positions at the given times, from the page's own scene and mixer.
POSITIONS = """
const [jointCount, times] = arguments;
const { gltf, mixer } = window.clip;
const nodes = new Map();
gltf.scene.traverse((object) => {
  const found = gltf.parser.associations.get(object);
  if (found && found.nodes !== undefined) nodes.set(found.nodes, object);
});
const out = [];
for (const time of times) {
  mixer.setTime(time);
  gltf.scene.updateMatrixWorld(true);
  const row = [];
  for (let i = 0; i < jointCount; i++) {
    const p = nodes.get(i).getWorldPosition(new THREE.Vector3());
    row.push([p.x, p.y, p.z]);
  }
  out.push(row);
}
return {positions: out, revision: THREE.REVISION, canvas: !!document.querySelector("canvas")};
"""


@pytest.mark.parametrize(
    "clip", ["human/lafan1/Lafan1_example.bvh", "dog/mann/D1_001_KAN01_001.bvh"]
)
def test_the_threejs_snippet_plays_a_written_clip(
    site: tuple[Path, str], shared_data: Path, clip: str
) -> None:
    folder, url = site
    motion = sa.read_bvh(shared_data / clip)[:90].to_metres()
    write_motion(motion, folder / "clip.glb")
    with ViewerBrowser(size=(320, 240)) as browser:
        browser.driver.get(url + "index.html")
        end = time.monotonic() + 60.0
        while not browser.driver.execute_script("return !!window.clip"):
            assert time.monotonic() < end, "the page did not load clip.glb within 60 s"
            time.sleep(0.05)
        frames = [0, 1, 30, 60, 88]  # before the last: a looping clip wraps there
        result = browser.driver.execute_script(
            POSITIONS, motion.num_joints, [f / motion.fps for f in frames]
        )
        logs = browser.driver.get_log("browser")
    errors = [e["message"] for e in logs if e["level"] == "SEVERE" and "favicon" not in str(e)]
    assert result["revision"] == "147" and result["canvas"]
    assert not errors, errors
    got = np.asarray(result["positions"], dtype=np.float64)
    expected = motion.global_positions()[frames].double().numpy()
    height = motion.skeleton.height()
    assert float(np.abs(got - expected).max()) <= 1e-4 * height
