"""Data: clip sources, the on-disk window cache and the :class:`MotionDataModule`.

Examples:
    >>> from skelagnostic.data import ProceduralSource
    >>> source = ProceduralSource(kinds=["quadruped"], gaits=["trot"], clips_per_gait=1, seconds=1)
    >>> [clip.id for clip in source.clips()]
    ['quadruped_trot_0']
"""

from skelagnostic.data.cache import CacheEntry, WindowCache, default_cache_dir
from skelagnostic.data.datamodule import MotionDataModule, WindowDataset
from skelagnostic.data.sources import (
    PRESETS,
    BVHSource,
    ClipRef,
    ClipSource,
    DatasetPreset,
    ProceduralSource,
    bvh_sources,
    preset_source,
    reroot,
)

__all__ = [
    "PRESETS",
    "BVHSource",
    "CacheEntry",
    "ClipRef",
    "ClipSource",
    "DatasetPreset",
    "MotionDataModule",
    "ProceduralSource",
    "WindowCache",
    "WindowDataset",
    "bvh_sources",
    "default_cache_dir",
    "preset_source",
    "reroot",
]
