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

from skelagnostic.core.motion import UNITS
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.data import ClipSource, MetresSource, MotionDataModule, flatten_sources
from skelagnostic.errors import SkelagnosticError
from skelagnostic.representations import LocalQuaternions, MotionRepresentation
from skelagnostic_pcmrl.points import infer_units

# MetresSource lives in skelagnostic.data now; importing it from here still works.
__all__ = ["MetresSource", "PcmrlReconDataModule", "load_target_skeleton"]


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
        skeleton = skeleton.rooted_at(skeleton.body_root)  # without a trajectory carrier
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
        sources: Source clip sources (default: procedural ``biped22``); each is
            wrapped in a :class:`~skelagnostic.data.MetresSource`.
        target: Target skeleton: procedural kind or BVH path.
        target_units: Units of the target file (``None``: guessed).
        source_units: Units of source clips that do not know theirs (``None``: guessed).
        batch_size: Windows per batch and dataset.
        **kwargs: The other options of :class:`~skelagnostic.data.MotionDataModule`
            (``representation``: default :class:`LocalQuaternions`, the only one the
            aligner takes: it needs local rotations and translations; ``fps``,
            ``window``, ``stride``, ...).

    Raises:
        SkelagnosticError: The representation is not :class:`LocalQuaternions`.
    """

    def __init__(
        self,
        sources: ClipSource | Sequence[ClipSource] | None = None,
        *,
        target: str = "biped31",
        target_units: str | None = None,
        source_units: str | None = None,
        batch_size: int = 8,
        **kwargs: Any,
    ) -> None:
        if sources is None:
            from skelagnostic.data.sources import ProceduralSource

            sources = [ProceduralSource(kinds=("biped22",))]
        sources = flatten_sources(sources)
        super().__init__(
            [MetresSource(s, source_units) for s in sources], batch_size=batch_size, **kwargs
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
