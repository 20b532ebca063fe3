"""VQ-PAE data: 1 s windows of root-local joint velocities centred on every pivot frame.

Per frame the input is the flattened root-local joint velocities
(:class:`~skelagnostic.representations.RootLocalVelocities`, ``J x 3``
channels), z-scored per channel over the frames of the dataset's training
clips. Constant channels (the authors' trainer divides them by zero and
produces NaN) and nearly constant ones (which blow up on clips outside the
training split) are guarded: every standard deviation is raised to at least
``std_floor`` times the dataset's mean channel standard deviation (0.01), and
one that is still below ``1e-6`` becomes 1. A window has ``T = round(fps *
window_seconds) + 1`` frames (odd) centred on its pivot; pivots are every
``stride``-th frame whose window stays inside its clip. Each clip's frames are
cached once on disk (one entry per clip) and the frames of a batch's windows are
read from there when the batch is asked for (:class:`CachedFrameWindows`, no
memory map), so stride 1 (the authors' setting) costs no extra memory and the
process's memory does not grow with the corpus. The normalisation statistics
are summed over chunks of a fixed size.

Every clip also keeps its root-local joint positions (normalised the same way)
for the average-pose MLP (Sec. 5.2).

With ``features="authors"`` (``data.features=authors``) the velocities and
positions are those of the WalkTheDog authors' exporter
(:mod:`skelagnostic_vqpae.features`: root frame with a smoothed facing, 3.25 Hz
low-pass) and every clip's cache entry also holds its mirror image, which the
training split uses as one more clip.

Several characters: one dataset per source and skeleton topology; training
steps draw one batch from every dataset. :class:`~skelagnostic.data.MultiSource` bundles several
sources (a human and a dog directory, several style sets) into the one
``data.source`` the CLI passes; each part becomes its own dataset.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor
from torch.utils.data import Dataset

from skelagnostic.core.skeleton import Skeleton
from skelagnostic.data import (
    BVHSource,
    ClipRef,
    ClipSource,
    MotionDataModule,
    MultiSource,
    preset_source,
)
from skelagnostic.data.cache import CacheEntry, read_exactly
from skelagnostic.data.loaders import SkeletonCollate
from skelagnostic.data.window_dataset import STATS_CHUNK_VALUES, check_statistics
from skelagnostic.errors import SkelagnosticError
from skelagnostic.representations import GlobalPositions, MotionRepresentation, RootLocalVelocities
from skelagnostic_vqpae.features import FEATURES, authors_features

__all__ = [
    "CachedFrameWindows",
    "FrameWindows",
    "MultiSource",
    "VqpaeDataModule",
    "human_dog_source",
    "styles_source",
]

#: Version of the cached per-clip layout (velocities and root-local positions per frame).
_LAYOUT = "vqpae-frames-1"


def human_dog_source(
    human_root: str | Path | None = None,
    dog_root: str | Path | None = None,
    human_preset: str = "lafan1",
    dog_preset: str = "mann_dog",
) -> MultiSource:
    """The human-dog setting: a human dataset preset plus the MANN dog (``data.source=human_dog``).

    Args:
        human_root: Directory of the human BVH files; ``None``:
            ``$SKELAGNOSTIC_DATA/<human_preset>``.
        dog_root: Directory of the dog BVH files; ``None``: ``$SKELAGNOSTIC_DATA/<dog_preset>``.
        human_preset: Preset of the human files (``lafan1``, ``cmu``, ``bandai``, ...).
        dog_preset: Preset of the dog files.

    Returns:
        A :class:`MultiSource` with parts ``human`` and ``dog``.
    """
    human = preset_source(human_preset, human_root)
    dog = preset_source(dog_preset, dog_root)
    human.name, dog.name = "human", "dog"
    return MultiSource([human, dog], name="human_dog")


def styles_source(
    root: str | Path,
    styles: Sequence[str],
    pattern: str = "**/{style}_*.bvh",
    units: str | None = "cmu",
) -> MultiSource:
    """One dataset per motion style (``data.source=styles``), e.g. the Xia set's file prefixes.

    Args:
        root: Directory of the BVH files.
        styles: Style names; ``pattern`` with ``{style}`` selects each style's files.
        pattern: Glob below ``root``.
        units: Length unit of the files (see :data:`skelagnostic.core.UNITS`).

    Returns:
        A :class:`MultiSource` with one part per style.

    Raises:
        SkelagnosticError: Fewer than two styles, unknown units, or a style without files.
    """
    if len(styles) < 2:
        raise SkelagnosticError(f"data.styles: give at least two styles, got {list(styles)}")
    parts = [BVHSource([root], pattern.format(style=s), units=units, name=s) for s in styles]
    return MultiSource(parts, name="styles")


class FrameWindows(Dataset):
    """Windows of one dataset gathered from per-frame features.

    Items (and batches, through ``__getitems__``) are dicts: ``features``
    ``[C, T]`` normalised velocities (``C = J * 3``, channels first), ``poses``
    ``[T, P]`` normalised root-local positions (``P = J * 3``), ``clip`` and
    ``pivot`` (frame index of the window centre within its clip).

    With ``pair_shift = s > 0`` every item also carries the window ``s`` frames
    later in the same clip (``s`` frames earlier where the clip ends first) as
    ``shifted`` ``[C, T]`` and the signed offset as ``shift`` (0 where the clip is
    shorter than ``T + s`` frames and neither fits), for the phase-rate loss of
    :class:`~skelagnostic_vqpae.training.VqpaeModel`.

    Args:
        features: ``[F, C]`` normalised features of all clips, concatenated.
        poses: ``[F, P]`` normalised poses.
        bounds: ``[(first, end)]`` frame range of every clip in the concatenation.
        window: ``T`` (odd).
        stride: Frames between pivots.
        pair_shift: Frames between a window and its partner (0: no partner).
    """

    def __init__(
        self,
        features: Tensor,
        poses: Tensor,
        bounds: Sequence[tuple[int, int]],
        window: int,
        stride: int,
        pair_shift: int = 0,
    ) -> None:
        self.features, self.poses = features, poses
        self._index(bounds, window, stride, pair_shift)

    def _index(
        self, bounds: Sequence[tuple[int, int]], window: int, stride: int, pair_shift: int
    ) -> None:
        """Window starts, pivots, clips and partner shifts of clips at ``bounds``."""
        if pair_shift < 0:
            raise SkelagnosticError(f"data.pair_shift must be >= 0 frames, got {pair_shift}")
        self.window = window
        self.pair_shift = int(pair_shift)
        half = window // 2
        starts, clips, pivots, shifts = [], [], [], []
        for c, (first, end) in enumerate(bounds):
            local = torch.arange(half, max(half, end - first - half), stride)  # none if too short
            start = first + local - half
            starts.append(start)
            pivots.append(local)
            clips.append(torch.full_like(local, c))
            later = start + pair_shift + window <= end
            earlier = start - pair_shift >= first
            shift = torch.where(later, pair_shift, torch.where(earlier, -pair_shift, 0))
            shifts.append(shift.long())
        empty = torch.zeros(0, dtype=torch.long)
        self.starts = torch.cat(starts) if starts else empty
        self.pivots = torch.cat(pivots) if pivots else empty
        self.clips = torch.cat(clips) if clips else empty
        self.shifts = torch.cat(shifts) if shifts else empty
        self._offsets = torch.arange(window)

    def __len__(self) -> int:
        return int(self.starts.numel())

    def __getitems__(self, indices: Sequence[int]) -> dict[str, Tensor]:
        """A stacked batch (what the data loaders fetch), with partners if ``pair_shift``."""
        return self.gather(indices, partners=bool(self.pair_shift))

    def gather(self, indices: Sequence[int], partners: bool = False) -> dict[str, Tensor]:
        """The windows ``indices`` stacked; ``partners`` adds ``shifted`` and ``shift``."""
        idx = torch.as_tensor(indices, dtype=torch.long)
        feats, poses = self._take(self.starts[idx])
        item = {
            "features": feats.transpose(1, 2).contiguous(),
            "poses": poses,
            "clip": self.clips[idx],
            "pivot": self.pivots[idx],
        }
        if partners:
            shift = self.shifts[idx]
            item["shifted"] = (
                self._take(self.starts[idx] + shift, poses=False)[0].transpose(1, 2).contiguous()
            )
            item["shift"] = shift
        return item

    def _take(self, starts: Tensor, poses: bool = True) -> tuple[Tensor, Tensor | None]:
        """``([B, T, C] features, [B, T, P] poses or None)`` of the windows at ``starts``."""
        frames = starts[:, None] + self._offsets
        return self.features[frames], self.poses[frames] if poses else None

    def __getitem__(self, index: int) -> dict[str, Tensor]:
        if not 0 <= index < len(self):
            raise IndexError(f"window index {index} out of range [0, {len(self)})")
        return {k: v[0] for k, v in self.gather([index]).items()}


class CachedFrameWindows(FrameWindows):
    """:class:`FrameWindows` whose frames stay in the cache and are read per batch.

    Every clip is one cache entry of ``[copies, F, J, C_in + C_pose]`` raw values
    (velocities, then root-local positions; a second copy is the clip's mirror image
    with ``data.features=authors``), each copy a clip of the dataset if
    ``copies``, else the first only. :meth:`gather` reads the ``T``
    frames of each asked window from its entry with a positioned read (no
    memory map) and normalises them with the dataset's statistics, so the
    values are those of :class:`FrameWindows` over the normalised frames, and
    the process holds only the windows of its current batches. Pickles
    cheaply into data-loader workers (paths and statistics).

    Args:
        entries: Cache entries of the clips, in dataset order.
        representation: The fitted input representation (its statistics are copied).
        poses: The fitted pose representation (its statistics are copied).
        window: ``T`` (odd).
        stride: Frames between pivots.
        pair_shift: Frames between a window and its partner (0: no partner).
        copies: Use every copy of an entry as a clip (the training split), else the first.
    """

    def __init__(
        self,
        entries: Sequence[CacheEntry],
        representation: MotionRepresentation,
        poses: MotionRepresentation,
        window: int,
        stride: int,
        pair_shift: int = 0,
        copies: bool = False,
    ) -> None:
        self.entries = list(entries)
        #: ``(entry index, copy)`` of every clip of the dataset.
        self.segments = [
            (e, c)
            for e, entry in enumerate(self.entries)
            if entry.num_windows
            for c in range(entry.num_windows if copies else 1)
        ]
        #: Clip ids of the segments (``<id>/mirrored`` for an entry's second copy).
        self.clip_names = [
            self.entries[e].meta["clip"] + ("/mirrored" if c else "") for e, c in self.segments
        ]
        self._n_in = len(representation.channels)
        self._stats = [
            (r.mean.clone(), r.std.clone())  # type: ignore[union-attr]
            for r in (representation, poses)
        ]
        lengths = np.cumsum([0] + [self.entries[e].layout[1][1] for e, _ in self.segments])
        self._firsts = torch.as_tensor(lengths[:-1], dtype=torch.long)
        self._index(
            list(zip(lengths[:-1].tolist(), lengths[1:].tolist(), strict=True)),
            window,
            stride,
            pair_shift,
        )

    def _read(self, clip: int, first: int, count: int) -> np.ndarray:
        """Raw frames ``first:first + count`` of clip ``clip``, ``[count, J, C_in + C_pose]``."""
        e, copy = self.segments[clip]
        entry = self.entries[e]
        offset, shape = entry.layout
        out = np.empty((count, *shape[2:]), np.float32)
        with entry.array.open("rb", buffering=0) as fh:
            fh.seek(offset + (copy * shape[1] + first) * 4 * math.prod(shape[2:]))
            read_exactly(fh, out, entry.array)
        return out

    def _normalize(self, raw: Tensor, poses: bool = True) -> tuple[Tensor, Tensor | None]:
        (mean, std), (pmean, pstd) = self._stats
        feats = ((raw[..., : self._n_in] - mean) / std).flatten(-2)
        if not poses:
            return feats, None
        return feats, ((raw[..., self._n_in :] - pmean) / pstd).flatten(-2)

    def _take(self, starts: Tensor, poses: bool = True) -> tuple[Tensor, Tensor | None]:
        clips = torch.searchsorted(self._firsts, starts, right=True) - 1
        raw = (
            torch.from_numpy(
                np.stack(
                    [
                        self._read(int(c), int(s - self._firsts[c]), self.window)
                        for c, s in zip(clips.tolist(), starts.tolist(), strict=True)
                    ]
                )
            )
            if len(starts)
            else torch.zeros(0, self.window, 0, 0)
        )
        return self._normalize(raw, poses)

    def frames(self) -> Iterator[tuple[Tensor, Tensor]]:
        """Every clip's normalised ``([F, C] features, [F, P] poses)``, one clip at a time."""
        for clip, (e, _) in enumerate(self.segments):
            feats, poses = self._normalize(
                torch.from_numpy(self._read(clip, 0, self.entries[e].layout[1][1]))
            )
            yield feats, poses  # type: ignore[misc]

    @property
    def features(self) -> Tensor:  # type: ignore[override]
        """``[F, C]`` normalised features of all clips (loads them all: small data only)."""
        return torch.cat([f for f, _ in self.frames()])

    @property
    def poses(self) -> Tensor:  # type: ignore[override]
        """``[F, P]`` normalised poses of all clips (loads them all: small data only)."""
        return torch.cat([p for _, p in self.frames()])


