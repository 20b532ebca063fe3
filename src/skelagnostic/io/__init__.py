"""File formats: BVH and glTF reading and writing; atomic, checked output files.

:func:`read_motion` and :func:`write_motion` choose BVH or glTF by the file suffix.

The BVH and glTF functions are imported on first access (:mod:`skelagnostic.lazy`), so
that :mod:`skelagnostic.io.atomic` and :mod:`skelagnostic.io.outputs` (used by
the renderers) do not import torch.
"""

from skelagnostic.lazy import lazy_exports

__all__ = [
    "parse_bvh",
    "read_bvh",
    "read_gltf",
    "read_motion",
    "write_bvh",
    "write_gltf",
    "write_motion",
]
__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "parse_bvh": "skelagnostic.io.bvh",
        "read_bvh": "skelagnostic.io.bvh",
        "write_bvh": "skelagnostic.io.bvh",
        "read_gltf": "skelagnostic.io.gltf",
        "write_gltf": "skelagnostic.io.gltf",
        "read_motion": "skelagnostic.io.motion_files",
        "write_motion": "skelagnostic.io.motion_files",
    },
)
