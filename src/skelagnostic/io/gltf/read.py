"""glTF reading: the skeletal animation of any glTF 2.0 file as a Motion."""

from __future__ import annotations

import base64
import heapq
import json
import math
import warnings
from pathlib import Path
from types import ModuleType
from typing import Any
from urllib.parse import unquote

import numpy as np
import torch

from skelagnostic.core import quaternion as Q
from skelagnostic.core.axes import to_canonical
from skelagnostic.core.motion import UNITS, Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.errors import GLTFError, SkeletonError
from skelagnostic.io.bvh import snap_rate
from skelagnostic.io.gltf._common import (
    _COMPONENTS,
    _EXTRA,
    _INTERPOLATIONS,
    _MAX_FRAMES,
    _NORMALIZE,
    _PATH_WIDTH,
    _SCALE_TOLERANCE,
    _WIDTH,
    _declared_axes,
    _end_sites,
    _metadata,
    _pygltflib,
    _unique,
)
from skelagnostic.io.gltf._tracks import Track, mul_xyzw, rotate_xyzw, to_wxyz

__all__ = ["read_gltf"]


def _is_index(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _uniform_scale(scale: np.ndarray) -> float | None:
    """The common value of a 3-vector scale, or ``None`` if it is not uniform and positive."""
    s = float(scale.mean())
    if s <= 0 or np.abs(scale - s).max() > _SCALE_TOLERANCE * s:
        return None
    return s


class _Reader:
    """One glTF file being read: checked access to its fields and accessors."""

    def __init__(self, pg: ModuleType, raw: bytes, path: Path) -> None:
        self.path = path
        binary = raw[:4] == b"glTF"
        try:
            if binary:
                with warnings.catch_warnings():  # unknown chunks, versions: checked below
                    warnings.simplefilter("ignore")
                    gltf = pg.GLTF2.load_from_bytes(raw)
            else:
                text = raw.decode("utf-8-sig")
                document = json.loads(text)
                if not isinstance(document, dict) or "asset" not in document:
                    raise ValueError("the JSON document is not an object with an 'asset'")
                gltf = pg.GLTF2.from_json(text)
        except GLTFError:
            raise
        except Exception as exc:  # pygltflib raises many kinds on damaged input
            kind = "a glTF binary (.glb) that cannot be read" if binary else "not a glTF file"
            raise GLTFError(f"{kind}: {exc}", path) from None
        if gltf is None:
            raise GLTFError("a glTF binary (.glb) without a JSON chunk", path)
        version = getattr(gltf.asset, "version", None)
        if not isinstance(version, str) or not version.startswith("2."):
            raise GLTFError(
                f"glTF version {version!r}: only glTF 2.x is read", path, "asset.version"
            )
        self.gltf = gltf
        self.binary = binary
        self._buffers: dict[int, bytes] = {}

    def error(self, reason: str, field: str | None = None) -> GLTFError:
        return GLTFError(reason, self.path, field)

    def items(self, name: str) -> list[Any]:
        value = getattr(self.gltf, name, None) or []
        if not isinstance(value, list):
            raise self.error("must be a list", name)
        return value

    def index(self, value: Any, collection: str, field: str) -> int:
        """``value`` checked as an index into the top-level list ``collection``."""
        count = len(self.items(collection))
        if not _is_index(value) or not 0 <= value < count:
            raise self.error(
                f"refers to {collection} {value!r}, the file has {count} {collection}", field
            )
        return value

    def buffer(self, index: int) -> bytes:
        if index in self._buffers:
            return self._buffers[index]
        field = f"buffers[{index}]"
        buffer = self.items("buffers")[index]
        uri = buffer.uri
        if uri is None:
            data = self.gltf.binary_blob() if self.binary and index == 0 else None
            if data is None:
                raise self.error("has no uri and the file has no binary chunk", field)
        elif not isinstance(uri, str):
            raise self.error(f"uri must be a string, got {uri!r}", field + ".uri")
        elif uri.startswith("data:"):
            try:
                data = base64.b64decode(uri.partition(",")[2], validate=True)
            except ValueError:
                raise self.error("the data URI is not valid base64", field + ".uri") from None
        else:
            source = self.path.parent / unquote(uri)
            try:
                data = source.read_bytes()
            except OSError as exc:
                raise self.error(f"cannot read {source}: {exc.strerror}", field + ".uri") from None
        length = buffer.byteLength
        if not _is_index(length) or len(data) < length:
            raise self.error(f"byteLength {length!r} but the data has {len(data)} bytes", field)
        self._buffers[index] = data
        return data

    def accessor(self, index: Any, field: str, kinds: tuple[str, ...]) -> np.ndarray:
        """An accessor's values as float64 ``[count, width]`` (normalized integers scaled)."""
        index = self.index(index, "accessors", field)
        where = f"accessors[{index}]"
        acc = self.items("accessors")[index]
        if acc.type not in kinds:
            raise self.error(f"type {acc.type!r} where {' or '.join(kinds)} is needed", where)
        component = _COMPONENTS.get(acc.componentType)
        if component is None:
            raise self.error(f"unknown componentType {acc.componentType!r}", where)
        if component is not np.float32 and not (acc.normalized and component in _NORMALIZE):
            raise self.error("animation data must be float or normalized integers", where)
        if acc.sparse is not None:
            raise self.error("sparse accessors are not supported", where + ".sparse")
        count = acc.count
        if not _is_index(count) or count < 1:
            raise self.error(f"count must be a positive integer, got {count!r}", where)
        width = _WIDTH[acc.type]
        dtype = np.dtype(component).newbyteorder("<")
        if acc.bufferView is None:
            return np.zeros((count, width))
        view_index = self.index(acc.bufferView, "bufferViews", where + ".bufferView")
        view = self.items("bufferViews")[view_index]
        vfield = f"bufferViews[{view_index}]"
        buffer = self.buffer(self.index(view.buffer, "buffers", vfield + ".buffer"))
        view_offset, length = view.byteOffset or 0, view.byteLength
        if not _is_index(view_offset) or not _is_index(length) or view_offset < 0:
            raise self.error("byteOffset and byteLength must be integers", vfield)
        if view_offset + length > len(buffer):
            raise self.error(
                f"bytes {view_offset}..{view_offset + length} lie outside the buffer "
                f"({len(buffer)} bytes)",
                vfield,
            )
        element = width * dtype.itemsize
        stride = view.byteStride or element
        offset = acc.byteOffset or 0
        if not _is_index(stride) or not _is_index(offset) or stride < element or offset < 0:
            raise self.error(f"byteOffset {offset!r} / byteStride {stride!r} are invalid", where)
        if offset + stride * (count - 1) + element > length:
            raise self.error(
                f"{count} elements of {element} bytes (stride {stride}) from byte {offset} "
                f"do not fit in its bufferView ({length} bytes)",
                where,
            )
        values = np.ndarray(
            (count, width),
            dtype=dtype,
            buffer=buffer,
            offset=view_offset + offset,
            strides=(stride, dtype.itemsize),
        ).astype(np.float64)
        if component is not np.float32:
            values = np.maximum(values / _NORMALIZE[component], -1.0)
        if not np.isfinite(values).all():
            raise self.error("holds a NaN or infinite value", where)
        return values

    # ----------------------------------------------------------------- hierarchy
    def parents(self) -> list[int]:
        """Parent node of every node (``-1`` for none), checked for cycles."""
        nodes = self.items("nodes")
        parent = [-1] * len(nodes)
        for i, node in enumerate(nodes):
            children = node.children or []
            if not isinstance(children, list):
                raise self.error("must be a list of node indices", f"nodes[{i}].children")
            for c in children:
                field = f"nodes[{i}].children"
                c = self.index(c, "nodes", field)
                if parent[c] >= 0 or c == i:
                    raise self.error(f"node {c} has more than one parent", field)
                parent[c] = i
        for i in range(len(nodes)):
            seen, k = 0, i
            while k >= 0:
                k, seen = parent[k], seen + 1
                if seen > len(nodes):
                    raise self.error("the node hierarchy has a cycle", f"nodes[{i}].children")
        return parent

    def local(self, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A node's rest ``(translation, rotation (x, y, z, w), scale)``."""
        node = self.items("nodes")[i]
        field = f"nodes[{i}]"
        if node.matrix is not None:
            matrix = self.floats(node.matrix, 16, field + ".matrix").reshape(4, 4).T
            linear = matrix[:3, :3]
            scale = np.linalg.norm(linear, axis=0)
            if np.linalg.det(linear) <= 0 or scale.min() <= 0:
                raise self.error("a mirroring or degenerate matrix is not supported", field)
            quat = Q.from_matrix(torch.from_numpy(linear / scale))
            return matrix[:3, 3], quat.numpy()[[1, 2, 3, 0]], scale
        translation = (
            np.zeros(3)
            if node.translation is None
            else self.floats(node.translation, 3, field + ".translation")
        )
        rotation = (
            np.array([0.0, 0.0, 0.0, 1.0])
            if node.rotation is None
            else self.floats(node.rotation, 4, field + ".rotation")
        )
        norm = float(np.linalg.norm(rotation))
        if norm < 1e-8:
            raise self.error("is a zero quaternion", field + ".rotation")
        scale = np.ones(3) if node.scale is None else self.floats(node.scale, 3, field + ".scale")
        return translation, rotation / norm, scale

    def floats(self, value: Any, count: int, field: str) -> np.ndarray:
        try:
            array = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            raise self.error(f"must be {count} numbers", field) from None
        if array.shape != (count,) or not np.isfinite(array).all():
            raise self.error(f"must be {count} finite numbers", field)
        return array

    # ----------------------------------------------------------------- animation
    def tracks(self, a: int) -> dict[int, dict[str, Track]]:
        """Every node's animated paths of animation ``a``."""
        animation = self.items("animations")[a]
        where = f"animations[{a}]"
        samplers = animation.samplers or []
        channels = animation.channels or []
        if not channels:
            raise self.error("has no channels", where + ".channels")
        out: dict[int, dict[str, Track]] = {}
        cache: dict[int, Track] = {}
        for c, channel in enumerate(channels):
            field = f"{where}.channels[{c}]"
            target = channel.target
            if target is None:
                raise self.error("has no target", field)
            if target.path not in (*_PATH_WIDTH, "weights"):
                raise self.error(f"unknown target path {target.path!r}", field + ".target.path")
            if target.node is None or target.path == "weights":
                continue  # an extension's target, or morph weights: not skeletal motion
            node = self.index(target.node, "nodes", field + ".target.node")
            s = channel.sampler
            if not _is_index(s) or not 0 <= s < len(samplers):
                raise self.error(
                    f"refers to sampler {s!r}, the animation has {len(samplers)} samplers",
                    field + ".sampler",
                )
            if target.path in out.get(node, {}):
                raise self.error(
                    f"node {node} has two {target.path} channels in this animation", field
                )
            if s not in cache:
                cache[s] = self.track(a, s)
            track = cache[s]
            width = _PATH_WIDTH[target.path]
            if track.values.shape[1] != width:
                raise self.error(
                    f"{target.path} needs VEC{width} values, sampler {s} has "
                    f"{track.values.shape[1]} components",
                    field,
                )
            out.setdefault(node, {})[target.path] = track
        if not out:
            raise self.error("animates no node's translation, rotation or scale", where)
        return out

    def track(self, a: int, s: int) -> Track:
        field = f"animations[{a}].samplers[{s}]"
        sampler = self.items("animations")[a].samplers[s]
        interpolation = sampler.interpolation or "LINEAR"
        if interpolation not in _INTERPOLATIONS:
            raise self.error(
                f"interpolation {interpolation!r} is not one of {', '.join(_INTERPOLATIONS)}",
                field + ".interpolation",
            )
        times = self.accessor(sampler.input, field + ".input", ("SCALAR",))[:, 0]
        if len(times) > 1 and not (np.diff(times) > 0).all():
            raise self.error("keyframe times must increase strictly", field + ".input")
        values = self.accessor(sampler.output, field + ".output", ("VEC3", "VEC4"))
        expected = len(times) * (3 if interpolation == "CUBICSPLINE" else 1)
        if len(values) != expected:
            raise self.error(
                f"output has {len(values)} values for {len(times)} keyframe times "
                f"({interpolation} needs {expected})",
                field + ".output",
            )
        return Track(times, values, interpolation, field)

    def pick_animation(self, animation: int | str) -> int:
        animations = self.items("animations")
        if not animations:
            raise self.error("the file has no animation", "animations")
        if isinstance(animation, str):
            names = [a.name for a in animations]
            if animation not in names:
                raise self.error(f"no animation named {animation!r} (found {names})", "animations")
            return names.index(animation)
        if not 0 <= animation < len(animations):
            raise self.error(
                f"animation {animation} requested, the file has {len(animations)}", "animations"
            )
        return animation


def _is_end_site(node: Any) -> bool:
    extras = node.extras if isinstance(node.extras, dict) else {}
    mark = extras.get(_EXTRA)
    return isinstance(mark, dict) and mark.get("end_site") is True


def _skeleton_nodes(
    reader: _Reader, parent: list[int], animated: set[int]
) -> tuple[int, list[int], list[int]]:
    """``(root node, joint nodes in parent-first order, End Site nodes)``."""
    nodes = reader.items("nodes")
    skins = reader.items("skins")
    if skins:
        best, wanted = -1, set()
        for k, skin in enumerate(skins):
            joints = skin.joints or []
            if not isinstance(joints, list) or not joints:
                raise reader.error("must be a non-empty list of nodes", f"skins[{k}].joints")
            chosen = {reader.index(j, "nodes", f"skins[{k}].joints") for j in joints}
            if best < 0 or len(chosen & animated) > len(wanted & animated):
                best, wanted = k, chosen
    else:
        wanted = set(animated)

    def chain(i: int) -> list[int]:
        out = []
        while i >= 0:
            out.append(i)
            i = parent[i]
        return out[::-1]  # top first

    chains = [chain(i) for i in sorted(wanted)]
    root = -1
    for depth in range(min(len(c) for c in chains)):
        if len({c[depth] for c in chains}) != 1:
            break
        root = chains[0][depth]
    if root < 0:
        raise reader.error(
            "the animated nodes do not share one root node (more than one character?)",
            "skins" if skins else "nodes",
        )
    children: dict[int, list[int]] = {}
    for i, p in enumerate(parent):
        children.setdefault(p, []).append(i)
    members: set[int] = set()
    sites: list[int] = []
    if skins:
        for c in chains:
            members.update(c[c.index(root) :])
        for i in sorted(members):
            sites += [c for c in children.get(i, []) if _is_end_site(nodes[c])]
    else:
        stack = [root]
        while stack:
            i = stack.pop()
            if _is_end_site(nodes[i]) and i != root:
                sites.append(i)
                continue
            if i != root and (nodes[i].mesh is not None or nodes[i].camera is not None):
                continue
            members.add(i)
            stack.extend(children.get(i, []))
    # parent-first, and in node order where that allows (it is the joint order
    # of files written by write_gltf)
    order: list[int] = []
    heap = [root]
    while heap:
        i = heapq.heappop(heap)
        order.append(i)
        for c in children.get(i, []):
            if c in members:
                heapq.heappush(heap, c)
    return root, order, sorted(sites)


def read_gltf(
    path: str | Path,
    dtype: torch.dtype = torch.float64,
    animation: int | str = 0,
    up: str | None = None,
    forward: str | None = None,
) -> Motion:
    """Read skeletal animation from a glTF 2.0 file (``.glb`` or ``.gltf``).

    The skeleton is the joints of the file's skin (when there are several, the one
    whose joints the animation moves most, with the nodes between its joints),
    else the node tree below the nodes the animation moves (nodes holding a mesh
    or camera left out). Joints are ordered parents first, in node order where
    that allows. A joint's rest offset is its node's translation; its rotation
    over time is the node's animated rotation, or its rest rotation when not
    animated. Static uniform scales, and the transform of the nodes above the
    skeleton, are folded into offsets and root motion; animated or non-uniform
    scale is an error. Translations animated on non-root joints become
    :attr:`Motion.translations <skelagnostic.Motion.translations>`.

    Frames: when every channel is keyed at the same evenly spaced times, the
    frames are those keys; otherwise the channels are sampled (``LINEAR``: lerp
    and shortest-arc slerp; ``STEP``; ``CUBICSPLINE``: Hermite) on an even grid
    from the first to the last key at the rate of the channel with the most keys,
    each channel held at its end values outside its own keys. A file written by
    :func:`write_gltf` gives back its frame rate, axes, units, BVH channel
    layout and body root.

    Args:
        path: The ``.glb`` or ``.gltf`` file (a ``.gltf`` may refer to ``.bin``
            files next to it).
        dtype: Float dtype of the tensors.
        animation: Index or name of the animation to read.
        up: The file's up axis (``x, y, z, -x, -y, -z``, or ``"auto"``); the motion is
            turned into the canonical frame (:mod:`skelagnostic.core.axes`). ``None``:
            the axes :func:`write_gltf` recorded, else ``"y"`` (glTF's own).
        forward: The file's forward axis, or ``"auto"``; ``None``: as for ``up``.

    Returns:
        The :class:`~skelagnostic.Motion`, named after the file stem.

    Raises:
        GLTFError: If pygltflib (the ``gltf`` extra) is missing, or the file is
            missing, not glTF 2.0, has no animation, or has a field that cannot
            be used (a channel naming a missing node, a sampler whose output
            count does not match its keyframe times, ...); the message names the
            file and the field.
    """
    path = Path(path)
    pg = _pygltflib(path)
    reader = _Reader(pg, _read_bytes(path), path)
    a = reader.pick_animation(animation)
    nodes = reader.items("nodes")
    parent = reader.parents()
    tracks = reader.tracks(a)
    animated = {i for i, paths in tracks.items() if set(paths) & set(_PATH_WIDTH)}
    root, joints, sites = _skeleton_nodes(reader, parent, animated)
    index = {node: j for j, node in enumerate(joints)}
    joint_parents = [-1] + [index[parent[i]] for i in joints[1:]]
    world_r, world_t, world_s = _transform_above(reader, parent, root, animated)
    used = [track for i in joints for track in tracks.get(i, {}).values()]
    if not used:
        raise reader.error(
            f"moves none of the skeleton's {len(joints)} joints (the nodes from {root} down)",
            f"animations[{a}]",
        )
    grid, same, fps = _frame_grid(reader, a, used)
    num_frames = len(grid)

    def sample(node: int, what: str, rest: np.ndarray) -> np.ndarray:
        track = tracks.get(node, {}).get(what)
        if track is None:
            return np.repeat(rest[None], num_frames, axis=0)
        if same:
            return track.keyframes()
        return track.at(grid, rotation=what == "rotation")

    # per joint: rest transform, animated values, cumulative scale
    num_joints = len(joints)
    offsets = np.zeros((num_joints, 3))
    rotations = np.zeros((num_frames, num_joints, 4))
    moving: dict[int, np.ndarray] = {}
    cumulative = np.zeros(num_joints)
    for j, node in enumerate(joints):
        t, r, s = reader.local(node)
        uniform = _joint_scale(reader, node, s, tracks.get(node, {}).get("scale"))
        above_scale = world_s if j == 0 else cumulative[joint_parents[j]]
        cumulative[j] = above_scale * uniform
        offsets[j] = above_scale * t
        rotations[:, j] = sample(node, "rotation", r)
        if "translation" in tracks.get(node, {}):
            moving[j] = above_scale * sample(node, "translation", t)
    norms = np.linalg.norm(rotations, axis=-1)
    if (norms < 1e-8).any():
        f, j = (int(v) for v in np.argwhere(norms < 1e-8)[0])
        track = tracks[joints[j]]["rotation"]
        raise reader.error(f"a zero quaternion at frame {f}", track.field + ".output")
    rotations = rotations / norms[..., None]
    # fold the transform above the root into the root
    root_rest = offsets[0] / world_s if world_s else offsets[0]
    offsets[0] = world_t + world_s * rotate_xyzw(world_r, root_rest)
    root_local = moving.get(0, np.repeat(root_rest[None] * world_s, num_frames, axis=0))
    root_positions = world_t + rotate_xyzw(world_r, root_local)
    rotations[:, 0] = mul_xyzw(world_r, rotations[:, 0])
    translations = None
    moved = {j: v for j, v in moving.items() if j > 0 and np.abs(v - offsets[j]).max() > 1e-9}
    if moved:
        translations = np.repeat(offsets[None], num_frames, axis=0)
        translations[:, 0] = root_positions
        for j, v in moved.items():
            translations[:, j] = v
    end_sites = _end_sites(reader, sites, parent, index, cumulative)
    skeleton, units = _skeleton(reader, nodes, root, joints, joint_parents, offsets, end_sites)
    quats = to_wxyz(rotations)
    motion = Motion(
        skeleton,
        Q.continuity(quats, dim=0),
        torch.from_numpy(np.ascontiguousarray(root_positions)),
        fps,
        translations=None if translations is None else torch.from_numpy(translations),
        name=path.stem,
        units=units,
        dtype=dtype,
    )
    up, forward = _declared_axes(_metadata(nodes[root]), up, forward)
    return to_canonical(motion, up, forward, where=path)[0]


def _read_bytes(path: Path) -> bytes:
    """The file's bytes, or a :class:`GLTFError` saying why they cannot be read."""
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise GLTFError("no such file", path) from None
    except IsADirectoryError:
        raise GLTFError("is a directory, not a glTF file", path) from None
    except OSError as exc:
        raise GLTFError(f"cannot read: {exc.strerror}", path) from None


def _transform_above(
    reader: _Reader, parent: list[int], root: int, animated: set[int]
) -> tuple[np.ndarray, np.ndarray, float]:
    """The transform of the nodes above the skeleton root.

    Returns:
        Its (x, y, z, w) rotation, translation and uniform scale.

    Raises:
        GLTFError: A node above the root is animated or scaled non-uniformly.
    """
    world_r, world_t, world_s = np.array([0.0, 0.0, 0.0, 1.0]), np.zeros(3), 1.0
    above, k = [], parent[root]
    while k >= 0:
        above.append(k)
        k = parent[k]
    for k in reversed(above):
        if k in animated:
            raise reader.error(
                "is animated but lies above the skeleton's root; animate the root instead",
                f"nodes[{k}]",
            )
        t, r, s = reader.local(k)
        uniform = _uniform_scale(s)
        if uniform is None:
            raise reader.error("a non-uniform scale is not supported", f"nodes[{k}].scale")
        world_t = world_t + world_s * rotate_xyzw(world_r, t)
        world_r = mul_xyzw(world_r, r)
        world_s *= uniform
    return world_r, world_t, world_s


def _frame_grid(reader: _Reader, a: int, used: list[Track]) -> tuple[np.ndarray, bool, float]:
    """The frame times of animation ``a``, from the tracks it plays on the skeleton.

    Returns:
        ``(times, keyed, fps)``: ``keyed`` when every track is keyed at exactly
        these evenly spaced times (no sampling needed).

    Raises:
        GLTFError: The keys span more than ``_MAX_FRAMES`` frames.
    """
    meta_fps = _metadata(reader.items("animations")[a]).get("fps")
    keys = used[0].times
    same = all(len(t.times) == len(keys) and np.array_equal(t.times, keys) for t in used[1:])
    densest = max(used, key=lambda t: len(t.times)).times
    span = float(densest[-1] - densest[0])
    fps = snap_rate((len(densest) - 1) / span) if len(densest) > 1 and span > 0 else 30.0
    if (
        isinstance(meta_fps, (int, float))
        and not isinstance(meta_fps, bool)
        and math.isfinite(meta_fps)
        and meta_fps > 0
    ):
        fps = float(meta_fps)
    if same and len(keys) > 1:
        steps = np.diff(keys)
        same = bool(np.abs(steps - 1.0 / fps).max() <= 1e-3 / fps)
    if same:
        return keys, same, fps
    start = min(float(t.times[0]) for t in used)
    end = max(float(t.times[-1]) for t in used)
    count = round((end - start) * fps) + 1
    if count > _MAX_FRAMES:
        raise reader.error(
            f"keys from {start:g} s to {end:g} s at {fps:g} fps would make {count} frames "
            f"(at most {_MAX_FRAMES})",
            f"animations[{a}]",
        )
    return start + np.arange(count) / fps, same, fps


def _joint_scale(reader: _Reader, node: int, rest: np.ndarray, track: Track | None) -> float:
    """The uniform scale of a joint node (its static scale track's, else its rest scale).

    Raises:
        GLTFError: The scale is animated, non-uniform or not positive.
    """
    if track is not None:
        values = track.keyframes()
        if np.abs(values - values[:1]).max() > _SCALE_TOLERANCE * np.abs(values).max():
            raise reader.error("animated scale is not supported", track.field)
        rest = values[0]
    uniform = _uniform_scale(rest)
    if uniform is None:
        raise reader.error(
            "a non-uniform or non-positive scale is not supported", f"nodes[{node}].scale"
        )
    return uniform


def _skeleton(
    reader: _Reader,
    nodes: list[Any],
    root: int,
    joints: list[int],
    joint_parents: list[int],
    offsets: np.ndarray,
    end_sites: dict[int, list[list[float]]],
) -> tuple[Skeleton, str | None]:
    """The skeleton of the joint nodes, with what the root's extras say, and the units.

    Raises:
        GLTFError: The skeleton is invalid (the message of :class:`SkeletonError`).
    """
    names: list[str] = []
    taken: set[str] = set()
    for node in joints:
        name = nodes[node].name
        name = name if isinstance(name, str) and name else f"node{node}"
        names.append(_unique(name, taken))
    meta = _metadata(nodes[root])
    up_axis = meta.get("up_axis") if meta.get("up_axis") in ("x", "y", "z") else "y"
    channels = meta.get("channels")
    if not (isinstance(channels, list) and len(channels) == len(joints)):
        channels = None
    body_root = meta.get("body_root")
    body_root = body_root if _is_index(body_root) and 0 <= body_root < len(joints) else None
    units = meta.get("units") if meta.get("units") in UNITS else None
    try:
        skeleton = Skeleton(
            names,
            joint_parents,
            offsets,
            end_sites=end_sites,
            up_axis=up_axis,
            name=reader.path.stem,
            channels=channels,
            body_root=body_root,
        )
    except SkeletonError as exc:
        raise GLTFError(str(exc), reader.path, f"nodes[{root}]") from None
    return skeleton, units