def _frame_chunks(
    entries: Sequence[CacheEntry], channels: slice, chunk_values: int = STATS_CHUNK_VALUES
) -> Iterator[Tensor]:
    """The ``channels`` of every frame (of every copy) of ``entries`` in ``[frames, J, C]`` chunks.

    Chunks hold a fixed number of frames (``chunk_values`` values with all
    channels; the last chunk of a clip may be shorter), read from the files, so
    fitting statistics over them (:meth:`MotionRepresentation.fit_normalization`)
    needs memory independent of the corpus.
    """
    for entry in entries:
        if not entry.num_windows:
            continue
        offset, shape = entry.layout
        rows = max(1, chunk_values // max(1, math.prod(shape[2:])))
        with entry.array.open("rb", buffering=0) as fh:
            fh.seek(offset)
            total = shape[0] * shape[1]  # every copy of the clip (the mirror image too)
            for first in range(0, total, rows):
                buf = np.empty((min(rows, total - first), *shape[2:]), np.float32)
                read_exactly(fh, buf, entry.array)
                yield torch.from_numpy(buf[..., channels])


class VqpaeDataModule(MotionDataModule):
    """Multi-dataset windows for the VQ-PAE (see the module docstring).

    Args:
        sources: Clip sources (default: procedural biped + quadruped); a
            :class:`~skelagnostic.data.MultiSource` gives one dataset per part.
        fps: Frame rate the clips are resampled to (the authors: 60).
        window: Frames per window, used only when ``window_seconds`` is ``None``; odd.
        stride: Frames between pivots (the authors: 1, every frame).
        window_seconds: Window length in seconds (1.0): ``T = round(fps * window_seconds) + 1``,
            plus one if that is even.
        std_floor: Lower bound of every channel's standard deviation, as a fraction of
            the dataset's mean channel standard deviation (0 turns the floor off).
        pair_seconds: Offset of the partner window every training window carries
            (``max(1, round(fps * pair_seconds))`` frames; default 0: none, as the
            authors), which the aligner's phase-rate loss needs
            (``model.lambda_phase_rate``; ``experiment=vqpae_plus`` sets 0.1 s, which
            keeps the phase advance between the two windows unambiguous up to 5 Hz).
        features: ``raw`` (default: :class:`RootLocalVelocities` and root-local positions
            of every frame) or ``authors`` (the WalkTheDog exporter's velocities and
            positions, :func:`~skelagnostic_vqpae.features.authors_features`, and a
            mirrored copy of every training clip).
        **kwargs: The other options of :class:`~skelagnostic.data.MotionDataModule`
            (``representation``: default :class:`RootLocalVelocities`; ``batch_size``:
            windows per batch and dataset, 32; ``cache_dir``: cache of the per-clip
            features; ...). Normalisation is always per element.

    Raises:
        SkelagnosticError: The window length is even or not positive, another argument is
            out of range, or ``per_element_stats`` or ``augment`` is given.
    """

    no_augmentation = (
        "its frame windows are read from cached per-frame features, not from the motion, "
        "and the authors train on their data as it is"
    )

    def __init__(
        self,
        sources: ClipSource | Sequence[ClipSource] | None = None,
        *,
        fps: float = 30.0,
        window: int = 31,
        stride: int = 1,
        window_seconds: float | None = 1.0,
        std_floor: float = 0.01,
        pair_seconds: float = 0.0,
        features: str = "raw",
        **kwargs: Any,
    ) -> None:
        if "per_element_stats" in kwargs:
            raise SkelagnosticError(
                "data.per_element_stats is not an option of VqpaeDataModule: its statistics "
                "are always per element"
            )
        if features not in FEATURES:
            raise SkelagnosticError(
                f"data.features must be one of {', '.join(FEATURES)}, got {features!r}"
            )
        if not pair_seconds >= 0:
            raise SkelagnosticError(f"data.pair_seconds must be >= 0, got {pair_seconds}")
        if not 0 <= std_floor < 1:
            raise SkelagnosticError(f"data.std_floor must be in [0, 1), got {std_floor}")
        if window_seconds is not None:
            if not window_seconds > 0:
                raise SkelagnosticError(f"data.window_seconds must be > 0, got {window_seconds}")
            window = round(float(fps) * window_seconds) + 1
            if window % 2 == 0:
                window += 1  # the pivot must be unique
        if window % 2 == 0:
            raise SkelagnosticError(
                f"data.window must be odd so the pivot frame is unique, got {window}"
            )
        super().__init__(sources, fps=fps, window=window, stride=stride, **kwargs)
        self.window_seconds = window_seconds
        self.std_floor = float(std_floor)
        self.pair_seconds = float(pair_seconds)
        self.features = features
        if features == "authors" and type(self.representation) is not RootLocalVelocities:
            raise SkelagnosticError(
                "data.features=authors computes its own velocities: leave data.representation "
                f"at its default, got {type(self.representation).__name__}"
            )
        #: Frames between a training window and its partner (0: no partner).
        self.pair_shift = max(1, round(float(fps) * pair_seconds)) if pair_seconds > 0 else 0
        self._poses = GlobalPositions(frame="root")
        #: Per dataset, the root-local position representation with its normalisation.
        self.pose_representations: dict[str, MotionRepresentation] = {}
        #: Per dataset and split, the clip ids in :class:`FrameWindows` order.
        self.clip_ids: dict[str, dict[str, list[str]]] = {s: {} for s in ("train", "val", "test")}

    def default_representation(self) -> MotionRepresentation:
        """Root-local joint velocities."""
        return RootLocalVelocities()

    def preprocessing(self) -> dict[str, Any]:
        """What the cached per-clip features depend on."""
        rep = type(self.representation)
        return {
            "representation": f"{rep.__module__}.{rep.__qualname__}",
            "options": self.representation.config(),
            "fps": self.fps,
            "layout": _LAYOUT,
            **({"features": self.features} if self.features != "raw" else {}),
        }

    def _encode(self, source: ClipSource, clip: ClipRef) -> tuple[np.ndarray, dict[str, Any]]:
        """The clip's frames as one ``[copies, F, J, C_in + C_pose]`` cache entry and its metadata.

        One copy; with ``features="authors"`` two if the skeleton has left/right pairs
        (the second is the mirror image).
        """
        motion = source.load(clip)
        if motion.fps != self.fps:
            motion = motion.resample(self.fps)
        if self.features == "authors":
            copies = [torch.cat(authors_features(motion), -1)]
            if motion.skeleton.mirror_map() != list(range(motion.num_joints)):
                copies.append(torch.cat(authors_features(motion, mirrored=True), -1))
            feats = torch.stack(copies)
        else:
            rep, poses = self.representation, self._poses
            feats = torch.cat([rep.encode(motion), poses.encode(motion)], -1)[None]
        long_enough = motion.num_frames >= self.window
        array = (
            feats.float().numpy() if long_enough else np.zeros((0, *feats.shape[1:]), np.float32)
        )
        meta = {
            "clip": clip.id,
            "skeleton": motion.skeleton.to_dict(),
            "starts": [0] * len(feats) if long_enough else [],
            "fps": self.fps,
            "units": motion.units,
        }
        return array, meta

    def add_dataset(self, name: str, members: list[tuple[ClipRef, CacheEntry]]) -> None:
        """Per-clip frame datasets with velocity and pose statistics (floored by ``std_floor``)."""
        entries = {clip.id: entry for clip, entry in members}
        split = self.split_clips([c for c, _ in members])
        n_in = len(self.representation.channels)
        train = [entries[c.id] for c in split["train"]]
        rep = copy.deepcopy(self.representation)
        rep.fit_normalization(_frame_chunks(train, slice(None, n_in)), per_element=True)
        poses = copy.deepcopy(self._poses)
        poses.fit_normalization(_frame_chunks(train, slice(n_in, None)), per_element=True)
        for r, label in ((rep, "input"), (poses, "pose")):
            check_statistics(name, r, label)
            if r.std is not None:
                r.std = torch.maximum(r.std, self.std_floor * r.std.mean())
        self.representations[name] = rep
        self.pose_representations[name] = poses
        self.skeletons[name] = Skeleton.from_dict(entries[split["train"][0].id].meta["skeleton"])
        for part, clips in split.items():
            if not clips:
                continue
            ds = CachedFrameWindows(
                [entries[c.id] for c in clips],
                rep,
                poses,
                self.window,
                self.stride,
                self.pair_shift if part == "train" else 0,
                copies=part == "train",
            )
            if len(ds):
                self.datasets[part][name] = ds  # type: ignore[assignment]
                self.clip_ids[part][name] = ds.clip_names

    def channels(self, name: str) -> int:
        """Input channels ``C = J * 3`` of dataset ``name``."""
        return self.skeletons[name].num_joints * len(self.representation.channels)

    def collate(self, name: str) -> Callable[[Any], dict[str, Any]]:
        """Batches come stacked from the datasets (``__getitems__``); the skeleton and fps added."""
        return SkeletonCollate(self.skeletons[name], self.fps, stacked=True)

    def state_dict(self) -> dict[str, Any]:
        """Velocity and pose normalisation statistics per dataset."""
        return {
            name: {
                "input": rep.normalization_state(),
                "pose": self.pose_representations[name].normalization_state(),
            }
            for name, rep in self.representations.items()
        }

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        """Restore statistics saved by :meth:`state_dict`."""
        for name, stats in state_dict.items():
            if name in self.representations:
                self.representations[name].load_normalization_state(stats["input"])
                self.pose_representations[name].load_normalization_state(stats["pose"])
