"""What the glTF reader and writer share: suffixes, accessor constants, pygltflib."""

from __future__ import annotations

from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from skelagnostic.errors import GLTFError

#: File suffixes of glTF files: binary (``.glb``) and JSON with embedded buffer (``.gltf``).
GLTF_SUFFIXES = (".glb", ".gltf")

_EXTRA = "skelagnostic"  # key of this package's data in a node's or animation's extras
_FLOAT = 5126
_COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32}
_COMPONENTS[_FLOAT] = np.float32
_NORMALIZE = {np.int8: 127.0, np.uint8: 255.0, np.int16: 32767.0, np.uint16: 65535.0}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_PATH_WIDTH = {"translation": 3, "rotation": 4, "scale": 3}
_INTERPOLATIONS = ("LINEAR", "STEP", "CUBICSPLINE")
#: Relative tolerance under which a node scale counts as uniform and constant.
_SCALE_TOLERANCE = 1e-5
#: An evaluation time this close to a keyframe (as a fraction of the key interval)
#: takes the keyframe's value (float32 key times, float64 frame times).
_SNAP = 1e-4
#: Most frames a resampled animation may have (10 hours at 240 fps).
_MAX_FRAMES = 10 * 3600 * 240


def _pygltflib(path: Path) -> ModuleType:
    """The pygltflib module, or a :class:`GLTFError` naming the extra that installs it."""
    try:
        import pygltflib
    except ImportError:
        raise GLTFError(
            "glTF support needs the pygltflib package: pip install 'skelagnostic[gltf]'", path
        ) from None
    return pygltflib


def _unique(name: str, taken: set[str]) -> str:
    candidate, k = name, 1
    while candidate in taken:
        k += 1
        candidate = f"{name}{k}"
    taken.add(candidate)
    return candidate


def _metadata(node: Any) -> dict[str, Any]:
    extras = node.extras if isinstance(node.extras, dict) else {}
    meta = extras.get(_EXTRA)
    return meta if isinstance(meta, dict) else {}


def _declared_axes(
    meta: dict[str, Any], up: str | None, forward: str | None
) -> tuple[str | None, str | None]:
    """``up`` and ``forward``, or (``up`` is ``None``) the file axes ``write_gltf`` recorded."""
    axes = meta.get("axes")
    if up is not None or not isinstance(axes, dict):
        return up, forward
    return axes.get("up"), forward if forward is not None else axes.get("forward")


def _end_sites(
    reader: Any,
    sites: list[int],
    parent: list[int],
    index: dict[int, int],
    cumulative: np.ndarray,
) -> dict[int, list[list[float]]]:
    """The End Site offsets of each joint, scaled by the joint's cumulative scale."""
    end_sites: dict[int, list[list[float]]] = {}
    for node in sites:
        if parent[node] in index:
            j = index[parent[node]]
            t = reader.local(node)[0]
            end_sites.setdefault(j, []).append([float(v) for v in cumulative[j] * t])
    return end_sites
