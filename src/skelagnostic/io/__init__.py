"""File formats: BVH and glTF reading and writing; atomic, checked output files.

The BVH and glTF functions are imported on first access (:mod:`skelagnostic.lazy`), so
that :mod:`skelagnostic.io.atomic` and :mod:`skelagnostic.io.outputs` (used by
the renderers) do not import torch.
"""

from skelagnostic.lazy import lazy_exports

__all__ = ["parse_bvh", "read_bvh", "read_gltf", "write_bvh", "write_gltf"]
__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "parse_bvh": "skelagnostic.io.bvh",
        "read_bvh": "skelagnostic.io.bvh",
        "write_bvh": "skelagnostic.io.bvh",
        "read_gltf": "skelagnostic.io.gltf",
        "write_gltf": "skelagnostic.io.gltf",
    },
)
