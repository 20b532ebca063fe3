"""Reconstruction-stage data: unpaired source clips and one target skeleton (PC-MRL Sec. 3.2).

Stage 1 needs no paired data: source clips (any skeletons, e.g. LaFAN1) are
cut into windows of local quaternions (+ root translation) and converted to
metres, as the paper requires (Sec. 4.2); the target skeleton (e.g. CMU) is
only a hierarchy with rest offsets. Point clouds are drawn per batch by the
aligner, so every sequence gets a fresh cloud.

``data.target`` is a procedural kind (``biped31``, ...) or the path of a BVH
file whose hierarchy is used; ``data.target_units`` / ``data.source_units``
name the length units when a file does not say (``null``: guessed from the
skeleton height, see :func:`~skelagnostic_pcmrl.points.infer_units`).
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cached_property
from pathlib import Path
from typing import Any

from skelagnostic.core.motion import UNITS, Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.data import ClipSource, MotionDataModule
from skelagnostic.data.sources import ClipRef
from skelagnostic.errors import SkelagnosticError
from skelagnostic.representations import LocalQuaternions, MotionRepresentation
from skelagnostic_pcmrl.points import infer_units

__all__ = ["MetresSource", "PcmrlReconDataModule", "load_target_skeleton"]


class MetresSource(ClipSource):
    """Wraps a clip source so that every clip comes in metres.

    Clips of known units (``motion.units``) are converted; others get
    ``units`` or the unit guessed from the skeleton height.

    Args:
        inner: The wrapped source.
        units: Units of clips that do not know theirs (``None``: guess).
    """

    def __init__(self, inner: ClipSource, units: str | None = None) -> None:
        self.inner = inner
        self.units = units
        self.name = inner.name

    def clips(self) -> list[ClipRef]:
        """The inner source's clips."""
        return self.inner.clips()

    def load(self, clip: ClipRef) -> Motion:
        """The clip in metres."""
        motion = self.inner.load(clip)
        if motion.units == "m":
            return motion
        units = motion.units or infer_units(motion.skeleton, self.units)
        return motion.convert_units("m", from_=units)


def load_target_skeleton(target: str, units: str | None = None) -> tuple[Skeleton, str]:
    """The target skeleton in metres and the units it came in.

    Args:
        target: A procedural kind (``skelagnostic.procedural.KINDS``) or a BVH file path.
        units: Units of the file (``None``: procedural kinds are in cm, files are guessed).

    Raises:
        SkelagnosticError: Unknown kind and no such file.
    """
    from skelagnostic import procedural, read_bvh

    if target in procedural.KINDS:
        skeleton = procedural.skeleton(target)
        units = units or "cm"
    elif Path(target).is_file():
        skeleton = read_bvh(target).skeleton
        units = infer_units(skeleton, units)
    else:
        raise SkelagnosticError(
            f"data.target={target!r} is neither a procedural kind ({', '.join(procedural.KINDS)}) "
            "nor a BVH file"
        )
    if units not in UNITS:
        raise SkelagnosticError(f"data.target_units: unknown unit {units!r}")
    return skeleton.scaled(UNITS[units]), units


class PcmrlReconDataModule(MotionDataModule):
    """Windows of source clips (local quaternions, metres) plus a target skeleton.

    Args:
        sources: Source clip sources (default: procedural ``biped22``).
        representation: Features (default: :class:`LocalQuaternions`; the aligner
            needs local rotations and translations).
        target: Target skeleton: procedural kind or BVH path.
        target_units: Units of the target file (``None``: guessed).
        source_units: Units of source clips that do not know theirs (``None``: guessed).
        fps, window, stride, batch_size, num_workers, val_fraction, test_fraction,
        split_seed, cache_dir, per_element_stats: See :class:`MotionDataModule`.
    """

    def __init__(
        self,
        sources: ClipSource | Sequence[ClipSource] | None = None,
        representation: MotionRepresentation | None = None,
        target: str = "biped31",
        target_units: str | None = None,
        source_units: str | None = None,
        fps: float = 30.0,
        window: int = 32,
        stride: int = 16,
        batch_size: int = 8,
        num_workers: int = 0,
        val_fraction: float = 0.2,
        test_fraction: float = 0.0,
        split_seed: int = 0,
        cache_dir: str | Path | None = None,
        per_element_stats: bool = True,
    ) -> None:
        if sources is None:
            from skelagnostic.data.sources import ProceduralSource

            sources = [ProceduralSource(kinds=("biped22",))]
        sources = [sources] if isinstance(sources, ClipSource) else list(sources)
        super().__init__(
            [MetresSource(s, source_units) for s in sources], representation, fps, window,
            stride, batch_size, num_workers, val_fraction, test_fraction, split_seed, cache_dir,
            per_element_stats,
        )
        if not isinstance(self.representation, LocalQuaternions):
            raise SkelagnosticError(
                "model=pcmrl needs data.representation=local_quaternions (or null), got "
                f"{type(self.representation).__name__}"
            )
        self.target = str(target)
        self.target_units_option = target_units
        self.source_units = source_units

    def default_representation(self) -> MotionRepresentation:
        """Local quaternions and translations ``[T, J, 7]``."""
        return LocalQuaternions()

    def preprocessing(self) -> dict[str, Any]:
        """Base preprocessing plus the conversion to metres."""
        return {**super().preprocessing(), "metres": True, "source_units": self.source_units}

    @cached_property
    def _target(self) -> tuple[Skeleton, str]:
        return load_target_skeleton(self.target, self.target_units_option)

    @property
    def target_skeleton(self) -> Skeleton:
        """The target skeleton, in metres."""
        return self._target[0]

    @property
    def target_units(self) -> str:
        """The units the target skeleton came in (what retargeted motions are written in)."""
        return self._target[1]
