"""Clips and windows of PC-MRL's interpolation data: frames, keyframe draws, window datasets.

:class:`Clip` holds one motion's global rotations and root per frame (:class:`CachedClip`
reads them from the window cache); the key functions draw a window's keyframes
(random, regular or every ``gap`` frames); :class:`TrainWindows` and
:class:`FixedWindows` are the training and the evaluation windows of
:class:`~skelagnostic_pcmrl.interp.data.PcmrlInterpDataModule`.
"""

from __future__ import annotations

import math
import random
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
from torch.utils.data import Dataset

from skelagnostic.core.motion import Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.data.cache import CacheEntry, read_exactly
from skelagnostic.errors import SkelagnosticError
from skelagnostic_pcmrl.interp.rpa import (
    augment_rest_pose,
    authors_rest_pose_rotations,
    bone_tails,
    mirrored_tail_offsets,
    random_tail_offsets,
)

__all__ = [
    "CachedClip",
    "Clip",
    "FixedWindows",
    "TrainWindows",
    "gap_keys",
    "random_keys",
    "regular_keys",
]


@dataclass
class Clip:
    """One motion of the target topology, ready for windowing (float32, metres).

    Attributes:
        name: Clip identifier.
        skeleton: Its own skeleton (same hierarchy as the target).
        global_rotations: ``[T, J, 4]``.
        root: ``[T, 3]``.
        offsets: ``[J, 3]``.
        tails: ``[J, 3]`` bone tails (:func:`~skelagnostic_pcmrl.interp.rpa.bone_tails`).
    """

    name: str
    skeleton: Skeleton
    global_rotations: torch.Tensor
    root: torch.Tensor
    offsets: torch.Tensor
    tails: torch.Tensor

    @classmethod
    def from_motion(cls, motion: Motion, name: str) -> Clip:
        """Precompute the global rotations of ``motion``."""
        m = motion.float()
        return cls(
            name,
            m.skeleton,
            m.global_rotations(),
            m.root_positions.clone(),
            m.skeleton.offsets.float(),
            bone_tails(m.skeleton).tails.float(),
        )

    @property
    def num_frames(self) -> int:
        """Frames of the clip."""
        return int(self.root.shape[0])

    def frames(self, start: int, stop: int) -> tuple[torch.Tensor, torch.Tensor]:
        """``(global rotations [n, J, 4], root [n, 3])`` of frames ``start:stop``."""
        return self.global_rotations[start:stop], self.root[start:stop]


class CachedClip(Clip):
    """A :class:`Clip` whose frames stay in the window cache and are read per window.

    The entry holds ``[1, T, J + 1, 4]`` float32 values: the global rotations
    and, in the last row, the root position (padded with 0). :meth:`frames`
    reads only the asked frames (positioned read, no memory map), so a process
    holds the windows of its current batches, not the corpus.

    Args:
        name: Clip identifier.
        entry: The cache entry (metadata: ``skeleton``, ``offsets``, ``tails``).
    """

    def __init__(self, name: str, entry: CacheEntry) -> None:
        meta = entry.meta
        sk = Skeleton.from_dict(meta["skeleton"])
        # the float32 skeleton of Clip.from_motion (motion.float() converts its offsets)
        self.name, self.entry = name, entry
        self.skeleton = (
            Motion(
                sk,
                torch.zeros(1, sk.num_joints, 4).index_fill_(-1, torch.tensor([0]), 1.0),
                torch.zeros(1, 3),
                float(meta["fps"]),
            )
            .float()
            .skeleton
        )
        self.offsets = torch.tensor(meta["offsets"], dtype=torch.float32)
        self.tails = torch.tensor(meta["tails"], dtype=torch.float32)

    @property
    def num_frames(self) -> int:
        """Frames of the clip."""
        return int(self.entry.layout[1][1])

    def frames(self, start: int, stop: int) -> tuple[torch.Tensor, torch.Tensor]:
        """Frames ``start:stop`` read from the cache entry."""
        offset, shape = self.entry.layout
        stop = min(stop, shape[1])
        out = np.empty((max(0, stop - start), *shape[2:]), np.float32)
        with self.entry.array.open("rb", buffering=0) as fh:
            fh.seek(offset + start * 4 * math.prod(shape[2:]))
            read_exactly(fh, out, self.entry.array)
        values = torch.from_numpy(out)
        return values[:, :-1], values[:, -1, :3]

    @property  # type: ignore[override]
    def global_rotations(self) -> torch.Tensor:
        """``[T, J, 4]`` of the whole clip (reads it all)."""
        return self.frames(0, self.num_frames)[0]

    @property  # type: ignore[override]
    def root(self) -> torch.Tensor:
        """``[T, 3]`` of the whole clip (reads it all)."""
        return self.frames(0, self.num_frames)[1]


