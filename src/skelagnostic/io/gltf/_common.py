"""What the glTF reader and writer share: suffixes, accessor constants, pygltflib."""

from __future__ import annotations

from pathlib import Path
from types import ModuleType

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
