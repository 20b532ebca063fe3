"""glTF writing: a motion as a node hierarchy, one animation, an optional skinned bone mesh."""

from __future__ import annotations

import base64
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import torch

from skelagnostic.core.axes import CANONICAL_UP, default_forward, from_canonical, parse_axis
from skelagnostic.core.motion import Motion
from skelagnostic.errors import GLTFError
from skelagnostic.io.atomic import atomic_write
from skelagnostic.io.gltf._common import (
    _COMPONENTS,
    _EXTRA,
    GLTF_SUFFIXES,
    _pygltflib,
    _unique,
)

__all__ = ["write_gltf"]


class _Blob:
    """The binary buffer of a file being written, with its buffer views and accessors."""

    def __init__(self, pg: ModuleType) -> None:
        self.pg = pg
        self.parts: list[bytes] = []
        self.size = 0
        self.views: list[Any] = []
        self.accessors: list[Any] = []

    def add(
        self,
        array: np.ndarray,
        kind: str,
        target: int | None = None,
        bounds: bool = False,
    ) -> int:
        """Append ``array`` (``[count, width]`` or ``[count]``) as one view and accessor.

        Returns:
            The accessor's index.
        """
        data = np.ascontiguousarray(array)
        raw = data.astype(data.dtype.newbyteorder("<"), copy=False).tobytes()
        self.views.append(
            self.pg.BufferView(buffer=0, byteOffset=self.size, byteLength=len(raw), target=target)
        )
        padding = -len(raw) % 4
        self.parts.append(raw + b"\0" * padding)
        self.size += len(raw) + padding
        component = {v: k for k, v in _COMPONENTS.items()}[data.dtype.type]
        flat = data.reshape(len(data), -1)
        accessor = self.pg.Accessor(
            bufferView=len(self.views) - 1,
            componentType=component,
            count=len(data),
            type=kind,
        )
        if bounds:
            accessor.min = [float(v) for v in flat.min(axis=0)]
            accessor.max = [float(v) for v in flat.max(axis=0)]
        self.accessors.append(accessor)
        return len(self.accessors) - 1

    def data(self) -> bytes:
        return b"".join(self.parts)


def _rest_positions(offsets: np.ndarray, parents: list[int]) -> np.ndarray:
    """Joint positions with every rotation the identity (the bind pose of the skin)."""
    rest = np.zeros_like(offsets)
    for j, p in enumerate(parents):
        rest[j] = offsets[j] if p < 0 else rest[p] + offsets[j]
    return rest


def _bone_mesh(segments: list[tuple[np.ndarray, np.ndarray, int]]) -> tuple[np.ndarray, ...]:
    """An octahedral bone from ``a`` to ``b`` per segment, skinned to joint ``j``.

    Returns:
        ``(positions [V, 3] float32, joints [V, 4] uint16, weights [V, 4] float32,
        indices [F * 3] uint32)``.
    """
    positions, joints, faces = [], [], []
    for a, b, j in segments:
        d = b - a
        length = float(np.linalg.norm(d))
        if length < 1e-9:
            continue
        u = d / length
        helper = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        v = np.cross(u, helper)
        v /= np.linalg.norm(v)
        w = np.cross(u, v)
        mid, r = a + 0.2 * d, 0.1 * length
        base = len(positions)
        positions += [a, mid + r * v, mid + r * w, mid - r * v, mid - r * w, b]
        joints += [j] * 6
        ring = [1, 2, 3, 4, 1]
        for k in range(4):
            faces += [base, base + ring[k + 1], base + ring[k]]
            faces += [base + 5, base + ring[k], base + ring[k + 1]]
    count = len(positions)
    joint_array = np.zeros((count, 4), dtype=np.uint16)
    joint_array[:, 0] = joints
    weights = np.zeros((count, 4), dtype=np.float32)
    weights[:, 0] = 1.0
    return (
        np.asarray(positions, dtype=np.float32).reshape(count, 3),
        joint_array,
        weights,
        np.asarray(faces, dtype=np.uint32),
    )


