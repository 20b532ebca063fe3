"""File formats: BVH reading and writing; atomic, checked output files.

The BVH functions are imported on first access (:mod:`skelagnostic.lazy`), so
that :mod:`skelagnostic.io.atomic` and :mod:`skelagnostic.io.outputs` (used by
the renderers) do not import torch.
"""

from skelagnostic.lazy import lazy_exports

__all__ = ["parse_bvh", "read_bvh", "write_bvh"]
__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "parse_bvh": "skelagnostic.io.bvh",
        "read_bvh": "skelagnostic.io.bvh",
        "write_bvh": "skelagnostic.io.bvh",
    },
)
