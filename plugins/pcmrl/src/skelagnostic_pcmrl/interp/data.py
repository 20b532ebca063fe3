"""Training data of PC-MRL's interpolation model (Sec. 3.4, Sec. 4.3 protocol).

:class:`PcmrlInterpDataModule` holds motions of ONE target skeleton topology
(for PC-MRL: the stage-1 reconstructions written by ``skelagnostic retarget``;
any BVH files or procedural clips of that topology work, e.g.
``data=bvh data.paths=[out/*.bvh] data.units=m``). Clips whose hierarchy (parent
list) equals the first clip's are accepted whatever their joint names and bone
lengths; each window keeps its own clip's offsets. Lengths must be in metres
(the paper's convention and the unit of the RPA range): pass ``data.units``
for files in other units.

Training windows (``window`` frames, 128 in the paper) are drawn at random
positions with a random number of keyframes in ``[min_keys, max_keys]`` (5 to
36 in the paper), the first and last frames always keys, the others spread
uniformly at random (or, with ``key_mode="regular"``, a key every ``g`` frames
with ``g`` drawn per window); rest pose augmentation (:mod:`skelagnostic_pcmrl.interp.rpa`) is
applied to a share ``rpa_prob`` of them with range ``rpa_range`` (metres).
Validation/test windows are fixed (every ``stride`` frames) with a key every
``val_gap`` frames plus the last frame.
"""

from __future__ import annotations

import logging
import os
import random
from collections.abc import Sequence
from typing import Any

import torch
import torch.nn.functional as F
from torch.utils.data import DataLoader

from skelagnostic.core.skeleton import Skeleton
from skelagnostic.data import MotionDataModule
from skelagnostic.data.cache import CacheEntry, cache_key, slot_key
from skelagnostic.data.sources import ClipRef, ClipSource, ProceduralSource
from skelagnostic.errors import SkelagnosticError
from skelagnostic_pcmrl.interp.clips import (
    CachedClip,
    Clip,
    FixedWindows,
    TrainWindows,
)
from skelagnostic_pcmrl.interp.rpa import (
    RPA_OFFSETS,
    RPA_SOLVES,
    bone_tails,
)

__all__ = ["PcmrlInterpDataModule"]

log = logging.getLogger(__name__)

#: Version of the cached per-clip layout (global rotations and root per frame).
_LAYOUT = "pcmrl-interp-frames-1"

#: A target skeleton taller than this (in metres) is almost certainly not in metres.
MAX_HEIGHT_M = 3.0


def _check_options(
    *,
    window: int,
    stride: int,
    batch_size: int,
    samples_per_epoch: int,
    val_gap: int,
    min_keys: int,
    max_keys: int,
    key_mode: str,
    min_gap: int,
    max_gap: int,
    rpa_range: float,
    rpa_prob: float,
    rpa_offsets: str,
    rpa_solve: str,
) -> None:
    """Raise :class:`SkelagnosticError` naming the first out-of-range data option."""
    checks = (
        ("window", window, 2),
        ("stride", stride, 0),
        ("batch_size", batch_size, 0),
        ("samples_per_epoch", samples_per_epoch, 0),
        ("val_gap", val_gap, 0),
        ("min_keys", min_keys, 1),
    )
    for arg, value, low in checks:
        if value <= low:
            raise SkelagnosticError(f"data.{arg} must be > {low}, got {value}")
    if max_keys < min_keys:
        raise SkelagnosticError(f"data.max_keys ({max_keys}) < data.min_keys ({min_keys})")
    if key_mode not in ("random", "regular"):
        raise SkelagnosticError(f"data.key_mode must be 'random' or 'regular', got {key_mode!r}")
    if not 1 <= min_gap <= max_gap:
        raise SkelagnosticError(
            f"data.min_gap ({min_gap}) and data.max_gap ({max_gap}) must satisfy "
            "1 <= min_gap <= max_gap"
        )
    if rpa_range < 0 or not 0 <= rpa_prob <= 1:
        raise SkelagnosticError("data.rpa_range must be >= 0 and data.rpa_prob in [0, 1]")
    if rpa_offsets not in RPA_OFFSETS:
        raise SkelagnosticError(
            f"data.rpa_offsets must be one of {', '.join(RPA_OFFSETS)}, got {rpa_offsets!r}"
        )
    if rpa_solve not in RPA_SOLVES:
        raise SkelagnosticError(
            f"data.rpa_solve must be one of {', '.join(RPA_SOLVES)}, got {rpa_solve!r}"
        )


