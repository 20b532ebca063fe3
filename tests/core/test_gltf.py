"""glTF 2.0 export and import: round trips, file consistency, foreign files, bad input.

``_evaluate`` below is a small glTF evaluator of its own (JSON, ``struct`` and 4x4
matrices; no pygltflib, nothing shared with :mod:`skelagnostic.io.gltf`): it gives
every node's world position at a keyframe, the reference for files the reader
must fold (rest rotations, scales, a transformed parent above the skeleton).
"""

from __future__ import annotations

import base64
import json
import math
import struct
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

import skelagnostic as sa
from skelagnostic.core import quaternion as Q

CLIPS = {
    "cmu": ("human", "cmu", "131_03.bvh"),
    "lafan1": ("human", "lafan1", "Lafan1_example.bvh"),
    "dog": ("dog", "mann", "D1_001_KAN01_001.bvh"),
}
#: Round-trip tolerance on lengths, relative to the largest coordinate (float32 storage).
RELATIVE = 1e-6
MEASURED: dict[str, tuple[float, float, float]] = {}


def _errors(a: sa.Motion, b: sa.Motion) -> tuple[float, float, float]:
    """Largest differences: local rotations, root positions, global positions."""
    rotation = float((a.rotations - b.rotations).abs().max())
    root = float((a.root_positions - b.root_positions).abs().max())
    world = float((a.global_positions() - b.global_positions()).abs().max())
    return rotation, root, world


def _assert_round_trip(motion: sa.Motion, back: sa.Motion, label: str) -> None:
    scale = max(1.0, float(motion.global_positions().abs().max()))
    rotation, root, world = _errors(motion, back)
    MEASURED[label] = (rotation, root / scale, world / scale)
    assert back.skeleton == motion.skeleton
    assert back.skeleton.joint_names == motion.skeleton.joint_names
    assert back.skeleton.end_sites == motion.skeleton.end_sites
    assert back.skeleton.channels == motion.skeleton.channels
    assert back.skeleton.up_axis == motion.skeleton.up_axis
    assert back.skeleton.body_root == motion.skeleton.body_root
    assert back.num_frames == motion.num_frames and back.fps == motion.fps
    assert (back.translations is None) == (motion.translations is None)
    assert rotation <= 1e-6, (label, rotation)
    assert root <= RELATIVE * scale and world <= RELATIVE * scale, (label, root, world, scale)


@pytest.mark.parametrize("clip", sorted(CLIPS))
@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_real_clip_round_trips_to_float32(shared_data, tmp_path, clip, suffix):
    motion = sa.read_bvh(shared_data.joinpath(*CLIPS[clip]))
    path = tmp_path / f"{clip}{suffix}"
    sa.write_gltf(motion, path)
    back = sa.read_gltf(path)
    _assert_round_trip(motion, back, f"{clip}{suffix}")
    assert back.name == clip
    # and back to BVH with the file's own channel layout
    sa.write_bvh(back, tmp_path / "again.bvh")
    again = sa.read_bvh(tmp_path / "again.bvh")
    assert again.skeleton.channels == motion.skeleton.channels
    print(clip, suffix, "max errors (rotation, root / size, global / size):", MEASURED)


@pytest.mark.parametrize(("kind", "gait"), [("biped22", "walk"), ("quadruped", "trot")])
def test_procedural_motion_round_trips(tmp_path, kind, gait):
    motion, _ = sa.procedural.generate(kind, gait, seconds=1.5, fps=24, seed=3)
    sa.write_gltf(motion, tmp_path / "m.glb")
    _assert_round_trip(motion, sa.read_gltf(tmp_path / "m.glb"), kind)


