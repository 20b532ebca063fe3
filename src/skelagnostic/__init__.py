"""skelagnostic: skeleton-agnostic character motion learning.

The top-level namespace re-exports the core lazily, so ``import skelagnostic``
stays fast and pulls in torch only when a core name is first used::

    import skelagnostic as sa
    motion = sa.read_bvh("walk.bvh")
    positions = motion.global_positions()

``skelagnostic.__version__`` is the installed distribution's version
(:func:`skelagnostic.version.distribution_version`), read on first access; from
sources that are not installed it is ``"0+unknown"``.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

_LAZY: dict[str, tuple[str, str | None]] = {
    "Skeleton": ("skelagnostic.core.skeleton", "Skeleton"),
    "Motion": ("skelagnostic.core.motion", "Motion"),
    "read_bvh": ("skelagnostic.io.bvh", "read_bvh"),
    "write_bvh": ("skelagnostic.io.bvh", "write_bvh"),
    "parse_bvh": ("skelagnostic.io.bvh", "parse_bvh"),
    "read_gltf": ("skelagnostic.io.gltf", "read_gltf"),
    "write_gltf": ("skelagnostic.io.gltf", "write_gltf"),
    "forward_kinematics": ("skelagnostic.core.kinematics", "forward_kinematics"),
    "reroot": ("skelagnostic.core.motion", "reroot"),
    "SkelagnosticError": ("skelagnostic.errors", "SkelagnosticError"),
    "BVHError": ("skelagnostic.errors", "BVHError"),
    "GLTFError": ("skelagnostic.errors", "GLTFError"),
    "SkeletonError": ("skelagnostic.errors", "SkeletonError"),
    "MotionError": ("skelagnostic.errors", "MotionError"),
    "NotInvertibleError": ("skelagnostic.errors", "NotInvertibleError"),
    "procedural": ("skelagnostic.procedural", None),
    "plugins": ("skelagnostic.plugins", None),
    "load_aligner": ("skelagnostic.plugins", "load_aligner"),
}

__all__ = [
    "BVHError",
    "GLTFError",
    "Motion",
    "MotionError",
    "NotInvertibleError",
    "SkelagnosticError",
    "Skeleton",
    "SkeletonError",
    "__version__",
    "forward_kinematics",
    "load_aligner",
    "parse_bvh",
    "plugins",
    "procedural",
    "read_bvh",
    "read_gltf",
    "reroot",
    "write_bvh",
    "write_gltf",
]

if TYPE_CHECKING:  # pragma: no cover
    from skelagnostic import plugins, procedural
    from skelagnostic.core.kinematics import forward_kinematics
    from skelagnostic.core.motion import Motion, reroot
    from skelagnostic.core.skeleton import Skeleton
    from skelagnostic.errors import (
        BVHError,
        GLTFError,
        MotionError,
        NotInvertibleError,
        SkelagnosticError,
        SkeletonError,
    )
    from skelagnostic.io.bvh import parse_bvh, read_bvh, write_bvh
    from skelagnostic.io.gltf import read_gltf, write_gltf
    from skelagnostic.plugins import load_aligner

    __version__: str


def __getattr__(name: str) -> Any:
    if name == "__version__":
        from skelagnostic.version import distribution_version

        version = globals()["__version__"] = distribution_version("skelagnostic")
        return version
    try:
        module_name, attr = _LAZY[name]
    except KeyError:
        # submodules such as skelagnostic.metrics are imported on first access
        try:
            return importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as exc:
            if exc.name == f"{__name__}.{name}":
                raise AttributeError(f"module 'skelagnostic' has no attribute {name!r}") from None
            raise
    module = importlib.import_module(module_name)
    value = module if attr is None else getattr(module, attr)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY) | {"__version__"})
