"""The :class:`MotionDataModule`: clips -> cached windows -> one batch per skeleton per step."""

from __future__ import annotations

import copy
import hashlib
import inspect
import math
import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, ClassVar

import lightning as L
import numpy as np
import torch
from lightning.pytorch.utilities import CombinedLoader
from lightning.pytorch.utilities.rank_zero import rank_zero_info, rank_zero_only
from torch.utils.data import DataLoader

from skelagnostic.core.motion import Motion
from skelagnostic.core.paths import expand_path
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.data.augment import MOTION_LAYOUT, Augmentation, WindowAugmenter, motion_frames
from skelagnostic.data.cache import (
    CacheEntry,
    WindowCache,
    cache_key,
    default_cache_dir,
    slot_key,
)
from skelagnostic.data.describe import describe_dataset
from skelagnostic.data.loaders import (
    ResumableDataLoader,
    ResumableSampler,
    SkeletonCollate,
    TaggedCollate,
)
from skelagnostic.data.progress import track_clips
from skelagnostic.data.sources import ClipRef, ClipSource, ProceduralSource, flatten_sources
from skelagnostic.data.window_dataset import WindowDataset, check_statistics
from skelagnostic.errors import SkelagnosticError
from skelagnostic.representations import GlobalPositions, MotionRepresentation

SPLITS = ("train", "val", "test")

#: Highest ``data.fps``: clips are resampled to it, so a huge rate would not fit in memory.
MAX_FPS = 1000.0


def _named_after(entry: CacheEntry, source: ClipSource, clip: ClipRef) -> CacheEntry:
    """``entry``, written for a clip of the same content, with ``clip``'s own names.

    The windows are shared (they depend on the content only), but the clip id
    and the skeleton (its ``name`` comes from the file, e.g. a BVH file's stem)
    are those of ``clip``: the clip is read again for its skeleton, the windows
    are not rebuilt. The cache files are not changed.
    """
    skeleton = source.load(clip).skeleton.to_dict()
    named = CacheEntry(entry.array, {**entry.meta, "clip": clip.id, "skeleton": skeleton})
    named.__dict__["layout"] = entry.layout  # the same file: spare a header read
    return named


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