def test_animated_translations_units_and_float32_round_trip(tmp_path):
    base, _ = sa.procedural.generate("biped22", "walk", seconds=1.0, fps=30, seed=0)
    offsets = base.skeleton.offsets
    translations = offsets.expand(base.num_frames, -1, -1).clone()
    translations[:, 0] = base.root_positions
    wave = torch.sin(torch.arange(base.num_frames, dtype=torch.float64) / 5.0)
    translations[:, 3, 1] += 2.0 * wave
    motion = sa.Motion(
        base.skeleton,
        base.rotations,
        base.root_positions,
        base.fps,
        translations=translations,
        units="cm",
    ).float()
    sa.write_gltf(motion, tmp_path / "t.gltf")
    back = sa.read_gltf(tmp_path / "t.gltf", dtype=torch.float32)
    assert back.dtype == torch.float32 and back.units == "cm"
    assert back.translations is not None
    assert float((back.translations - motion.translations).abs().max()) <= 1e-5
    _assert_round_trip(motion, back, "translations")


def test_bones_false_writes_no_skin_and_still_reads(tmp_path):
    motion, _ = sa.procedural.generate("quadruped", "walk", seconds=0.5, fps=30, seed=0)
    sa.write_gltf(motion, tmp_path / "plain.gltf", bones=False)
    document = json.loads((tmp_path / "plain.gltf").read_text())
    assert "skins" not in document and "meshes" not in document
    _assert_round_trip(motion, sa.read_gltf(tmp_path / "plain.gltf"), "no skin")


# ----------------------------------------------------------------- file consistency
def _chunks(path: Path) -> tuple[dict, bytes]:
    """The JSON document and binary buffer of a .glb (checked header) or .gltf."""
    raw = path.read_bytes()
    if path.suffix == ".gltf":
        document = json.loads(raw)
        uri = document["buffers"][0]["uri"]
        assert uri.startswith("data:application/octet-stream;base64,")
        return document, base64.b64decode(uri.split(",", 1)[1])
    magic, version, length = struct.unpack_from("<4sII", raw)
    assert (magic, version, length) == (b"glTF", 2, len(raw))
    json_length, json_type = struct.unpack_from("<I4s", raw, 12)
    assert json_type == b"JSON" and json_length % 4 == 0
    document = json.loads(raw[20 : 20 + json_length])
    bin_length, bin_type = struct.unpack_from("<I4s", raw, 20 + json_length)
    assert bin_type == b"BIN\0" and bin_length % 4 == 0
    start = 28 + json_length
    assert start + bin_length == len(raw)
    return document, raw[start : start + bin_length]


_SIZES = {5121: 1, 5123: 2, 5125: 4, 5126: 4}
_WIDTHS = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}
_NUMPY = {5121: "<u1", 5123: "<u2", 5125: "<u4", 5126: "<f4"}


def _read_accessor(document: dict, blob: bytes, index: int) -> np.ndarray:
    accessor = document["accessors"][index]
    view = document["bufferViews"][accessor["bufferView"]]
    width = _WIDTHS[accessor["type"]]
    start = view.get("byteOffset", 0) + accessor.get("byteOffset", 0)
    data = np.frombuffer(
        blob, _NUMPY[accessor["componentType"]], accessor["count"] * width, start
    ).astype(np.float64)
    return data.reshape(accessor["count"], width)


