"""Data: clip sources, the on-disk window cache and the :class:`MotionDataModule`.

Examples:
    >>> from skelagnostic.data import ProceduralSource
    >>> source = ProceduralSource(kinds=["quadruped"], gaits=["trot"], clips_per_gait=1, seconds=1)
    >>> [clip.id for clip in source.clips()]
    ['quadruped_trot_0']
"""

from skelagnostic.data.cache import CacheEntry, WindowCache, default_cache_dir
from skelagnostic.data.sources import (
    DATA_ROOT_ENV,
    MANN_DOG_TEST,
    PRESETS,
    Archive,
    BVHSource,
    ClipRef,
    ClipSource,
    DatasetPreset,
    MetresSource,
    MultiSource,
    ProceduralSource,
    bvh_sources,
    dataset_root,
    flatten_sources,
    preset_source,
)

__all__ = [
    "DATA_ROOT_ENV",
    "MANN_DOG_TEST",
    "PRESETS",
    "Archive",
    "BVHSource",
    "CacheEntry",
    "ClipRef",
    "ClipSource",
    "DatasetPreset",
    "MetresSource",
    "MotionDataModule",
    "MultiSource",
    "ProceduralSource",
    "SkeletonCollate",
    "WindowCache",
    "WindowDataset",
    "bvh_sources",
    "datamodule_options",
    "dataset_root",
    "default_cache_dir",
    "flatten_sources",
    "preset_source",
]

# The data module needs Lightning: imported on first use, so that reading clips (and
# `skelagnostic plugins`, which lists the dataset presets) does not import it.
from skelagnostic.lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "MotionDataModule": "skelagnostic.data.datamodule",
        "WindowDataset": "skelagnostic.data.datamodule",
        "datamodule_options": "skelagnostic.data.datamodule",
        "SkeletonCollate": "skelagnostic.data.loaders",
    },
)
