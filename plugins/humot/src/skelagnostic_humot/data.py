"""HuMoT data: 1 s chunks of joint positions, per-chunk templates, stochastic joint subsampling.

Preprocessing (Sec. 3.4.1): clips resampled to 30 Hz, converted to metres and
to joint positions, cut into 30-frame chunks overlapping by 24 frames
(``window=30, stride=6``), each centred by the mean position of its major
joints over the chunk. :class:`HumotDataModule` caches the world positions;
:func:`prepare_chunks` does the per-batch part (model axes, centring,
templates from the chunk's median bone lengths).

Stochastic joint subsampling (Sec. 3.4.2, App. A.4): :func:`sample_keep`
drops each major joint with probability 0.1 and every other joint with 0.5;
:func:`gather_subset` packs the kept joints first (skeleton order kept),
pads, and lists the subset's bones (each kept joint to its nearest kept
ancestor).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from skelagnostic.core.skeleton import Skeleton
from skelagnostic.data import ClipSource, MotionDataModule
from skelagnostic.data.cache import CacheEntry
from skelagnostic.data.sources import ClipRef, MultiSource, ProceduralSource, preset_source
from skelagnostic.errors import SkelagnosticError
from skelagnostic.representations import GlobalPositions, MotionRepresentation
from skelagnostic_humot.template import major_mask, skeleton_template, to_model_frame

__all__ = [
    "HumotDataModule",
    "Subset",
    "Topology",
    "corpus_and_procedural_source",
    "gather_subset",
    "prepare_chunks",
    "sample_keep",
]

log = logging.getLogger(__name__)


@dataclass
class Topology:
    """What HuMoT needs of a skeleton topology, precomputed once.

    Attributes:
        skeleton: The skeleton.
        directions: ``[J, 3]`` unit direction of each bone in the template (model frame).
        ancestors: ``[J, J]`` 1 where column ``k`` is ``j`` or an ancestor of row ``j``.
        major: ``[J]`` major-joint mask.
        parents: ``[J]`` parent indices (root: itself).
    """

    skeleton: Skeleton
    directions: torch.Tensor
    ancestors: torch.Tensor
    major: torch.Tensor
    parents: torch.Tensor

    @classmethod
    def of(cls, skeleton: Skeleton) -> Topology:
        """Precompute the topology data of ``skeleton``."""
        num = skeleton.num_joints
        # the bone directions of the skeleton's own template: the template's body frame
        # depends on the bone lengths, so a unit-length copy would not give them
        tmpl = skeleton_template(skeleton)
        parents = torch.tensor([max(p, 0) for p in skeleton.parents])
        bones = tmpl - tmpl[parents]
        norms = bones.norm(dim=-1, keepdim=True)
        directions = torch.where(norms > 1e-9, bones / norms.clamp_min(1e-12), 0.0).float()
        ancestors = torch.zeros(num, num)
        for j in range(num):
            k = j
            while k > 0:
                ancestors[j, k] = 1.0
                k = skeleton.parents[k]
        return cls(skeleton, directions, ancestors, major_mask(skeleton), parents)

    def templates(self, lengths: torch.Tensor) -> torch.Tensor:
        """``[..., J, 3]`` templates (model frame) for bone lengths ``[..., J]``."""
        d = self.directions.to(lengths)
        return self.ancestors.to(lengths) @ (lengths[..., None] * d)


def prepare_chunks(
    world: torch.Tensor, topology: Topology, up_axis: str = "y"
) -> tuple[torch.Tensor, torch.Tensor]:
    """Chunks ready for the network: model axes, centred by the major joints, with templates.

    Args:
        world: ``[B, F, J, 3]`` world joint positions (metres) in the skeleton's axes.
        topology: The chunks' topology.
        up_axis: Up axis of ``world``.

    Returns:
        ``(positions [B, F, J, 3], templates [B, J, 3])``: positions minus the mean of
        the major joints over the chunk (all joints if the skeleton has none), and
        templates with each chunk's median bone lengths.
    """
    pos = to_model_frame(world, up_axis)
    major = topology.major.to(pos.device)
    ref = pos[:, :, major] if bool(major.any()) else pos
    pos = pos - ref.mean(dim=(1, 2), keepdim=True)
    parents = topology.parents.to(pos.device)
    lengths = (pos - pos[:, :, parents]).norm(dim=-1).median(dim=1).values
    return pos, topology.templates(lengths)


def sample_keep(
    major: torch.Tensor,
    batch: int,
    p_major: float = 0.1,
    p_other: float = 0.5,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """``[batch, J]`` random keep masks: drop major joints with ``p_major``, others ``p_other``.

    A draw that drops every joint is replaced by keeping all of them.

    Raises:
        SkelagnosticError: A probability is outside [0, 1).
    """
    for name, p in (("p_major", p_major), ("p_other", p_other)):
        if not 0.0 <= p < 1.0:
            raise SkelagnosticError(f"{name} must be in [0, 1), got {p}")
    drop = torch.where(major, p_major, p_other).to(torch.float32)
    keep = torch.rand(batch, major.numel(), generator=generator) >= drop
    empty = ~keep.any(dim=1)
    keep[empty] = True
    return keep


@dataclass
class Subset:
    """Packed joint subsets of a batch.

    Attributes:
        index: ``[B, J']`` source joint index of each packed slot (0 on padding).
        mask: ``[B, J']`` valid slots (kept joints first).
        bones: ``[B, K, 2]`` (parent, child) slot indices of the subset's bones.
        bone_mask: ``[B, K]`` valid bones.
    """

    index: torch.Tensor
    mask: torch.Tensor
    bones: torch.Tensor
    bone_mask: torch.Tensor

    def take(self, x: torch.Tensor, joint_dim: int) -> torch.Tensor:
        """Gather the packed joints of ``x`` (batch first) along ``joint_dim``; padding is 0."""
        moved = x.movedim(joint_dim, 1)
        rest = moved.shape[2:]
        view = (*self.index.shape, *([1] * len(rest)))
        idx = self.index.to(x.device).reshape(view).expand(*self.index.shape, *rest)
        out = moved.gather(1, idx) * self.mask.to(x.device).reshape(view).to(x.dtype)
        return out.movedim(1, joint_dim)


def gather_subset(keep: torch.Tensor, parents: Sequence[int]) -> Subset:
    """Pack the kept joints of each sample and find the subset's bones.

    Args:
        keep: ``[B, J]`` keep masks.
        parents: Parent index per joint of the full skeleton (root ``-1``).

    Returns:
        The packed :class:`Subset`; the width ``J'`` is the largest kept count.
    """
    b = keep.shape[0]
    counts = keep.sum(1)
    width = int(counts.max())
    index = torch.zeros(b, width, dtype=torch.long)
    mask = torch.arange(width)[None] < counts[:, None]
    bones_list: list[list[tuple[int, int]]] = []
    for i in range(b):
        kept = keep[i].nonzero().flatten().tolist()
        index[i, : len(kept)] = torch.tensor(kept, dtype=torch.long)
        slot = {j: s for s, j in enumerate(kept)}
        bones = []
        for s, j in enumerate(kept):
            p = parents[j]
            while p >= 0 and p not in slot:
                p = parents[p]
            if p >= 0:
                bones.append((slot[p], s))
        bones_list.append(bones)
    k = max(1, max(len(x) for x in bones_list))
    bones_t = torch.zeros(b, k, 2, dtype=torch.long)
    bone_mask = torch.zeros(b, k, dtype=torch.bool)
    for i, bones in enumerate(bones_list):
        if bones:
            bones_t[i, : len(bones)] = torch.tensor(bones)
            bone_mask[i, : len(bones)] = True
    return Subset(index, mask, bones_t, bone_mask)


class HumotDataModule(MotionDataModule):
    """World joint positions of human clips, in HuMoT's 1 s chunks.

    A :class:`~skelagnostic.data.MotionDataModule` with the paper's defaults
    (30 fps, ``window=30``, ``stride=6``: 24 overlapping frames; batch 32) and
    the :class:`~skelagnostic.representations.GlobalPositions` representation.
    HuMoT models humans: clips of non-biped skeletons (e.g. the procedural
    quadruped of the framework's default data) are left out with a log message.

    Args:
        sources: Clip sources.
        window: Chunk length in frames (paper: 30).
        stride: Frames between chunk starts (paper: 6).
        **kwargs: The other options of :class:`~skelagnostic.data.MotionDataModule`
            (``fps``: paper 30, the default; ``batch_size``: paper 32, the default;
            ``representation``: default world joint positions; ...).
    """

    def __init__(
        self,
        sources: ClipSource | Sequence[ClipSource] | None = None,
        *,
        window: int = 30,
        stride: int = 6,
        **kwargs: Any,
    ) -> None:
        super().__init__(sources, window=window, stride=stride, **kwargs)
        #: Datasets left out because their skeleton is not a biped.
        self.skipped: list[str] = []

    def default_representation(self) -> MotionRepresentation:
        """World joint positions (centring happens per batch)."""
        return GlobalPositions()

    def add_dataset(self, name: str, members: list[tuple[ClipRef, CacheEntry]]) -> None:
        """As the base class, but a dataset of a non-biped skeleton is left out (and logged)."""
        skeleton = Skeleton.from_dict(members[0][1].meta["skeleton"])
        if skeleton.morphology != "biped":
            log.info(
                "humot: skipping dataset %r (%s skeleton, HuMoT models humans)",
                name,
                skeleton.morphology,
            )
            self.skipped.append(name)
            return
        super().add_dataset(name, members)

    def setup(self, stage: str | None = None) -> None:
        """As the base class, without non-human datasets.

        Raises:
            SkelagnosticError: No human clip is long enough for one chunk.
        """
        try:
            super().setup(stage)
        except SkelagnosticError as exc:
            if self.skipped:
                raise SkelagnosticError(
                    f"data: HuMoT needs human (biped) clips; only non-human datasets were "
                    f"found ({', '.join(self.skipped)})"
                ) from exc
            raise


def corpus_and_procedural_source(
    root: str | Path | None = None,
    preset: str = "lafan1",
    kinds: Sequence[str] = ("biped22", "biped17"),
    gaits: Sequence[str] = ("walk", "run"),
    clips_per_gait: int = 8,
    seconds: float = 6.0,
    seed: int = 0,
) -> MultiSource:
    """A real human corpus plus procedural humans (``data.source=humot_mix``).

    The corpus keeps its preset's test split (LaFAN1: subject 5); the procedural
    clips (seeds from ``seed``) add topologies the corpus lacks, which
    retargeting between skeletons needs. The procedural ``biped22`` has LaFAN1's
    joint set, ``biped31`` CMU's, ``biped17`` none of the corpora's.

    Args:
        root: Directory of the corpus's BVH files; ``None``: ``$SKELAGNOSTIC_DATA/<preset>``.
        preset: Dataset preset of the corpus (``lafan1``, ``cmu``, ``bandai``, ...).
        kinds: Procedural human kinds (``biped22``, ``biped31``, ``biped17``); empty: none.
        gaits: Procedural gaits.
        clips_per_gait: Procedural clips per (kind, gait).
        seconds: Duration of each procedural clip.
        seed: Base seed of the procedural clips (held-out evaluations use 1000 on).

    Returns:
        A :class:`~skelagnostic.data.MultiSource` with parts ``<preset>`` and
        ``procedural`` (the latter only when ``kinds`` is not empty).

    Raises:
        SkelagnosticError: A kind is not a procedural human.
    """
    bipeds = ("biped22", "biped31", "biped17")
    wrong = [k for k in kinds if k not in bipeds]
    if wrong:
        raise SkelagnosticError(
            f"data.kinds: {wrong} are not procedural humans; choose from {list(bipeds)}"
        )
    corpus = preset_source(preset, root)
    corpus.name = preset
    parts: list[ClipSource] = [corpus]
    if kinds:
        parts.append(
            ProceduralSource(
                kinds=tuple(kinds),
                gaits=tuple(gaits),
                clips_per_gait=clips_per_gait,
                seconds=seconds,
                seed=seed,
                name="procedural",
            )
        )
    return MultiSource(parts, name=f"{preset}+procedural")