def write_gltf(
    motion: Motion,
    path: str | Path,
    bones: bool = True,
    up: str | None = None,
    forward: str | None = None,
) -> None:
    """Write a motion as glTF 2.0: ``.glb`` (binary) or ``.gltf`` (JSON, embedded buffer).

    One node per joint, in joint order (nodes ``0 .. J-1``), its ``translation`` the
    joint's rest offset; one node per BVH End Site under its joint (marked in
    ``extras``); one animation with a rotation channel (quaternions x, y, z, w) per
    joint and a translation channel on the root and on every joint with animated
    translations, keyed at ``k / fps`` seconds with ``LINEAR`` interpolation.
    Lengths are the motion's own units; the axes are glTF's (+Y up, facing +Z),
    the canonical frame, unless ``up``/``forward`` say otherwise. With ``bones`` a skin
    (bind pose: the rest offsets, no rotation) and a mesh of one octahedron per
    bone, skinned rigidly to the bone's parent joint, are added, so that Blender
    imports an armature and viewers show a figure.

    The file's axes, units, BVH channel layout and body root go into the
    root node's ``extras`` and the frame rate into the animation's, so that
    :func:`read_gltf` gives them back. The file is written atomically
    (:func:`~skelagnostic.io.atomic.atomic_write`).

    Args:
        motion: The motion.
        path: Target ``.glb`` or ``.gltf`` file.
        bones: Add the skin and the bone mesh.
        up: The file's up axis (``x, y, z, -x, -y, -z``; ``None``: ``"y"``): the motion
            is turned from the canonical frame into it
            (:func:`~skelagnostic.core.axes.from_canonical`). glTF viewers expect
            Y up; other axes serve tools that read the file's nodes as they are.
        forward: The file's forward axis (``None``: the usual one for ``up``).

    Raises:
        GLTFError: If the suffix is neither ``.glb`` nor ``.gltf``, pygltflib (the
            ``gltf`` extra) is missing, or the file cannot be written.
        AxesError: A bad ``up``/``forward`` (nothing is written).

    Examples:
        >>> import skelagnostic as sa, tempfile, os
        >>> motion, _ = sa.procedural.generate("biped22", "walk", seconds=0.5, fps=30)
        >>> path = os.path.join(tempfile.mkdtemp(), "walk.glb")
        >>> sa.write_gltf(motion, path)
        >>> sa.read_gltf(path).num_frames
        16
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in GLTF_SUFFIXES:
        raise GLTFError(f"a glTF file name ends in .glb or .gltf, not {path.suffix!r}", path)
    file_up = parse_axis(up, "up") if up is not None else CANONICAL_UP
    file_forward = parse_axis(forward, "forward") if forward is not None else None
    file_forward = file_forward or default_forward(file_up)
    m = from_canonical(motion.to(dtype=torch.float64, device="cpu"), file_up, file_forward)
    pg = _pygltflib(path)
    sk = m.skeleton
    offsets = sk.offsets.detach().double().cpu().numpy()
    blob = _Blob(pg)
    nodes, taken, sites = _nodes(pg, m, offsets)
    nodes[0].extras[_EXTRA]["axes"] = {"up": file_up, "forward": file_forward}
    animation = _animation(pg, blob, m, offsets)
    scene_nodes = [0]
    skins, meshes, materials = [], [], []
    rest = _rest_positions(offsets, sk.parents)
    segments = [(rest[p], rest[j], p) for j, p in enumerate(sk.parents) if p >= 0]
    segments += [(rest[j], rest[j] + site, j) for j, site in sites]
    positions, joints, weights, indices = _bone_mesh(segments)
    if bones and len(indices):  # a skin needs a mesh: a lone joint gets neither
        skins.append(_skin(pg, blob, rest))
        meshes.append(_mesh(pg, blob, positions, joints, weights, indices))
        materials.append(_bone_material(pg))
        nodes.append(pg.Node(name=_unique("bones", taken), mesh=0, skin=0))
        scene_nodes.append(len(nodes) - 1)

    data = blob.data()
    from skelagnostic.version import distribution_version

    generator = f"skelagnostic {distribution_version('skelagnostic')}"
    gltf = pg.GLTF2(
        asset=pg.Asset(version="2.0", generator=generator),
        scene=0,
        scenes=[pg.Scene(name=m.name or "motion", nodes=scene_nodes)],
        nodes=nodes,
        animations=[animation],
        skins=skins,
        meshes=meshes,
        materials=materials,
        accessors=blob.accessors,
        bufferViews=blob.views,
        buffers=[pg.Buffer(byteLength=len(data))],
    )
    if suffix == ".glb":
        gltf.set_binary_blob(data)
        content = b"".join(gltf.save_to_bytes())
    else:
        gltf.buffers[0].uri = "data:application/octet-stream;base64," + base64.b64encode(
            data
        ).decode("ascii")
        content = gltf.to_json(indent=1).encode("utf-8")
    try:
        atomic_write(path, content)
    except OSError as exc:
        raise GLTFError(f"cannot write: {exc.strerror or exc}", path) from None


def _nodes(
    pg: ModuleType, m: Motion, offsets: np.ndarray
) -> tuple[list[Any], set[str], list[tuple[int, np.ndarray]]]:
    """The node hierarchy: joints first, in joint order, then End Sites.

    Returns:
        The nodes (the root's ``extras`` hold the skeleton's metadata), the node
        names taken, and ``(joint, offset)`` of every End Site.
    """
    sk = m.skeleton
    nodes = [
        pg.Node(name=name, translation=[float(v) for v in offsets[j]], children=[])
        for j, name in enumerate(sk.joint_names)
    ]
    for j, p in enumerate(sk.parents):
        if p >= 0:
            nodes[p].children.append(j)
    taken = set(sk.joint_names)
    sites: list[tuple[int, np.ndarray]] = []
    for j in sorted(sk.end_sites):
        for site in sk.end_sites[j]:
            nodes[j].children.append(len(nodes))
            nodes.append(
                pg.Node(
                    name=_unique(f"{sk.joint_names[j]}_end", taken),
                    translation=[float(v) for v in site],
                    extras={_EXTRA: {"end_site": True}},
                )
            )
            sites.append((j, np.asarray(site, dtype=np.float64)))
    meta: dict[str, Any] = {"up_axis": sk.up_axis, "body_root": sk.body_root}
    if m.units is not None:
        meta["units"] = m.units
    if sk.channels is not None:
        meta["channels"] = sk.channels
    nodes[0].extras = {_EXTRA: meta}
    return nodes, taken, sites


def _animation(pg: ModuleType, blob: _Blob, m: Motion, offsets: np.ndarray) -> Any:
    """The animation: a rotation channel per joint, translation channels where they move."""
    root_positions = m.root_positions.detach().numpy()
    translations = None if m.translations is None else m.translations.detach().numpy()
    times = (np.arange(m.num_frames, dtype=np.float64) / m.fps).astype(np.float32)
    time_accessor = blob.add(times, "SCALAR", bounds=True)
    samplers, channels = [], []

    def channel(node: int, target: str, values: np.ndarray, kind: str) -> None:
        output = blob.add(values.astype(np.float32), kind)
        samplers.append(pg.AnimationSampler(input=time_accessor, output=output))
        channels.append(
            pg.AnimationChannel(
                sampler=len(samplers) - 1, target=pg.AnimationChannelTarget(node=node, path=target)
            )
        )

    # (w, x, y, z) -> glTF's (x, y, z, w)
    rotations = m.rotations.detach().numpy()[..., [1, 2, 3, 0]]
    translated = [0]
    if translations is not None:
        moved = np.abs(translations - offsets).max(axis=(0, 2)) > 1e-9
        translated += [int(j) for j in np.nonzero(moved)[0] if j > 0]
    for j in range(m.skeleton.num_joints):
        channel(j, "rotation", rotations[:, j], "VEC4")
        if j == 0:
            channel(0, "translation", root_positions, "VEC3")
        elif j in translated:
            assert translations is not None
            channel(j, "translation", translations[:, j], "VEC3")
    return pg.Animation(
        name=m.name or "motion",
        samplers=samplers,
        channels=channels,
        extras={_EXTRA: {"fps": m.fps}},
    )


def _skin(pg: ModuleType, blob: _Blob, rest: np.ndarray) -> Any:
    """The skin of every joint, bound in the rest pose ``rest`` ``[J, 3]``."""
    num_joints = len(rest)
    inverse_bind = np.tile(np.eye(4, dtype=np.float32), (num_joints, 1, 1))
    inverse_bind[:, 3, :3] = -rest  # column-major: the translation is the 4th column
    return pg.Skin(
        inverseBindMatrices=blob.add(inverse_bind.reshape(num_joints, 16), "MAT4"),
        joints=list(range(num_joints)),
        skeleton=0,
    )


def _mesh(
    pg: ModuleType,
    blob: _Blob,
    positions: np.ndarray,
    joints: np.ndarray,
    weights: np.ndarray,
    indices: np.ndarray,
) -> Any:
    """The bone mesh (see :func:`_bone_mesh`), skinned, with material 0."""
    attributes = pg.Attributes(
        POSITION=blob.add(positions, "VEC3", target=pg.ARRAY_BUFFER, bounds=True),
        JOINTS_0=blob.add(joints, "VEC4", target=pg.ARRAY_BUFFER),
        WEIGHTS_0=blob.add(weights, "VEC4", target=pg.ARRAY_BUFFER),
    )
    primitive = pg.Primitive(
        attributes=attributes,
        indices=blob.add(indices, "SCALAR", target=pg.ELEMENT_ARRAY_BUFFER),
        material=0,
    )
    return pg.Mesh(name="bones", primitives=[primitive])


def _bone_material(pg: ModuleType) -> Any:
    """The bones' material: matte, double-sided, orange."""
    return pg.Material(
        name="bone",
        doubleSided=True,
        pbrMetallicRoughness=pg.PbrMetallicRoughness(
            baseColorFactor=[0.85, 0.55, 0.3, 1.0],
            metallicFactor=0.0,
            roughnessFactor=0.8,
        ),
    )
