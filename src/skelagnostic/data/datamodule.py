"""The :class:`MotionDataModule`: clips -> cached windows -> one batch per skeleton per step."""

from __future__ import annotations

import copy
import hashlib
import math
import os
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import lightning as L
import numpy as np
import torch
from lightning.pytorch.utilities import CombinedLoader
from torch.utils.data import DataLoader, Dataset, DistributedSampler, default_collate

from skelagnostic.core.skeleton import Skeleton
from skelagnostic.data.cache import (
    CacheEntry,
    WindowCache,
    cache_key,
    default_cache_dir,
    read_exactly,
)
from skelagnostic.data.sources import ClipRef, ClipSource, ProceduralSource
from skelagnostic.errors import SkelagnosticError
from skelagnostic.representations import GlobalPositions, MotionRepresentation

SPLITS = ("train", "val", "test")


#: Values (frames x elements x channels) per chunk of the normalisation pass. The
#: pass reads the training windows in chunks of this fixed size, so what it
#: allocates does not depend on the corpus or the clip lengths.
STATS_CHUNK_VALUES = 1 << 20


class WindowDataset(Dataset):
    """The cached windows of clips that share one skeleton topology.

    Items are dicts of tensors: ``features`` ``[window, N, C]`` float32 (not
    normalised), ``clip`` (index into :attr:`clip_ids`), ``start`` (first
    frame), and the clip's skeleton: ``offsets`` ``[J, 3]``, ``template``
    ``[J, 3]`` (:meth:`Skeleton.template`) and ``height``. Each item is read
    from its cache file when asked for (:meth:`CacheEntry.read`, no memory
    map), so a process holds only the windows of its current batches and the
    dataset pickles cheaply into workers.

    Args:
        entries: Cache entries of the clips.
    """

    def __init__(self, entries: Sequence[CacheEntry]) -> None:
        self.entries = list(entries)
        self.clip_ids = [e.meta["clip"] for e in self.entries]
        self._bounds = np.cumsum([0] + [e.num_windows for e in self.entries])
        self._skeletons = []
        for e in self.entries:
            sk = Skeleton.from_dict(e.meta["skeleton"])
            self._skeletons.append(
                (sk.offsets.float(), sk.template().float(), torch.tensor(sk.height()).float())
            )

    def __len__(self) -> int:
        return int(self._bounds[-1])

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        if not 0 <= index < len(self):
            raise IndexError(f"window index {index} out of range [0, {len(self)})")
        clip = int(np.searchsorted(self._bounds, index, side="right") - 1)
        k = index - int(self._bounds[clip])
        offsets, template, height = self._skeletons[clip]
        return {
            "features": torch.from_numpy(self.entries[clip].read(k, k + 1)[0]),
            "clip": torch.tensor(clip),
            "start": torch.tensor(self.entries[clip].meta["starts"][k]),
            "offsets": offsets,
            "template": template,
            "height": height,
        }

    def feature_chunks(self, chunk_values: int | None = None) -> Iterator[torch.Tensor]:
        """All features as ``[frames, N, C]`` chunks of a fixed size, for statistics.

        The windows of all clips are read from their files one after the
        other (no memory map), frames packed across window and clip boundaries
        into chunks of ``max(1, chunk_values // (N * C))`` frames (fewer if the
        dataset is smaller; the last chunk may be shorter). Each chunk is a new
        tensor, but all have the same size whatever the clips, so a pass that
        reduces them (:meth:`MotionRepresentation.fit_normalization`) runs in
        constant memory: the allocator reuses the freed chunks and temporaries.
        Variable, large per-clip temporaries were what made glibc's heap grow
        with the corpus when torch reduced them on several threads.

        Args:
            chunk_values: Values per chunk (default: :data:`STATS_CHUNK_VALUES`).

        Raises:
            SkelagnosticError: Two clips' windows have different element or channel counts.
        """
        if not self.entries:
            return
        item = self.entries[0].layout[1][2:]
        values = STATS_CHUNK_VALUES if chunk_values is None else chunk_values
        total = sum(e.layout[1][0] * e.layout[1][1] for e in self.entries)
        rows = max(1, min(total, values // max(1, math.prod(item))))
        buf, filled = np.empty((rows, *item), np.float32), 0
        for entry in self.entries:
            offset, shape = entry.layout
            if shape[2:] != item:
                raise SkelagnosticError(
                    f"data: clip {entry.meta['clip']!r} has windows of {shape[2:]} values per "
                    f"frame, clip {self.clip_ids[0]!r} of {item} (cache entry {entry.array})"
                )
            remaining = shape[0] * shape[1]
            with entry.array.open("rb", buffering=0) as fh:
                fh.seek(offset)
                while remaining:
                    n = min(rows - filled, remaining)
                    read_exactly(fh, buf[filled : filled + n], entry.array)
                    filled, remaining = filled + n, remaining - n
                    if filled == rows:
                        yield torch.from_numpy(buf)
                        buf, filled = np.empty((rows, *item), np.float32), 0
        if filled:
            yield torch.from_numpy(buf[:filled])


class _ResumableSampler(DistributedSampler):
    """A :class:`DistributedSampler` (one shard per rank) that can start a pass part-way.

    The order of a pass depends only on ``seed`` and the epoch (never on the
    global RNG), so a resumed run sees the same windows as an uninterrupted one.
    """

    def __init__(self, dataset: Dataset, num_replicas: int, rank: int, shuffle: bool,
                 seed: int) -> None:
        super().__init__(dataset, num_replicas=num_replicas, rank=rank, shuffle=shuffle,
                         seed=seed)
        #: Indices to drop from the start of the next pass (set when resuming).
        self.skip = 0

    def __iter__(self) -> Iterator[int]:
        indices = list(super().__iter__())[self.skip :]
        self.skip = 0
        return iter(indices)


class ResumableDataLoader(DataLoader):
    """A training :class:`DataLoader` whose position is saved in checkpoints.

    Lightning stores :meth:`state_dict` with every checkpoint (``combined_loader``
    in the fit-loop state) and calls :meth:`load_state_dict` before iterating
    again, so training resumed from a mid-epoch checkpoint continues with the
    very next batch of the interrupted pass: exact resume. It counts the
    batches handed to the training loop (not those prefetched by workers).

    Args:
        dataset: The windows.
        batch_size: Windows per batch.
        sampler: The pass order.
        num_workers: Worker processes.
    """

    def __init__(self, dataset: Dataset, batch_size: int, sampler: _ResumableSampler,
                 num_workers: int = 0) -> None:
        super().__init__(dataset, batch_size=batch_size, sampler=sampler,
                         num_workers=num_workers, persistent_workers=num_workers > 0)
        self._served = 0
        self._resume_at = 0

    def __iter__(self) -> Iterator[Any]:
        self._served, self._resume_at = self._resume_at, 0
        for batch in super().__iter__():
            self._served += 1
            yield batch

    def state_dict(self) -> dict[str, int]:
        """The epoch of the sampler and the batches served in the current pass."""
        return {"epoch": int(self.sampler.epoch), "served": self._served}

    def load_state_dict(self, state_dict: dict[str, int]) -> None:
        """Continue the pass of :meth:`state_dict` with its next batch."""
        self.sampler.set_epoch(state_dict["epoch"])
        self.sampler.skip = state_dict["served"] * int(self.batch_size)
        self._resume_at = state_dict["served"]


class _Tagged:
    """Collate function wrapping the batch as ``{name: batch}`` (picklable for workers)."""

    def __init__(self, name: str) -> None:
        self.name = name

    def __call__(self, items: list[dict[str, torch.Tensor]]) -> dict[str, Any]:
        return {self.name: default_collate(items)}


def _split_clips(
    clips: list[ClipRef], val_fraction: float, test_fraction: float, seed: int
) -> dict[str, list[ClipRef]]:
    """Deterministic split by clip; clips marked ``split="test"`` always go to test."""
    forced = [c for c in clips if c.split == "test"]
    rest = sorted(
        (c for c in clips if c.split != "test"),
        key=lambda c: hashlib.sha256(f"{seed}:{c.id}".encode()).hexdigest(),
    )
    n = len(rest)
    n_val = round(val_fraction * n)
    n_test = round(test_fraction * n)
    if val_fraction > 0 and n >= 2:
        n_val = max(1, n_val)
    if test_fraction > 0 and n - n_val >= 2:
        n_test = max(1, n_test)
    while n and n_val + n_test > n - 1:  # keep at least one training clip
        if n_test >= n_val and n_test:
            n_test -= 1
        else:
            n_val -= 1
    return {
        "val": rest[:n_val],
        "test": forced + rest[n_val : n_val + n_test],
        "train": rest[n_val + n_test :],
    }


class MotionDataModule(L.LightningDataModule):
    """Windows of motion clips for one or several skeletons, cached on disk.

    ``prepare_data`` (one process per node) loads each clip, resamples it to
    ``fps``, encodes it with the representation, cuts windows of ``window``
    frames every ``stride`` frames and caches them (keyed by the clip's
    content hash and this preprocessing). ``setup`` (every process) groups the
    clips by skeleton topology, one *dataset* per topology, splits each by
    clip into train/val/test, and fits one normalisation per dataset on its
    training windows (:attr:`representations`).

    Batches: training yields ``{dataset_name: batch}`` with one batch per
    dataset per step (shorter datasets cycle); validation and test yield the
    same dict with ``None`` for datasets already exhausted; predict yields
    one-entry dicts, dataset after dataset. Each batch is a dict of stacked
    :class:`WindowDataset` items.

    Subclasses usually override :meth:`default_representation` only.

    Args:
        sources: Clip sources (default: :class:`ProceduralSource` with its defaults).
        representation: Features to compute (default: :meth:`default_representation`).
        fps: Frame rate the clips are resampled to.
        window: Frames per window.
        stride: Frames between window starts.
        batch_size: Windows per batch and dataset.
        num_workers: Data-loader worker processes.
        val_fraction: Share of each dataset's clips used for validation.
        test_fraction: Share of clips used for testing (plus clips a preset marks as test).
        split_seed: Seed of the clip split.
        cache_dir: Window cache directory (default:
            :func:`~skelagnostic.data.cache.default_cache_dir`).
        per_element_stats: Normalisation per (element, channel) rather than per channel.

    Raises:
        SkelagnosticError: An argument is out of range (the message names it).
    """

    def __init__(
        self,
        sources: ClipSource | Sequence[ClipSource] | None = None,
        representation: MotionRepresentation | None = None,
        fps: float = 30.0,
        window: int = 32,
        stride: int = 16,
        batch_size: int = 32,
        num_workers: int = 0,
        val_fraction: float = 0.2,
        test_fraction: float = 0.0,
        split_seed: int = 0,
        cache_dir: str | Path | None = None,
        per_element_stats: bool = True,
    ) -> None:
        super().__init__()
        for arg, value, low in (("fps", fps, 0), ("window", window, 0), ("stride", stride, 0),
                                ("batch_size", batch_size, 0), ("num_workers", num_workers, -1)):
            if value <= low:
                raise SkelagnosticError(f"data.{arg} must be > {low}, got {value}")
        if not (0 <= val_fraction < 1 and 0 <= test_fraction < 1
                and val_fraction + test_fraction < 1):
            raise SkelagnosticError(
                f"data.val_fraction ({val_fraction}) and data.test_fraction ({test_fraction}) "
                "must be in [0, 1) with a sum below 1"
            )
        if sources is None:
            sources = [ProceduralSource()]
        self.sources = [sources] if isinstance(sources, ClipSource) else list(sources)
        self.representation = representation or self.default_representation()
        self.fps = float(fps)
        self.window = int(window)
        self.stride = int(stride)
        self.batch_size = int(batch_size)
        self.num_workers = int(num_workers)
        self.val_fraction = float(val_fraction)
        self.test_fraction = float(test_fraction)
        self.split_seed = int(split_seed)
        self.cache = WindowCache(cache_dir if cache_dir is not None else default_cache_dir())
        self.per_element_stats = per_element_stats
        #: ``split -> dataset name -> WindowDataset``, filled by :meth:`setup`.
        self.datasets: dict[str, dict[str, WindowDataset]] = {s: {} for s in SPLITS}
        #: A skeleton per dataset (of its first training clip).
        self.skeletons: dict[str, Skeleton] = {}
        #: A copy of the representation per dataset, with its normalisation fitted.
        self.representations: dict[str, MotionRepresentation] = {}

    def default_representation(self) -> MotionRepresentation:
        """The representation used when none is given (world joint positions)."""
        return GlobalPositions()

    @property
    def dataset_names(self) -> list[str]:
        """Names of the datasets (one per skeleton topology), available after :meth:`setup`."""
        return list(self.skeletons)

    def preprocessing(self) -> dict[str, Any]:
        """What the cached windows depend on besides the clip content."""
        rep = type(self.representation)
        return {
            "representation": f"{rep.__module__}.{rep.__qualname__}",
            "options": self.representation.config(),
            "fps": self.fps,
            "window": self.window,
            "stride": self.stride,
        }

    # ------------------------------------------------------------------ caching
    def _entry(self, source: ClipSource, clip: ClipRef) -> CacheEntry:
        key = cache_key(clip.key, self.preprocessing())
        entry = self.cache.get(key)
        if entry is not None:
            return entry
        motion = source.load(clip)
        if motion.fps != self.fps:
            motion = motion.resample(self.fps)
        starts = list(range(0, motion.num_frames - self.window + 1, self.stride))
        rep = self.representation
        if not starts:
            windows = np.zeros((0, self.window, rep.num_elements(motion.skeleton),
                                len(rep.channels)), np.float32)
        elif rep.window_dependent:
            windows = torch.stack(
                [rep.encode(motion[s : s + self.window]) for s in starts]
            ).float().numpy()
        else:
            feats = rep.encode(motion).float()
            windows = feats.unfold(0, self.window, self.stride).permute(0, 3, 1, 2).numpy()
        meta = {"clip": clip.id, "skeleton": motion.skeleton.to_dict(), "starts": starts,
                "fps": self.fps}
        return self.cache.put(key, windows, meta)

    def prepare_data(self) -> None:
        """Preprocess and cache every clip (runs once per node under DDP)."""
        for source in self.sources:
            for clip in source.clips():
                self._entry(source, clip)

    # -------------------------------------------------------------------- setup
    def setup(self, stage: str | None = None) -> None:
        """Group clips by topology, split them and fit normalisation (idempotent)."""
        if self.skeletons:
            return
        for source in self.sources:
            groups: dict[tuple[Any, ...], list[tuple[ClipRef, CacheEntry]]] = {}
            for clip in source.clips():
                entry = self._entry(source, clip)
                if entry.num_windows == 0:
                    continue
                sk = entry.meta["skeleton"]
                if Skeleton.from_dict(sk).height() <= 0:
                    raise SkelagnosticError(
                        f"data: clip {clip.id!r} has a skeleton of height 0 ({len(sk['parents'])} "
                        "joint(s), no bone of non-zero length); features are normalised by "
                        "the skeleton height"
                    )
                topo = (tuple(sk["joint_names"]), tuple(sk["parents"]))
                groups.setdefault(topo, []).append((clip, entry))
            for members in groups.values():
                self._add_dataset(self._dataset_name(source, members, len(groups)), members)
        if not self.skeletons:
            raise SkelagnosticError(
                f"data: no clip is at least data.window={self.window} frames long at "
                f"{self.fps:g} fps"
            )

    def _dataset_name(
        self, source: ClipSource, members: list[tuple[ClipRef, CacheEntry]], num_groups: int
    ) -> str:
        name = source.name
        if num_groups > 1:
            labels = {e.meta["skeleton"].get("name") for _, e in members}
            label = labels.pop() if len(labels) == 1 and None not in labels else None
            name = f"{name}/{label or str(len(members[0][1].meta['skeleton']['parents'])) + 'j'}"
        base, n = name, 2
        while name in self.skeletons:
            name, n = f"{base}-{n}", n + 1
        return name

    def _add_dataset(self, name: str, members: list[tuple[ClipRef, CacheEntry]]) -> None:
        entries = {clip.id: entry for clip, entry in members}
        split = _split_clips([c for c, _ in members], self.val_fraction, self.test_fraction,
                             self.split_seed)
        if not split["train"]:
            shown = ", ".join(c.id for c in split["test"][:3])
            more = f" and {len(split['test']) - 3} more" if len(split["test"]) > 3 else ""
            raise SkelagnosticError(
                f"dataset {name!r}: no training clip; all {len(members)} clip(s) of this "
                f"skeleton are in the test split ({shown}{more}). Loosen data.test_pattern, or "
                "add training clips of this skeleton"
            )
        for part, clips in split.items():
            if clips:
                self.datasets[part][name] = WindowDataset([entries[c.id] for c in clips])
        train = self.datasets["train"][name]
        self.skeletons[name] = Skeleton.from_dict(train.entries[0].meta["skeleton"])
        rep = copy.deepcopy(self.representation)
        rep.fit_normalization(train.feature_chunks(), per_element=self.per_element_stats)
        self.representations[name] = rep

    # -------------------------------------------------------------- dataloaders
    def _loaders(self, split: str, shuffle: bool) -> dict[str, DataLoader]:
        return {
            name: DataLoader(
                ds,
                batch_size=self.batch_size,
                shuffle=shuffle,
                num_workers=self.num_workers,
                persistent_workers=self.num_workers > 0,
            )
            for name, ds in self.datasets[split].items()
        }

    def train_dataloader(self) -> CombinedLoader:
        """One batch per dataset per step (``max_size_cycle``), resumable mid-epoch.

        Each dataset's order is a permutation seeded by the run's ``seed``
        (``PL_GLOBAL_SEED``, set by :func:`lightning.seed_everything`) and the
        epoch, sharded over the DDP ranks (:class:`ResumableDataLoader`).
        With ``trainer.overfit_batches`` set, plain loaders in a fixed order
        instead: Lightning rebuilds the training loaders with a sequential
        sampler to overfit the same batches, which the resumable loader does not
        support.
        """
        trainer = self.trainer
        if trainer is not None and getattr(trainer, "overfit_batches", 0):
            return CombinedLoader(self._loaders("train", shuffle=False), mode="max_size_cycle")
        replicas, rank = (trainer.world_size, trainer.global_rank) if trainer else (1, 0)
        seed = int(os.environ.get("PL_GLOBAL_SEED", "0"))
        loaders = {
            name: ResumableDataLoader(ds, self.batch_size,
                                      _ResumableSampler(ds, replicas, rank, True, seed),
                                      self.num_workers)
            for name, ds in self.datasets["train"].items()
        }
        return CombinedLoader(loaders, mode="max_size_cycle")

    def val_dataloader(self) -> CombinedLoader:
        """Every validation window once (``max_size``: exhausted datasets give ``None``)."""
        return CombinedLoader(self._loaders("val", shuffle=False), mode="max_size")

    def test_dataloader(self) -> CombinedLoader:
        """Every test window once (``max_size``)."""
        return CombinedLoader(self._loaders("test", shuffle=False), mode="max_size")

    def predict_dataloader(self) -> CombinedLoader:
        """The test windows (else the validation windows), one dataset after the other.

        Lightning only predicts over ``sequential`` loaders, so each batch is a
        one-entry ``{dataset_name: batch}`` dict and ``dataloader_idx`` tells
        the datasets apart.
        """
        split = "test" if self.datasets["test"] else "val"
        loaders = [
            DataLoader(ds, batch_size=self.batch_size, num_workers=self.num_workers,
                       collate_fn=_Tagged(name))
            for name, ds in self.datasets[split].items()
        ]
        return CombinedLoader(loaders, mode="sequential")

    # -------------------------------------------------------- checkpoint state
    def state_dict(self) -> dict[str, Any]:
        """The per-dataset normalisation statistics (saved in checkpoints)."""
        return {name: rep.normalization_state() for name, rep in self.representations.items()}

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        """Restore normalisation statistics saved by :meth:`state_dict`."""
        for name, stats in state_dict.items():
            if name in self.representations:
                self.representations[name].load_normalization_state(stats)