class PcmrlInterpDataModule(MotionDataModule):
    """Keyframe-interpolation windows on one target skeleton (see the module docstring).

    Args:
        sources: Clip sources (default: procedural ``biped31``, the CMU-31 hierarchy).
        representation: Must be ``None`` (the model computes its own FOQ features).
        window: Frames per window (paper 128).
        stride: Frames between validation/test window starts.
        min_keys: Fewest keyframes of a training window (paper 5).
        max_keys: Most keyframes of a training window (paper 36).
        batch_size: Windows per batch.
        samples_per_epoch: Random training windows per epoch.
        key_mode: Keyframes of the training windows: ``"random"`` (the paper: ``min_keys``
            to ``max_keys`` keys at random frames) or ``"regular"`` (not in the paper: a
            key every ``g`` frames, ``g`` uniform in ``[min_gap, max_gap]``, from a random
            phase; the layout of the Table 1 protocol and of ``interpolate every=N``).
        min_gap: Shortest key gap of ``key_mode="regular"``.
        max_gap: Longest key gap of ``key_mode="regular"``.
        val_gap: Keyframe gap of the validation/test windows.
        rpa_range: RPA tail offset range in metres (paper 0.1; 0 disables RPA).
        rpa_prob: Share of training windows that get RPA (not given by the paper).
        rpa_offsets: How the RPA tail offsets are drawn
            (:data:`~skelagnostic_pcmrl.interp.rpa.RPA_OFFSETS`): ``"independent"`` (every bone
            its own offset in ``[-rpa_range, rpa_range]^3``) or ``"mirrored"`` (the
            authors' draw: arm and leg bones only, each left/right pair one offset
            mirrored across the sagittal plane,
            :func:`~skelagnostic_pcmrl.interp.rpa.mirrored_tail_offsets`; their ``aug_range``
            of 0.1 is ``rpa_range=0.05``).
        rpa_solve: How the motion follows the moved tails
            (:data:`~skelagnostic_pcmrl.interp.rpa.RPA_SOLVES`): ``"directions"`` (the bones
            take the new lengths and keep their directions,
            :func:`~skelagnostic_pcmrl.interp.rpa.augment_rest_pose`) or ``"authors"`` (the
            authors' code: the bone lengths stay and the rotations are solved again,
            :func:`~skelagnostic_pcmrl.interp.rpa.authors_rest_pose_rotations`).
        mirror: Also train on the left/right mirror of every training clip (not in the paper).
        procedural_kind: Add procedural clips of this kind (same hierarchy) to training.
        procedural_clips: How many per gait (walk, run).
        seed: Seed of the window/keyframe/RPA draws.
        **kwargs: The other options of :class:`~skelagnostic.data.MotionDataModule`:
            ``fps`` (frame rate the clips are resampled to), ``val_fraction`` (share of
            the non-test clips used for validation), ``test_fraction`` (share of the
            clips moved to the test split, besides the clips a source marks as test,
            e.g. with ``data.test_pattern``), ``split_seed``, ``num_workers`` and
            ``cache_dir`` (every clip's global rotations and root are cached there and
            read per window, :class:`CachedClip`, so memory does not grow with the
            corpus).

    Raises:
        SkelagnosticError: On out-of-range options, clips of another hierarchy, or
            lengths that are not in metres.
    """

    no_augmentation = (
        "PC-MRL's interpolation has its own augmentation: rest-pose augmentation "
        "(data.rpa_*) and mirrored clips (data.mirror=true)"
    )

    def __init__(
        self,
        sources: ClipSource | Sequence[ClipSource] | None = None,
        representation: Any = None,
        *,
        window: int = 128,
        stride: int = 32,
        min_keys: int = 5,
        max_keys: int = 36,
        key_mode: str = "random",
        min_gap: int = 5,
        max_gap: int = 30,
        batch_size: int = 16,
        samples_per_epoch: int = 1024,
        val_gap: int = 15,
        rpa_range: float = 0.1,
        rpa_prob: float = 0.5,
        rpa_offsets: str = "independent",
        rpa_solve: str = "directions",
        mirror: bool = False,
        procedural_kind: str | None = None,
        procedural_clips: int = 0,
        seed: int = 0,
        **kwargs: Any,
    ) -> None:
        if representation is not None:
            raise SkelagnosticError(
                "data.representation is not used by pcmrl_interp (it computes FOQ features)"
            )
        _check_options(
            window=window,
            stride=stride,
            batch_size=batch_size,
            samples_per_epoch=samples_per_epoch,
            val_gap=val_gap,
            min_keys=min_keys,
            max_keys=max_keys,
            key_mode=key_mode,
            min_gap=min_gap,
            max_gap=max_gap,
            rpa_range=rpa_range,
            rpa_prob=rpa_prob,
            rpa_offsets=rpa_offsets,
            rpa_solve=rpa_solve,
        )
        if sources is None:
            sources = [ProceduralSource(kinds=("biped31",), gaits=("walk", "run"))]
        super().__init__(
            sources=sources,
            representation=None,
            window=window,
            stride=stride,
            batch_size=batch_size,
            **kwargs,
        )
        self.min_keys, self.max_keys = int(min_keys), int(max_keys)
        self.key_mode, self.min_gap, self.max_gap = key_mode, int(min_gap), int(max_gap)
        self.samples_per_epoch, self.val_gap = int(samples_per_epoch), int(val_gap)
        self.rpa_range, self.rpa_prob, self.mirror = float(rpa_range), float(rpa_prob), mirror
        self.rpa_offsets, self.rpa_solve = rpa_offsets, rpa_solve
        self.procedural_kind, self.procedural_clips = procedural_kind, int(procedural_clips)
        self.seed = int(seed)
        self.skeleton: Skeleton | None = None
        self.clips: dict[str, list[Clip]] = {"train": [], "val": [], "test": []}
        self.train_set: TrainWindows | None = None

    # ------------------------------------------------------------------ loading
    def prepare_data(self) -> None:
        """Cache every clip's global rotations and root (runs once per node under DDP)."""
        for source, ref, mirror in self._refs():
            self.cache_entry(source, ref, mirror)

    @property
    def dataset_names(self) -> list[str]:
        """One dataset: the target skeleton (after :meth:`setup`)."""
        return ["target"] if self.skeleton is not None else []

    def _extra(self) -> ProceduralSource | None:
        if not (self.procedural_kind and self.procedural_clips > 0):
            return None
        return ProceduralSource(
            kinds=(self.procedural_kind,),
            gaits=("walk", "run"),
            clips_per_gait=self.procedural_clips,
            seconds=8.0,
            seed=self.seed + 1000,
            name="procedural_extra",
        )

    def _refs(self) -> list[tuple[ClipSource, ClipRef, bool]]:
        """Every clip to cache: ``(source, clip, mirrored)`` (mirrors of all non-test clips)."""
        sources: list[ClipSource] = list(self.sources)
        extra = self._extra()
        if extra is not None:
            sources.append(extra)
        return [
            (src, ref, mirror)
            for src in sources
            for ref in src.clips()
            for mirror in ((False, True) if self.mirror and ref.split != "test" else (False,))
        ]

    def cache_entry(self, source: ClipSource, clip: ClipRef, mirror: bool = False) -> CacheEntry:
        """The cached frames of ``clip`` (resampled, mirrored if asked), built when missing.

        Replaces the base hook: one ``[1, F, J + 1, 4]`` entry per clip holding the
        global rotations and, as the last row, the root position (padded to 4).
        """
        # what the source does to the clip's content when loading it (class, units, re-rooting)
        loading = {
            "class": f"{type(source).__module__}.{type(source).__qualname__}",
            **source.loading(),
        }
        pre = {"layout": _LAYOUT, "fps": self.fps, "mirror": mirror, "source": loading}
        key = cache_key(clip.key, pre)
        entry = self.cache.get(key)
        if entry is None:
            motion = source.load(clip)
            if motion.fps != self.fps:
                motion = motion.resample(self.fps)
            if mirror:
                motion = motion.mirror()
            m = motion.float()
            frames = torch.cat(
                [m.global_rotations(), F.pad(m.root_positions, (0, 1))[:, None]], dim=1
            )
            meta = {
                "clip": clip.id,
                "skeleton": motion.skeleton.to_dict(),
                "starts": [0],
                "fps": self.fps,
                "offsets": m.skeleton.offsets.float().tolist(),
                "tails": bone_tails(m.skeleton).tails.float().tolist(),
            }
            entry = self.cache.put(key, frames.numpy()[None], meta)
        if os.path.isfile(clip.id):  # an edited file's earlier entry is deleted
            self.cache.track(slot_key(os.path.abspath(clip.id), pre), key)
        return entry

    def _check(self, entry: CacheEntry, name: str) -> None:
        """The target-skeleton checks of the (resampled) clip ``name``."""
        skeleton = Skeleton.from_dict(entry.meta["skeleton"])
        if self.skeleton is None:
            height = skeleton.height()
            if height > MAX_HEIGHT_M:
                raise SkelagnosticError(
                    f"data: clip {name!r} is {height:.3g} units tall; pcmrl_interp expects "
                    "metres (set data.units, e.g. data.units=cmu or data.units=cm)"
                )
            self.skeleton = skeleton
        elif list(skeleton.parents) != list(self.skeleton.parents):
            raise SkelagnosticError(
                f"data: clip {name!r} has {skeleton.num_joints} joints with another "
                f"hierarchy than the target skeleton {self.skeleton!r}; pcmrl_interp trains on "
                "one target skeleton"
            )

    def setup(self, stage: str | None = None) -> None:
        """Cache and check every clip, split by clip (idempotent).

        The clips stay in the cache (:class:`CachedClip`): memory does not grow
        with the corpus. For a stage other than ``fit`` (``test``, ``validate``,
        ``skelagnostic evaluate``) the data may hold no training clip, e.g.
        ``data.test_fraction=1`` to evaluate on every clip of another dataset.

        Raises:
            SkelagnosticError: No training clip when fitting (or ``stage=None``).
        """
        if self.skeleton is not None:
            return
        test: list[tuple[str, ClipSource, ClipRef]] = []
        rest: list[tuple[str, ClipSource, ClipRef]] = []
        for source in self.sources:
            for ref in source.clips():
                self._check(self.cache_entry(source, ref), ref.id)
                (test if ref.split == "test" else rest).append((ref.id, source, ref))
        extra = self._extra()
        procedural = []
        if extra is not None:
            for r in extra.clips():
                self._check(self.cache_entry(extra, r), r.id)
                procedural.append((f"procedural:{r.id}", extra, r))
        order = list(range(len(rest)))
        random.Random(self.split_seed).shuffle(order)
        n_test = round(self.test_fraction * len(rest))
        test += [rest[i] for i in sorted(order[:n_test])]
        order = order[n_test:]
        n_val = round(self.val_fraction * len(rest)) if len(order) > 1 else 0
        if self.val_fraction > 0 and len(order) > 1:
            n_val = max(n_val, 1)
        val_idx = set(order[:n_val])
        train = [rest[i] for i in order if i not in val_idx] + procedural
        if not train and stage in (None, "fit"):
            raise SkelagnosticError(
                "data: no training clips (every clip is in the test or validation split: lower "
                "data.test_fraction or data.val_fraction, or loosen the test pattern)"
            )

        def clips(items: list[tuple[str, ClipSource, ClipRef]], mirror: bool = False) -> list[Clip]:
            return [
                CachedClip(f"{n}:mirror" if mirror else n, self.cache_entry(src, ref, mirror))
                for n, src, ref in items
            ]

        val = [rest[i] for i in sorted(val_idx)]
        self.clips = {
            "train": clips(train) + (clips(train, mirror=True) if self.mirror else []),
            "val": clips(val),
            "test": clips(test),
        }
        # the split of the source clips, for split.json and skelagnostic evaluate
        for part, items in (("train", train), ("val", val), ("test", test)):
            self.assigned_splits.update((ref.id, part) for _, src, ref in items if src is not extra)
        self.skeletons = {"target": self.skeleton}
        if train:  # evaluation data (stage test/validate) may hold no training clip
            self.train_set = TrainWindows(
                self.clips["train"],
                self.window,
                self.min_keys,
                self.max_keys,
                self.rpa_range,
                self.rpa_prob,
                self.samples_per_epoch,
                self.seed,
                self.key_mode,
                self.min_gap,
                self.max_gap,
                self.rpa_offsets,
                self.rpa_solve,
            )
        for split in ("val", "test"):
            short = [c.name for c in self.clips[split] if c.num_frames < self.window]
            if short:
                log.warning(
                    "data: %s clips shorter than %d frames are skipped: %s",
                    split,
                    self.window,
                    ", ".join(short),
                )

    # ------------------------------------------------------------------ loaders
    def train_dataloader(self) -> DataLoader:
        """Random windows (new draws every epoch).

        Raises:
            SkelagnosticError: The data, set up for evaluation, holds no training clip.
        """
        if self.skeleton is None:
            self.setup("fit")
        if self.train_set is None:
            raise SkelagnosticError(
                "data: no training clips (every clip is in the test split: lower "
                "data.test_fraction or loosen the test pattern)"
            )
        return DataLoader(
            self.train_set,
            batch_size=self.batch_size,
            shuffle=False,
            num_workers=self.num_workers,
            drop_last=True,
            collate_fn=self.collate("target"),
        )

    def _fixed(self, split: str) -> DataLoader:
        self.setup(split)
        windows = FixedWindows(self.clips[split], self.window, self.stride, self.val_gap)
        return DataLoader(
            windows,
            batch_size=self.batch_size,
            num_workers=self.num_workers,
            collate_fn=self.collate("target"),
        )

    def val_dataloader(self) -> DataLoader | list:
        """Fixed windows of the validation clips (empty when there are none)."""
        self.setup("validate")
        return self._fixed("val") if self.clips["val"] else []

    def test_dataloader(self) -> DataLoader:
        """Fixed windows of the test clips (``test_pattern`` of the source)."""
        return self._fixed("test")

    def predict_dataloader(self) -> DataLoader:
        """Fixed windows of the test clips (as :meth:`test_dataloader`)."""
        return self._fixed("test")

    def state_dict(self) -> dict[str, Any]:
        """No loader state to resume (training windows are re-drawn per epoch)."""
        return {}

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        """Nothing to restore."""