def random_keys(length: int, min_keys: int, max_keys: int, rng: random.Random) -> torch.Tensor:
    """``[length]`` boolean mask: first and last frames plus random others.

    The number of keys is uniform in ``[min_keys, max_keys]`` (clipped to ``length``).
    """
    n = rng.randint(min(min_keys, length), min(max_keys, length))
    mask = torch.zeros(length, dtype=torch.bool)
    mask[0] = mask[-1] = True
    inner = list(range(1, length - 1))
    extra = max(n - 2, 0)
    if extra and inner:
        mask[rng.sample(inner, min(extra, len(inner)))] = True
    return mask


def regular_keys(length: int, min_gap: int, max_gap: int, rng: random.Random) -> torch.Tensor:
    """``[length]`` boolean mask: a key every ``g`` frames from a random phase, plus both ends.

    ``g`` is uniform in ``[min_gap, max_gap]`` and the first inner key at a uniform
    offset in ``[0, g)``, so every frame is equally likely to be a key.
    """
    gap = rng.randint(min_gap, max_gap)
    mask = torch.zeros(length, dtype=torch.bool)
    mask[rng.randrange(gap) :: gap] = True
    mask[0] = mask[-1] = True
    return mask


def gap_keys(length: int, gap: int) -> torch.Tensor:
    """``[length]`` boolean mask with a key every ``gap`` frames and on the last frame."""
    if gap <= 0:
        raise SkelagnosticError(f"keyframe gap must be positive, got {gap}")
    mask = torch.zeros(length, dtype=torch.bool)
    mask[::gap] = True
    mask[-1] = True
    return mask


def _window(clip: Clip, start: int, length: int, keys: torch.Tensor) -> dict[str, torch.Tensor]:
    rotations, root = clip.frames(start, start + length)
    return {
        "global_rotations": rotations,
        "root": root,
        "offsets": clip.offsets,
        "tails": clip.tails,
        "keys": keys,
    }


class TrainWindows(Dataset):
    """Random windows with random keyframes and RPA (map-style; DDP shards the indices)."""

    def __init__(
        self,
        clips: Sequence[Clip],
        window: int,
        min_keys: int,
        max_keys: int,
        rpa_range: float,
        rpa_prob: float,
        samples: int,
        seed: int,
        key_mode: str = "random",
        min_gap: int = 5,
        max_gap: int = 30,
        rpa_offsets: str = "independent",
        rpa_solve: str = "directions",
    ) -> None:
        self.clips = [c for c in clips if c.num_frames >= window]
        if not self.clips:
            raise SkelagnosticError(
                f"data: no training clip has data.window={window} frames; lower data.window or "
                "add longer clips"
            )
        self.weights = [c.num_frames - window + 1 for c in self.clips]
        self.window, self.min_keys, self.max_keys = window, min_keys, max_keys
        self.rpa_range, self.rpa_prob, self.rpa_offsets = rpa_range, rpa_prob, rpa_offsets
        self.rpa_solve = rpa_solve
        self.samples, self.seed = samples, seed
        self.key_mode, self.min_gap, self.max_gap = key_mode, min_gap, max_gap
        self.epoch = 0

    def __len__(self) -> int:
        return self.samples

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        rng = random.Random(hash((self.seed, self.epoch, index)))
        clip = rng.choices(self.clips, weights=self.weights)[0]
        start = rng.randint(0, clip.num_frames - self.window)
        if self.key_mode == "regular":
            keys = regular_keys(self.window, self.min_gap, self.max_gap, rng)
        else:
            keys = random_keys(self.window, self.min_keys, self.max_keys, rng)
        item = _window(clip, start, self.window, keys)
        if self.rpa_range > 0 and rng.random() < self.rpa_prob:
            gen = torch.Generator().manual_seed(rng.getrandbits(62))
            if self.rpa_offsets == "mirrored":
                delta = mirrored_tail_offsets(clip.skeleton, self.rpa_range, gen)
            else:
                delta = random_tail_offsets(clip.skeleton.num_joints, self.rpa_range, gen)
            if self.rpa_solve == "authors":
                grot = authors_rest_pose_rotations(
                    item["global_rotations"],
                    item["root"],
                    clip.offsets,
                    clip.tails,
                    clip.skeleton.parents,
                    delta,
                )
                item.update(global_rotations=grot)
                return item
            offsets, grot, tails = augment_rest_pose(
                clip.skeleton, item["global_rotations"], delta, offsets=clip.offsets
            )
            item.update(offsets=offsets, global_rotations=grot, tails=tails)
        return item


class FixedWindows(Dataset):
    """Windows every ``stride`` frames with a key every ``gap`` frames (validation/test)."""

    def __init__(self, clips: Sequence[Clip], window: int, stride: int, gap: int) -> None:
        self.items = [
            (c, s)
            for c in clips
            if c.num_frames >= window
            for s in range(0, c.num_frames - window + 1, stride)
        ]
        self.keys = gap_keys(window, gap)
        self.window = window

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        clip, start = self.items[index]
        return _window(clip, start, self.window, self.keys)