@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_written_file_is_valid_and_self_consistent(shared_data, tmp_path, suffix):
    pygltflib = pytest.importorskip("pygltflib")
    from pygltflib.validator import validate

    motion = sa.read_bvh(shared_data.joinpath(*CLIPS["lafan1"]))[:120]
    path = tmp_path / f"clip{suffix}"
    sa.write_gltf(motion, path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # "provisional function"
        assert validate(pygltflib.GLTF2().load(str(path))) in (None, [])

    document, blob = _chunks(path)
    assert document["asset"]["version"] == "2.0"
    assert document["buffers"][0]["byteLength"] == len(blob) or (
        suffix == ".glb" and len(blob) - document["buffers"][0]["byteLength"] < 4
    )
    for view in document["bufferViews"]:
        assert view["buffer"] == 0
        assert view.get("byteOffset", 0) % 4 == 0
        assert (
            view.get("byteOffset", 0) + view["byteLength"] <= document["buffers"][0]["byteLength"]
        )
    for accessor in document["accessors"]:
        view = document["bufferViews"][accessor["bufferView"]]
        size = _SIZES[accessor["componentType"]] * _WIDTHS[accessor["type"]]
        assert accessor.get("byteOffset", 0) + accessor["count"] * size <= view["byteLength"]
    num_joints, num_frames = motion.num_joints, motion.num_frames
    # nodes: the joints in joint order, each child with one parent
    nodes = document["nodes"]
    assert [n["name"] for n in nodes[:num_joints]] == motion.skeleton.joint_names
    children = [c for n in nodes for c in n.get("children", [])]
    assert len(children) == len(set(children))
    for j, p in enumerate(motion.skeleton.parents):
        if p >= 0:
            assert j in nodes[p]["children"]
        assert np.allclose(nodes[j]["translation"], motion.skeleton.offsets[j].numpy(), atol=0)
    # the animation: one clock, keyed at k / fps, a rotation per joint, root translation
    (animation,) = document["animations"]
    inputs = {s["input"] for s in animation["samplers"]}
    assert len(inputs) == 1
    clock = document["accessors"][inputs.pop()]
    times = _read_accessor(document, blob, document["accessors"].index(clock))[:, 0]
    assert clock["min"] == [0.0] and math.isclose(clock["max"][0], times[-1])
    assert np.allclose(times, np.arange(num_frames) / motion.fps, atol=1e-6)
    targets = {}
    for channel in animation["channels"]:
        sampler = animation["samplers"][channel["sampler"]]
        assert sampler.get("interpolation", "LINEAR") == "LINEAR"
        values = _read_accessor(document, blob, sampler["output"])
        assert len(values) == num_frames
        targets[(channel["target"]["node"], channel["target"]["path"])] = values
    assert {n for n, p in targets if p == "rotation"} == set(range(num_joints))
    assert {n for n, p in targets if p == "translation"} == {0}
    for j in range(num_joints):
        xyzw = targets[(j, "rotation")]
        assert np.allclose(np.linalg.norm(xyzw, axis=1), 1.0, atol=1e-6)
        wxyz = torch.from_numpy(xyzw[:, [3, 0, 1, 2]])
        assert torch.allclose(wxyz, motion.rotations[:, j], atol=1e-6)
    root = motion.root_positions.numpy()
    assert np.abs(targets[(0, "translation")] - root).max() <= 1e-6 * np.abs(root).max()
    # the skin: one inverse bind matrix per joint, the bone mesh skinned to joints
    (skin,) = document["skins"]
    assert skin["joints"] == list(range(num_joints))
    assert document["accessors"][skin["inverseBindMatrices"]]["count"] == num_joints
    (primitive,) = document["meshes"][0]["primitives"]
    joints = _read_accessor(document, blob, primitive["attributes"]["JOINTS_0"])
    assert joints.max() < num_joints
    position = document["accessors"][primitive["attributes"]["POSITION"]]
    assert len(position["min"]) == 3 and len(position["max"]) == 3


# ------------------------------------------------------- an independent evaluator
def _matrix(translation=None, rotation=None, scale=None) -> np.ndarray:
    x, y, z, w = rotation if rotation is not None else (0.0, 0.0, 0.0, 1.0)
    rot = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    out = np.eye(4)
    out[:3, :3] = rot * np.asarray(scale if scale is not None else (1.0, 1.0, 1.0))[None, :]
    out[:3, 3] = translation if translation is not None else (0.0, 0.0, 0.0)
    return out


def _evaluate(document: dict, blobs: list[bytes], key: int) -> np.ndarray:
    """World position of every node at keyframe ``key`` of animation 0 (all samplers
    keyed alike; CUBICSPLINE takes the middle value of each triple)."""
    animated: dict[tuple[int, str], np.ndarray] = {}
    animation = document["animations"][0]
    for channel in animation["channels"]:
        sampler = animation["samplers"][channel["sampler"]]
        accessor = document["accessors"][sampler["output"]]
        view = document["bufferViews"][accessor["bufferView"]]
        width = _WIDTHS[accessor["type"]]
        values = np.frombuffer(
            blobs[view["buffer"]],
            "<f4",
            accessor["count"] * width,
            view.get("byteOffset", 0) + accessor.get("byteOffset", 0),
        ).reshape(-1, width)
        if sampler.get("interpolation") == "CUBICSPLINE":
            values = values[1::3]
        animated[(channel["target"]["node"], channel["target"]["path"])] = values[key]
    nodes = document["nodes"]
    world = [None] * len(nodes)

    def visit(i: int, above: np.ndarray) -> None:
        node = nodes[i]
        if "matrix" in node:
            local = np.asarray(node["matrix"], dtype=np.float64).reshape(4, 4).T
        else:
            local = _matrix(
                animated.get((i, "translation"), node.get("translation")),
                animated.get((i, "rotation"), node.get("rotation")),
                animated.get((i, "scale"), node.get("scale")),
            )
        world[i] = above @ local
        for c in node.get("children", []):
            visit(c, world[i])

    for root in document["scenes"][0]["nodes"]:
        visit(root, np.eye(4))
    return np.array([m[:3, 3] for m in world])


def _add_accessor(document: dict, blobs: list[bytes], values: np.ndarray, kind: str) -> int:
    """Append ``values`` as float32 in a new data-URI buffer; returns the accessor."""
    raw = np.ascontiguousarray(values, dtype="<f4").tobytes()
    document["buffers"].append(
        {
            "byteLength": len(raw),
            "uri": "data:application/octet-stream;base64," + base64.b64encode(raw).decode(),
        }
    )
    blobs.append(raw)
    document["bufferViews"].append(
        {"buffer": len(document["buffers"]) - 1, "byteOffset": 0, "byteLength": len(raw)}
    )
    accessor = {
        "bufferView": len(document["bufferViews"]) - 1,
        "componentType": 5126,
        "count": len(values),
        "type": kind,
    }
    if kind == "SCALAR":
        accessor["min"], accessor["max"] = [float(values.min())], [float(values.max())]
    document["accessors"].append(accessor)
    return len(document["accessors"]) - 1


def _written(tmp_path: Path, bones: bool = True) -> tuple[sa.Motion, dict, list[bytes]]:
    motion, _ = sa.procedural.generate("biped22", "run", seconds=1.0, fps=20, seed=5)
    path = tmp_path / "base.gltf"
    sa.write_gltf(motion, path, bones=bones)
    document, blob = _chunks(path)
    return motion, document, [blob]


def _save(tmp_path: Path, document: dict, name: str = "foreign.gltf") -> Path:
    path = tmp_path / name
    path.write_text(json.dumps(document), encoding="utf-8")
    return path


def _channel(document: dict, node: int, path: str) -> dict:
    animation = document["animations"][0]
    return next(c for c in animation["channels"] if c["target"] == {"node": node, "path": path})


def test_evaluator_agrees_with_global_positions_on_a_written_file(tmp_path):
    motion, document, blobs = _written(tmp_path)
    expected = motion.global_positions().numpy()
    for key in (0, 7, motion.num_frames - 1):
        got = _evaluate(document, blobs, key)[: motion.num_joints]
        assert np.abs(got - expected[key]).max() <= 1e-4


def test_foreign_structure_is_folded_into_the_motion(tmp_path):
    """An armature node above the root (rotated, scaled, moved), a joint with a rest
    rotation and no rotation channel, a uniform scale, a matrix node, STEP and
    CUBICSPLINE samplers, no frame-rate hint and no metadata: the motion read must
    place every joint where the file does."""
    motion, document, blobs = _written(tmp_path, bones=False)
    num_joints, num_frames = motion.num_joints, motion.num_frames
    nodes = document["nodes"]
    del document["animations"][0]["extras"], nodes[0]["extras"]
    # Blender-like armature object: Z-up to Y-up rotation, centimetres to metres
    half = math.sqrt(0.5)
    nodes.append(
        {
            "name": "Armature",
            "children": [0],
            "rotation": [-half, 0.0, 0.0, half],
            "scale": [0.01, 0.01, 0.01],
            "translation": [1.0, 2.0, 3.0],
        }
    )
    document["scenes"][0]["nodes"] = [len(nodes) - 1]
    animation = document["animations"][0]
    # joint 2: a rest rotation, not animated
    animation["channels"].remove(_channel(document, 2, "rotation"))
    nodes[2]["rotation"] = [0.0, 0.0, math.sin(0.3), math.cos(0.3)]
    # joint 5: a uniform scale of 1.5
    nodes[5]["scale"] = [1.5, 1.5, 1.5]
    # joint 9: its rest as a matrix (rotation about y and its offset), not animated
    animation["channels"].remove(_channel(document, 9, "rotation"))
    rest = _matrix(nodes[9].pop("translation"), [0.0, math.sin(0.2), 0.0, math.cos(0.2)])
    nodes[9]["matrix"] = rest.T.reshape(-1).tolist()
    # joint 4: STEP; joint 6: CUBICSPLINE with zero tangents
    animation["samplers"][_channel(document, 4, "rotation")["sampler"]]["interpolation"] = "STEP"
    cubic = animation["samplers"][_channel(document, 6, "rotation")["sampler"]]
    keys = _read_accessor(document, blobs[0], cubic["output"])
    triples = np.zeros((num_frames, 3, 4))
    triples[:, 1] = keys
    cubic["output"] = _add_accessor(document, blobs, triples.reshape(-1, 4), "VEC4")
    cubic["interpolation"] = "CUBICSPLINE"
    path = _save(tmp_path, document)

    back = sa.read_gltf(path)
    assert back.num_frames == num_frames and back.fps == motion.fps
    assert back.num_joints == num_joints  # the armature node is not a joint
    got = back.global_positions().numpy()
    for key in range(0, num_frames, 4):
        expected = _evaluate(document, blobs, key)[:num_joints]
        assert np.abs(got[key] - expected).max() <= 1e-5, key


def test_channels_keyed_at_different_times_are_resampled(tmp_path):
    motion, document, blobs = _written(tmp_path)
    animation = document["animations"][0]
    sampler = animation["samplers"][_channel(document, 3, "rotation")["sampler"]]
    keys = _read_accessor(document, blobs[0], sampler["output"])
    times = _read_accessor(document, blobs[0], sampler["input"])[:, 0]
    sampler["input"] = _add_accessor(document, blobs, times[::2], "SCALAR")
    sampler["output"] = _add_accessor(document, blobs, keys[::2], "VEC4")
    back = sa.read_gltf(_save(tmp_path, document))
    assert back.num_frames == motion.num_frames and back.fps == motion.fps
    expected = motion.rotations.numpy()
    # on the sparse channel's keys the values are the file's; between them a slerp
    assert np.abs(back.rotations[::2, 3].numpy() - expected[::2, 3]).max() <= 1e-6
    middle = Q.slerp(motion.rotations[0:-2:2, 3], motion.rotations[2::2, 3], 0.5)
    odd = back.rotations[1:-1:2, 3]
    assert torch.allclose(odd, middle[: len(odd)], atol=1e-5)
    others = [j for j in range(motion.num_joints) if j != 3]
    assert np.abs(back.rotations[:, others].numpy() - expected[:, others]).max() <= 1e-6


# --------------------------------------------------------------------- bad input
def _mutated(tmp_path: Path, change) -> Path:
    _, document, _ = _written(tmp_path)
    change(document)
    return _save(tmp_path, document, "bad.gltf")


def _add_short_clock(document: dict) -> None:
    sampler = document["animations"][0]["samplers"][0]
    accessor = dict(document["accessors"][sampler["input"]], count=5)
    document["accessors"].append(accessor)
    sampler["input"] = len(document["accessors"]) - 1


BAD_DOCUMENTS = {
    "no animation": (lambda d: d.pop("animations"), "animations", "no animation"),
    "missing node": (
        lambda d: d["animations"][0]["channels"][0]["target"].update(node=999),
        "animations[0].channels[0].target.node",
        "nodes 999",
    ),
    "sampler counts": (
        _add_short_clock,
        "animations[0].samplers[0].output",
        "for 5 keyframe times",
    ),
    "missing sampler": (
        lambda d: d["animations"][0]["channels"][1].update(sampler=10**6),
        "animations[0].channels[1].sampler",
        "sampler 1000000",
    ),
    "accessor too long": (
        lambda d: d["accessors"][1].update(count=10**6),
        "accessors[1]",
        "do not fit",
    ),
    "interpolation": (
        lambda d: d["animations"][0]["samplers"][0].update(interpolation="BEZIER"),
        "animations[0].samplers[0].interpolation",
        "BEZIER",
    ),
    "version": (lambda d: d["asset"].update(version="1.0"), "asset.version", "2.x"),
    "skeleton not animated": (
        lambda d: d["animations"][0].update(
            channels=[{"sampler": 0, "target": {"node": len(d["nodes"]) - 1, "path": "rotation"}}]
        ),
        "animations[0]",
        "moves none of the skeleton's",
    ),
    "two parents": (
        lambda d: d["nodes"][1].setdefault("children", []).append(2),
        "nodes[1].children",
        "more than one parent",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD_DOCUMENTS))
def test_malformed_document_names_file_and_field(tmp_path, case):
    change, field, words = BAD_DOCUMENTS[case]
    path = _mutated(tmp_path, change)
    with pytest.raises(sa.GLTFError) as caught:
        sa.read_gltf(path)
    message = str(caught.value)
    assert str(path) in message and field in message and words in message, message
    assert caught.value.path == path


def test_not_gltf_truncated_missing_and_directory(tmp_path):
    bvh = tmp_path / "clip.gltf"
    bvh.write_text("HIERARCHY\nROOT Hips\n")
    with pytest.raises(sa.GLTFError, match="not a glTF file"):
        sa.read_gltf(bvh)
    for name, text in (("array.gltf", "[1, 2]"), ("empty.gltf", "{}")):
        (tmp_path / name).write_text(text)
        with pytest.raises(sa.GLTFError, match="not a glTF file"):
            sa.read_gltf(tmp_path / name)
    motion, _ = sa.procedural.generate("biped22", "walk", seconds=0.3, fps=30)
    sa.write_gltf(motion, tmp_path / "whole.glb")
    cut = tmp_path / "cut.glb"
    cut.write_bytes((tmp_path / "whole.glb").read_bytes()[:200])
    with pytest.raises(sa.GLTFError, match=r"cut\.glb"):
        sa.read_gltf(cut)
    with pytest.raises(sa.GLTFError, match="no such file"):
        sa.read_gltf(tmp_path / "absent.glb")
    with pytest.raises(sa.GLTFError, match="is a directory"):
        sa.read_gltf(tmp_path)


def test_varying_scale_and_non_uniform_scale_are_errors(tmp_path):
    motion, document, blobs = _written(tmp_path)
    grow = np.linspace(1.0, 2.0, motion.num_frames)[:, None].repeat(3, axis=1)
    animation = document["animations"][0]
    animation["samplers"].append(
        {
            "input": animation["samplers"][0]["input"],
            "output": _add_accessor(document, blobs, grow, "VEC3"),
        }
    )
    animation["channels"].append(
        {"sampler": len(animation["samplers"]) - 1, "target": {"node": 4, "path": "scale"}}
    )
    with pytest.raises(sa.GLTFError, match="animated scale is not supported"):
        sa.read_gltf(_save(tmp_path, document, "grow.gltf"))
    _, document, _ = _written(tmp_path)
    document["nodes"][3]["scale"] = [1.0, 2.0, 1.0]
    with pytest.raises(sa.GLTFError, match=r"nodes\[3\]\.scale"):
        sa.read_gltf(_save(tmp_path, document, "stretched.gltf"))


def test_writing_checks_suffix_and_target(tmp_path):
    motion, _ = sa.procedural.generate("biped22", "walk", seconds=0.3, fps=30)
    with pytest.raises(sa.GLTFError, match=r"ends in \.glb or \.gltf"):
        sa.write_gltf(motion, tmp_path / "clip.fbx")
    with pytest.raises(sa.GLTFError, match="cannot write"):
        sa.write_gltf(motion, tmp_path / "missing" / "clip.glb")
    assert not (tmp_path / "missing").exists()


def test_missing_pygltflib_names_the_extra(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "pygltflib", None)  # import pygltflib -> ImportError
    motion, _ = sa.procedural.generate("biped22", "walk", seconds=0.3, fps=30)
    with pytest.raises(sa.GLTFError, match=r"skelagnostic\[gltf\]"):
        sa.write_gltf(motion, tmp_path / "clip.glb")
    with pytest.raises(sa.GLTFError, match=r"skelagnostic\[gltf\]"):
        sa.read_gltf(tmp_path / "clip.glb")


def test_motion_files_choose_the_format_by_suffix(tmp_path):
    from skelagnostic.io import read_motion, write_motion

    motion, _ = sa.procedural.generate("biped17", "walk", seconds=0.3, fps=30)
    for name in ("m.bvh", "m.GLB", "m.gltf"):
        write_motion(motion, tmp_path / name)
        back = read_motion(tmp_path / name)
        assert torch.allclose(back.global_positions(), motion.global_positions(), atol=1e-4)
    assert (tmp_path / "m.GLB").read_bytes()[:4] == b"glTF"
    assert (tmp_path / "m.gltf").read_text().lstrip().startswith("{")
    with pytest.raises(sa.SkelagnosticError, match=r"m\.fbx: a motion file ends in \.bvh"):
        write_motion(motion, tmp_path / "m.fbx")
    assert not (tmp_path / "m.fbx").exists()


def test_channels_reduced_to_one_or_two_keys_hold_their_values(tmp_path):
    """Exporters drop the keys of static channels (Blender keeps two, or one)."""
    motion, document, blobs = _written(tmp_path)
    animation = document["animations"][0]
    times = _read_accessor(document, blobs[0], animation["samplers"][0]["input"])[:, 0]
    held = {
        5: [0.0, math.sin(0.4), 0.0, math.cos(0.4)],
        8: [math.sin(0.1), 0.0, 0.0, math.cos(0.1)],
    }
    for node, count in ((5, 2), (8, 1)):
        sampler = animation["samplers"][_channel(document, node, "rotation")["sampler"]]
        keys = times[[0, -1]] if count == 2 else times[:1]
        sampler["input"] = _add_accessor(document, blobs, keys, "SCALAR")
        sampler["output"] = _add_accessor(document, blobs, np.array([held[node]] * count), "VEC4")
    back = sa.read_gltf(_save(tmp_path, document))
    assert back.num_frames == motion.num_frames and back.fps == motion.fps
    for node, xyzw in held.items():
        wxyz = torch.tensor([xyzw[3], *xyzw[:3]], dtype=torch.float64)
        assert torch.allclose(back.rotations[:, node], wxyz.expand(motion.num_frames, 4), atol=1e-6)
    others = [j for j in range(motion.num_joints) if j not in held]
    assert torch.allclose(back.rotations[:, others], motion.rotations[:, others], atol=1e-6)


def test_render_and_stick_figures_read_gltf_by_suffix(tmp_path, capsys):
    from skelagnostic.cli.render import main as render
    from skelagnostic.viz.stick import to_stick_figures

    motion, _ = sa.procedural.generate("quadruped", "walk", seconds=0.5, fps=20)
    sa.write_gltf(motion, tmp_path / "dog.glb")
    sa.write_bvh(motion, tmp_path / "dog.txt")  # any other name is still read as BVH
    for figure in to_stick_figures([tmp_path / "dog.glb", tmp_path / "dog.txt"]):
        assert figure.name == "dog"
        assert np.abs(figure.positions - motion.global_positions().numpy()).max() <= 1e-4
    out = tmp_path / "dog.png"
    assert render([str(tmp_path / "dog.glb"), f"out={out}", "size=64", "frames=2"]) == 0
    assert out.is_file() and str(out) in capsys.readouterr().out
