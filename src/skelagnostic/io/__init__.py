"""File formats: BVH reading and writing."""

from skelagnostic.io.bvh import parse_bvh, read_bvh, write_bvh

__all__ = ["parse_bvh", "read_bvh", "write_bvh"]