def _keep_recorded(
    split: dict[str, list[ClipRef]], recorded: dict[str, str]
) -> dict[str, list[ClipRef]]:
    """``split`` with the recorded clips moved back to their recorded split.

    A test split asked for later takes no recorded clip: the training clips trained the
    model and the validation clips chose its checkpoint, so neither is held out.
    """
    out: dict[str, list[ClipRef]] = {part: [] for part in SPLITS}
    for part in SPLITS:
        for clip in split.get(part, []):
            out[recorded.get(clip.id, part) if recorded.get(clip.id) in SPLITS else part].append(
                clip
            )
    return out


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
    :class:`WindowDataset` items plus the dataset's ``skeleton``
    (:attr:`skeletons`) and ``fps`` (:meth:`collate`), so a model needs no data
    module to read the topology of its batches.

    Extension points (public hooks, see the "Data modules of a method" section
    of ``docs/data.md``): :meth:`default_representation` (what most subclasses
    override), :meth:`cache_entry` (what is cached per clip),
    :meth:`add_dataset` (how one topology's clips become datasets and
    statistics), :meth:`loaders` (the data loaders of a split) and
    :meth:`collate` (how a dataset's items become a batch). A subclass
    declares only its own constructor arguments and forwards the others with
    ``**kwargs``; :func:`datamodule_options` lists what a subclass accepts.

    Args:
        sources: Clip sources (default: :class:`ProceduralSource` with its defaults);
            a :class:`~skelagnostic.data.MultiSource` counts as its parts.
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
        augment: Augmentation of the training windows (``data.augment.*``:
            :class:`~skelagnostic.data.augment.Augmentation`); default none.

    Raises:
        SkelagnosticError: An argument is out of range (the message names it), or
            ``augment`` is on for a data module that refuses it (:attr:`no_augmentation`).
    """

    #: Why ``data.augment.*`` is refused, or None (the training windows take it): a
    #: subclass whose training datasets are not the base class's augmented
    #: :class:`WindowDataset` says why here.
    no_augmentation: ClassVar[str | None] = None

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
        augment: Augmentation | Mapping[str, Any] | None = None,
    ) -> None:
        super().__init__()
        self.augmentation = Augmentation.parse(augment)
        if self.augmentation.enabled and self.no_augmentation:
            raise SkelagnosticError(
                f"data.augment: {type(self).__name__} does not augment its windows: "
                f"{self.no_augmentation}; remove the data.augment.* settings"
            )
        for arg, value, ok, what in (
            ("fps", fps, not fps <= 0, "> 0"),  # NaN: refused below, with the limit
            ("window", window, window > 0, "> 0"),
            ("stride", stride, stride > 0, "> 0"),
            ("batch_size", batch_size, batch_size > 0, "> 0"),
            ("num_workers", num_workers, num_workers >= 0, ">= 0 (0: load in the main process)"),
        ):
            if not ok:
                raise SkelagnosticError(f"data.{arg} must be {what}, got {value}")
        if not math.isfinite(fps) or fps > MAX_FPS:  # resampling would allocate without bound
            raise SkelagnosticError(
                f"data.fps={fps:g}: must be a number of frames per second of at most "
                f"{MAX_FPS:g} (the clips are resampled to it)"
            )
        if not (
            0 <= val_fraction < 1 and 0 <= test_fraction < 1 and val_fraction + test_fraction < 1
        ):
            raise SkelagnosticError(
                f"data.val_fraction ({val_fraction}) and data.test_fraction ({test_fraction}) "
                "must be in [0, 1) with a sum below 1"
            )
        self.sources = flatten_sources(sources) or [ProceduralSource()]
        self.representation = representation or self.default_representation()
        self.fps = float(fps)
        self.window = int(window)
        self.stride = int(stride)
        self.batch_size = int(batch_size)
        self.num_workers = int(num_workers)
        self.val_fraction = float(val_fraction)
        self.test_fraction = float(test_fraction)
        self.split_seed = int(split_seed)
        self.cache = WindowCache(
            expand_path(cache_dir) if cache_dir is not None else default_cache_dir()
        )
        self.per_element_stats = per_element_stats
        #: ``split -> dataset name -> WindowDataset``, filled by :meth:`setup`.
        self.datasets: dict[str, dict[str, WindowDataset]] = {s: {} for s in SPLITS}
        #: A skeleton per dataset (of its first training clip).
        self.skeletons: dict[str, Skeleton] = {}
        #: A copy of the representation per dataset, with its normalisation fitted.
        self.representations: dict[str, MotionRepresentation] = {}
        #: ``clip id -> split`` of every clip :meth:`split_clips` placed (the CLI
        #: writes it to the run directory as ``split.json``).
        self.assigned_splits: dict[str, str] = {}
        #: A recorded ``clip id -> split`` to keep (a run's ``split.json``), or None.
        self.recorded_splits: dict[str, str] | None = None
        #: With augmentation: window cache entry path -> the clip's raw motion entry.
        self.motion_entries: dict[Path, CacheEntry] = {}

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
    def cache_entry(self, source: ClipSource, clip: ClipRef) -> CacheEntry:
        """The clip's cache entry, built with :meth:`_encode` when missing or damaged (a hook).

        The entry is keyed by the clip's content key, :meth:`preprocessing` and
        the source's :meth:`~skelagnostic.data.ClipSource.loading` options, so
        files of the same bytes share their windows; the names still come from
        the clip being read: an entry written for another clip id (a copy of the
        file under another name) is returned with this clip's id and skeleton
        (whose name is the file's, e.g. a BVH file's stem). A
        clip whose id is a file path keeps one entry per preprocessing: the
        entry of an earlier version of the file is deleted (:meth:`WindowCache.track`).
        Override it to cache something else per clip (PC-MRL's interpolation
        data caches global rotations, and mirrored copies).

        Args:
            source: The source ``clip`` comes from.
            clip: The clip.

        Returns:
            The cache entry (windows ``[N, T, E, C]`` and metadata).
        """
        key = cache_key(clip.key, {**self.preprocessing(), "loading": source.loading()})
        entry = self.cache.get(key)
        if entry is None:
            entry = self.cache.put(key, *self._encode(source, clip))
        elif entry.meta.get("clip") != clip.id:
            entry = _named_after(entry, source, clip)
        if os.path.isfile(clip.id):
            self.cache.track(slot_key(os.path.abspath(clip.id), self.preprocessing()), key)
        return entry

    def motion_entry(self, source: ClipSource, clip: ClipRef) -> CacheEntry:
        """The clip's resampled motion as one cache entry, built when missing.

        What augmented training windows are cut from (the window cache holds
        encoded features): ``[1, T, R, 4]`` rows of
        :func:`~skelagnostic.data.augment.motion_frames`, keyed by the clip's
        content, ``fps`` and the source's loading options (not the
        representation), so representations share it. Built only with
        ``data.augment.*`` on.
        """
        pre = {"layout": MOTION_LAYOUT, "fps": self.fps, "loading": source.loading()}
        key = cache_key(clip.key, pre)
        entry = self.cache.get(key)
        if entry is None:
            motion = self._load(source, clip)
            meta = {
                "kind": "motion",
                "clip": clip.id,
                "skeleton": motion.skeleton.to_dict(),
                "starts": [0],
                "fps": self.fps,
                "units": motion.units,
            }
            entry = self.cache.put(key, motion_frames(motion), meta)
        if os.path.isfile(clip.id):
            self.cache.track(slot_key(os.path.abspath(clip.id), pre), key)
        return entry

    def _load(self, source: ClipSource, clip: ClipRef) -> Motion:
        """``clip`` read from ``source`` and resampled to ``fps``."""
        motion = source.load(clip)
        return motion.resample(self.fps) if motion.fps != self.fps else motion

    def _encode(self, source: ClipSource, clip: ClipRef) -> tuple[np.ndarray, dict[str, Any]]:
        """Load, resample and encode ``clip``: its ``(windows, metadata)`` for the cache."""
        motion = self._load(source, clip)
        starts = list(range(0, motion.num_frames - self.window + 1, self.stride))
        rep = self.representation
        if not starts:
            windows = np.zeros(
                (0, self.window, rep.num_elements(motion.skeleton), len(rep.channels)), np.float32
            )
        elif rep.window_dependent:
            windows = (
                torch.stack([rep.encode(motion[s : s + self.window]) for s in starts])
                .float()
                .numpy()
            )
        else:
            feats = rep.encode(motion).float()
            windows = feats.unfold(0, self.window, self.stride).permute(0, 3, 1, 2).numpy()
        meta = {
            "clip": clip.id,
            "skeleton": motion.skeleton.to_dict(),
            "starts": starts,
            "fps": self.fps,
            "units": motion.units,
        }
        if (axes := source.axes(clip)) is not None:
            meta["axes"] = axes
        return windows, meta

    def prepare_data(self) -> None:
        """Preprocess and cache every clip (runs once per node under DDP).

        A pass that takes a while shows a progress bar on a terminal
        (:func:`~skelagnostic.data.progress.track_clips`).
        """
        clips = [(source, clip) for source in self.sources for clip in source.clips()]
        for source, clip in track_clips(clips, "data: caching windows", rank_zero_only.rank == 0):
            self.cache_entry(source, clip)
            if self.augmentation.enabled:
                self.motion_entry(source, clip)

    # -------------------------------------------------------------------- setup
    def setup(self, stage: str | None = None) -> None:
        """Group clips by topology, split them and fit normalisation (idempotent)."""
        if self.skeletons:
            return
        listed = [(i, clip) for i, source in enumerate(self.sources) for clip in source.clips()]
        entries = [
            (i, clip, self.cache_entry(self.sources[i], clip))
            for i, clip in track_clips(
                listed, "data: reading the window cache", rank_zero_only.rank == 0
            )
        ]
        for index, source in enumerate(self.sources):
            groups: dict[tuple[Any, ...], list[tuple[ClipRef, CacheEntry]]] = {}
            for i, clip, entry in entries:
                if i != index or entry.num_windows == 0:
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
                if self.augmentation.enabled:
                    self.motion_entries[entry.array] = self.motion_entry(source, clip)
            for members in groups.values():
                name = self._dataset_name(source, members, len(groups))
                self.add_dataset(name, members)
                if name in self.skeletons:
                    rank_zero_info(describe_dataset(name, members, self.assigned_splits))
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

    def split_clips(self, clips: list[ClipRef]) -> dict[str, list[ClipRef]]:
        """The train/val/test clips of one dataset (subclasses call this, not a copy).

        Clips are ordered by a hash of ``(split_seed, clip id)`` and cut by
        ``val_fraction`` / ``test_fraction``; clips a source marks as test stay
        test. With :attr:`recorded_splits` (a run's ``split.json``), every clip
        it lists keeps its recorded split, so a later verb never evaluates on a
        clip the model trained on, whatever fractions it is given; a
        ``test_fraction`` asked for later takes only clips the run never saw (a
        run recorded without test clips has no test split: its validation clips
        chose its checkpoint). Every placement is noted in :attr:`assigned_splits`.

        Args:
            clips: The clips of one dataset.

        Returns:
            ``{"train": [...], "val": [...], "test": [...]}``.
        """
        split = _split_clips(clips, self.val_fraction, self.test_fraction, self.split_seed)
        if self.recorded_splits:
            split = _keep_recorded(split, self.recorded_splits)
        for part, members in split.items():
            self.assigned_splits.update((c.id, part) for c in members)
        return split

    def add_dataset(self, name: str, members: list[tuple[ClipRef, CacheEntry]]) -> None:
        """Split one topology's clips and register its datasets and statistics (a hook).

        :meth:`setup` calls it once per (source, skeleton topology). The base
        version splits the clips with :meth:`split_clips`, fills
        ``datasets[split][name]`` with :class:`WindowDataset`, records the
        skeleton in :attr:`skeletons` and fits a copy of the representation's
        normalisation on the training windows (:attr:`representations`).
        Override it to leave datasets out (HuMoT skips non-human skeletons:
        return without registering) or to build other datasets (VQ-PAE).

        Args:
            name: Dataset name (the source's name, plus the skeleton's when a
                source holds several topologies).
            members: ``(clip, cache entry)`` of every clip of this topology.

        Raises:
            SkelagnosticError: Every clip is in the test split.
        """
        entries = {clip.id: entry for clip, entry in members}
        split = self.split_clips([c for c, _ in members])
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
        train.augmenter = self.window_augmenter(name, train.entries)
        self.skeletons[name] = Skeleton.from_dict(train.entries[0].meta["skeleton"])
        rep = copy.deepcopy(self.representation)
        rep.fit_normalization(train.feature_chunks(), per_element=self.per_element_stats)
        check_statistics(name, rep)
        self.representations[name] = rep

    def window_augmenter(self, name: str, entries: list[CacheEntry]) -> WindowAugmenter | None:
        """The augmenter of dataset ``name``'s training windows (None without ``data.augment``).

        A skeleton without left/right pairs is not mirrored (logged once).
        """
        if not self.augmentation.enabled:
            return None
        augmenter = WindowAugmenter(
            self.augmentation,
            copy.deepcopy(self.representation),
            [self.motion_entries[e.array] for e in entries],
            self.window,
        )
        if self.augmentation.mirror and not all(augmenter.mirrorable):
            rank_zero_info(
                f"data: dataset {name!r}: data.augment.mirror skips its clips of a skeleton "
                "without left/right joint pairs"
            )
        return augmenter

    # -------------------------------------------------------------- dataloaders
    def loaders(self, split: str, shuffle: bool) -> dict[str, DataLoader]:
        """One plain data loader per dataset of ``split`` (a hook).

        Validation, test and (with ``trainer.overfit_batches``) training use
        them; the resumable training loaders of :meth:`train_dataloader` and
        the predict loaders are built apart. All of them collate with
        :meth:`collate`. Override it to change the loader options.

        Args:
            split: ``"train"``, ``"val"`` or ``"test"``.
            shuffle: Whether to shuffle.

        Returns:
            ``{dataset name: DataLoader}``.
        """
        return {
            name: DataLoader(
                ds,
                batch_size=self.batch_size,
                shuffle=shuffle,
                num_workers=self.num_workers,
                persistent_workers=self.num_workers > 0,
                collate_fn=self.collate(name),
            )
            for name, ds in self.datasets[split].items()
        }

    def collate(self, name: str) -> Callable[[Any], dict[str, Any]]:
        """How the items of dataset ``name`` become a batch (a hook).

        The items stacked, with the dataset's skeleton (:attr:`skeletons`) and
        frame rate as ``skeleton`` and ``fps`` (:class:`SkeletonCollate`). Every
        loader of the data module uses it. Override it when the datasets gather
        their batches themselves (VQ-PAE: ``SkeletonCollate(..., stacked=True)``).

        Args:
            name: The dataset.

        Returns:
            A picklable collate function.
        """
        return SkeletonCollate(self.skeletons[name], self.fps)

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
            return CombinedLoader(self.loaders("train", shuffle=False), mode="max_size_cycle")
        replicas, rank = (trainer.world_size, trainer.global_rank) if trainer else (1, 0)
        seed = int(os.environ.get("PL_GLOBAL_SEED", "0"))
        loaders = {
            name: ResumableDataLoader(
                ds,
                self.batch_size,
                ResumableSampler(ds, replicas, rank, True, seed, keyed=_augments(ds)),
                self.num_workers,
                self.collate(name),
            )
            for name, ds in self.datasets["train"].items()
        }
        return CombinedLoader(loaders, mode="max_size_cycle")

    def val_dataloader(self) -> CombinedLoader:
        """Every validation window once (``max_size``: exhausted datasets give ``None``)."""
        return CombinedLoader(self.loaders("val", shuffle=False), mode="max_size")

    def test_dataloader(self) -> CombinedLoader:
        """Every test window once (``max_size``)."""
        return CombinedLoader(self.loaders("test", shuffle=False), mode="max_size")

    def predict_dataloader(self) -> CombinedLoader:
        """The test windows (else the validation windows), one dataset after the other.

        Lightning only predicts over ``sequential`` loaders, so each batch is a
        one-entry ``{dataset_name: batch}`` dict and ``dataloader_idx`` tells
        the datasets apart.
        """
        split = "test" if self.datasets["test"] else "val"
        loaders = [
            DataLoader(
                ds,
                batch_size=self.batch_size,
                num_workers=self.num_workers,
                collate_fn=self.predict_collate(name),
            )
            for name, ds in self.datasets[split].items()
        ]
        return CombinedLoader(loaders, mode="sequential")

    def predict_collate(self, name: str) -> Callable[[Any], dict[str, Any]]:
        """Collate function of dataset ``name``'s predict loader: ``{name: collated batch}``.

        The batch is :meth:`collate`'s, put under the dataset's name.
        """
        return TaggedCollate(name, self.collate(name))

    # -------------------------------------------------------- checkpoint state
    def state_dict(self) -> dict[str, Any]:
        """The per-dataset normalisation statistics (saved in checkpoints)."""
        return {name: rep.normalization_state() for name, rep in self.representations.items()}

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        """Restore normalisation statistics saved by :meth:`state_dict`."""
        for name, stats in state_dict.items():
            if name in self.representations:
                self.representations[name].load_normalization_state(stats)


def _augments(dataset: Any) -> bool:
    """Whether ``dataset`` is a :class:`WindowDataset` that augments its windows."""
    return isinstance(dataset, WindowDataset) and dataset.augmenter is not None


def datamodule_options(cls: type) -> dict[str, type]:
    """The constructor options a data-module class accepts, through its ``**kwargs`` too.

    A subclass of :class:`MotionDataModule` declares its own arguments and
    forwards the others with ``**kwargs``; this follows the ``**kwargs`` up the
    class hierarchy (the first declaration of a name wins, so a subclass's
    default shadows the base class's) until a constructor without them.

    Args:
        cls: A data-module class.

    Returns:
        ``{option name: the class whose constructor declares it}`` (``self``
        and ``*args``/``**kwargs`` excluded).

    Example:
        >>> datamodule_options(MotionDataModule)["batch_size"].__name__
        'MotionDataModule'
    """
    options: dict[str, type] = {}
    for klass in cls.__mro__:
        if "__init__" not in vars(klass):
            continue
        params = inspect.signature(vars(klass)["__init__"]).parameters
        for name, p in params.items():
            if name != "self" and p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY):
                options.setdefault(name, klass)
        if not any(p.kind is p.VAR_KEYWORD for p in params.values()):
            break
    return options
