"""Files of ``write_gltf`` loaded by three.js's own GLTFLoader in headless Chromium.

The page holds the vendored three.js r147 and its GLTFLoader of the same release
(``tests/assets/GLTFLoader.js``); it parses the file, plays its animation with an
``AnimationMixer`` and reports every joint node's world position at a few frames.
Those must match :meth:`Motion.global_positions` within 1e-4 of the skeleton's
height. Skipped, like the viewer's browser tests, when Chromium, chromedriver or
selenium is missing.
"""

from __future__ import annotations

import base64
import json
from pathlib import Path

import numpy as np
import pytest

import skelagnostic as sa
from skelagnostic.viz.browser import ViewerBrowser, browser_available

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(
        browser_available() is not None, reason=f"no headless browser: {browser_available()}"
    ),
]

REPO = Path(__file__).resolve().parents[2]
THREE = REPO / "src" / "skelagnostic" / "viz" / "assets" / "three.min.js"
LOADER = REPO / "tests" / "assets" / "GLTFLoader.js"

#: The page: three.js and the loader as scripts, and one function the test calls.
PAGE = """<!doctype html><meta charset="utf-8">
<script src="{three}"></script>
<script src="{loader}"></script>
<script>
window.jointPositions = function (content, binary, jointCount, frames, done) {{
  const data = binary ? Uint8Array.from(atob(content), (c) => c.charCodeAt(0)).buffer : content;
  new THREE.GLTFLoader().parse(data, "", (gltf) => {{
    const nodes = new Map();
    gltf.scene.traverse((object) => {{
      const found = gltf.parser.associations.get(object);
      if (found && found.nodes !== undefined) nodes.set(found.nodes, object);
    }});
    const mixer = new THREE.AnimationMixer(gltf.scene);
    const action = mixer.clipAction(gltf.animations[0]);
    action.setLoop(THREE.LoopOnce);  // a looping clip shows frame 0 again at its end
    action.clampWhenFinished = true;
    action.play();
    const out = [];
    for (const time of frames) {{
      mixer.setTime(time);
      gltf.scene.updateMatrixWorld(true);
      const row = [];
      for (let i = 0; i < jointCount; i++) {{
        const p = nodes.get(i).getWorldPosition(new THREE.Vector3());
        row.push([p.x, p.y, p.z]);
      }}
      out.push(row);
    }}
    let skinned = 0;
    gltf.scene.traverse((object) => {{ if (object.isSkinnedMesh) skinned += 1; }});
    done({{positions: out, revision: THREE.REVISION, skinned: skinned}});
  }}, (error) => done({{error: String(error)}}));
}};
</script>
"""


@pytest.fixture(scope="module")
def browser(tmp_path_factory: pytest.TempPathFactory):
    page = tmp_path_factory.mktemp("threejs") / "gltf.html"
    page.write_text(PAGE.format(three=THREE.as_uri(), loader=LOADER.as_uri()), encoding="utf-8")
    with ViewerBrowser(size=(320, 240)) as chromium:
        chromium.driver.get(page.as_uri())
        chromium.driver.set_script_timeout(120)
        yield chromium


def _three_positions(
    browser: ViewerBrowser, path: Path, num_joints: int, times: list[float]
) -> np.ndarray:
    binary = path.suffix == ".glb"
    content = (
        base64.b64encode(path.read_bytes()).decode("ascii")
        if binary
        else path.read_text(encoding="utf-8")
    )
    result = browser.driver.execute_async_script(
        "window.jointPositions(...arguments);",
        content,
        binary,
        num_joints,
        times,
    )
    assert "error" not in result, result
    assert result["revision"] == "147"
    assert result["skinned"] == 1  # the bone mesh, bound to the joints
    return np.asarray(result["positions"], dtype=np.float64)


#: Joint names three.js rewrites when it binds tracks (spaces, dots, brackets, slashes,
#: colons) or that collide once rewritten, and non-ASCII text.
AWKWARD = ("Left Up.Leg[0]", "a/b", "\u00fc name", "x:y", "dup.name", "dup_name")


def _awkward_names(motion: sa.Motion) -> sa.Motion:
    sk = motion.skeleton
    names = [f"{new} {old}" for new, old in zip(AWKWARD, sk.joint_names, strict=False)]
    names += sk.joint_names[len(names) :]
    renamed = sa.Skeleton(
        names, sk.parents, sk.offsets, end_sites=sk.end_sites, body_groups=sk.body_groups
    )
    return sa.Motion(renamed, motion.rotations, motion.root_positions, motion.fps, name="awkward")


def _motions(shared_data: Path) -> list[sa.Motion]:
    human, _ = sa.procedural.generate("biped22", "walk", seconds=1.0, fps=30, seed=0)
    awkward, _ = sa.procedural.generate("biped17", "run", seconds=1.0, fps=24, seed=2)
    dog, _ = sa.procedural.generate("quadruped", "trot", seconds=1.0, fps=30, seed=1)
    clips = [
        sa.read_bvh(shared_data / "human" / "cmu" / "131_03.bvh")[:200],
        sa.read_bvh(shared_data / "human" / "lafan1" / "Lafan1_example.bvh")[:200],
        sa.read_bvh(shared_data / "dog" / "mann" / "D1_001_KAN01_001.bvh")[:200],
    ]
    return [human, dog, _awkward_names(awkward), *clips]


def test_threejs_gltfloader_places_every_joint_where_global_positions_does(
    browser: ViewerBrowser, shared_data: Path, tmp_path: Path
) -> None:
    worst = {}
    for k, motion in enumerate(_motions(shared_data)):
        suffix = ".gltf" if k % 2 else ".glb"
        path = tmp_path / f"clip{k}{suffix}"
        sa.write_gltf(motion, path)
        frames = sorted(
            {0, 1, motion.num_frames // 3, motion.num_frames // 2, motion.num_frames - 1}
        )
        got = _three_positions(browser, path, motion.num_joints, [f / motion.fps for f in frames])
        expected = motion.global_positions()[frames].double().numpy()
        error = float(np.abs(got - expected).max())
        height = motion.skeleton.height()
        worst[f"{motion.name}{suffix}"] = error / height
        assert error <= 1e-4 * height, (motion.name, suffix, error, height)
    print(json.dumps(worst))
