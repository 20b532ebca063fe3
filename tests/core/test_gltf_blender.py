"""glTF through Blender: Blender's own exports read back, and Blender reads ours.

Blender runs headless (``blender -b``) with its bundled BVH and glTF add-ons:

* a BVH clip imported into Blender and exported as glTF (an armature whose bones
  carry rest rotations, under an armature object, with scale channels) must read
  back as the BVH's motion: same joints in the same order, fps, frames and joint
  positions;
* a file of ``write_gltf`` imported into Blender (an armature, an action) and
  exported again must read back as the motion written.

Skipped where Blender is not installed (Debian: ``apt-get install blender
python3-numpy``; CI installs neither, so these run only where a developer did).
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

import skelagnostic as sa

BLENDER = shutil.which("blender")

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(BLENDER is None, reason="Blender is not installed"),
]

#: Run inside Blender: import a BVH or glTF file, export it as .glb. Two shims let
#: Debian's Blender 3.4 run its add-ons on Python 3.11 and numpy >= 1.24: the BVH
#: importer opens files with mode "rU" and the glTF importer uses ``np.bool``.
SCRIPT = """
import builtins
import sys

import bpy
import numpy

_open = builtins.open
builtins.open = lambda file, mode="r", *a, **k: _open(file, mode.replace("U", ""), *a, **k)
if not hasattr(numpy, "bool"):
    numpy.bool = bool

source, target = sys.argv[sys.argv.index("--") + 1 :]
bpy.ops.wm.read_factory_settings(use_empty=True)
if source.endswith(".bvh"):
    bpy.ops.import_anim.bvh(
        filepath=source, global_scale=1.0, update_scene_fps=True,
        update_scene_duration=True, axis_forward="-Z", axis_up="Y",
    )
else:
    bpy.ops.import_scene.gltf(filepath=source)
bones = [len(o.data.bones) for o in bpy.context.scene.objects if o.type == "ARMATURE"]
print("ARMATURE BONES", bones)
bpy.ops.export_scene.gltf(filepath=target, export_format="GLB", export_animations=True)
"""


def _through_blender(source: Path, target: Path, tmp_path: Path) -> str:
    script = tmp_path / "blender_io.py"
    script.write_text(SCRIPT, encoding="utf-8")
    proc = subprocess.run(
        [
            BLENDER,
            "-b",
            "--factory-startup",
            "--python",
            str(script),
            "--",
            str(source),
            str(target),
        ],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    log = proc.stdout + proc.stderr
    if "No module named 'numpy'" in log:
        pytest.skip("Blender's Python has no numpy (Debian: apt-get install python3-numpy)")
    assert target.is_file(), log[-3000:]
    return log


def _matched(motion: sa.Motion, back: sa.Motion) -> np.ndarray:
    """``back``'s joint positions in ``motion``'s joint order (names must match)."""
    order = [back.skeleton.joint_names.index(n) for n in motion.skeleton.joint_names]
    return back.global_positions().numpy()[:, order]


@pytest.mark.parametrize(
    "clip", [("human", "lafan1", "Lafan1_example.bvh"), ("dog", "mann", "D1_001_KAN01_001.bvh")]
)
def test_blender_export_of_a_bvh_clip_reads_back_as_that_clip(shared_data, tmp_path, clip):
    source = shared_data.joinpath(*clip)
    motion = sa.read_bvh(source)
    _through_blender(source, tmp_path / "blender.glb", tmp_path)
    back = sa.read_gltf(tmp_path / "blender.glb")
    assert back.skeleton.joint_names == motion.skeleton.joint_names  # same order, too
    assert back.fps == motion.fps and back.num_frames == motion.num_frames
    error = np.abs(_matched(motion, back) - motion.global_positions().numpy()).max()
    assert error <= 2e-5 * motion.skeleton.height(), error


def test_blender_imports_write_gltf_output_as_an_armature(shared_data, tmp_path):
    # Blender plays glTF at its scene rate (24 fps unless changed): write at 24 fps
    motion = sa.read_bvh(shared_data / "human" / "lafan1" / "Lafan1_example.bvh")[:150]
    motion = motion.resample(24.0)
    sa.write_gltf(motion, tmp_path / "ours.glb")
    log = _through_blender(tmp_path / "ours.glb", tmp_path / "again.glb", tmp_path)
    assert f"ARMATURE BONES [{motion.num_joints}]" in log
    back = sa.read_gltf(tmp_path / "again.glb")
    assert back.num_frames == motion.num_frames
    error = np.abs(_matched(motion, back) - motion.global_positions().numpy()).max()
    assert error <= 2e-5 * motion.skeleton.height(), error
