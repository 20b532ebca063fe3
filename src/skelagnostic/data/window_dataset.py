"""The windows of one dataset as a torch :class:`~torch.utils.data.Dataset`, and their statistics.

A :class:`WindowDataset` reads the cached windows of clips that share one skeleton
topology; :meth:`WindowDataset.feature_chunks` feeds the normalisation pass in chunks of
:data:`STATS_CHUNK_VALUES` values, and :func:`check_statistics` refuses what it fitted
when a value is not finite.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator, Sequence

import numpy as np
import torch
from torch.utils.data import Dataset

from skelagnostic.core.skeleton import Skeleton
from skelagnostic.data.augment import WindowAugmenter
from skelagnostic.data.cache import CacheEntry, read_exactly
from skelagnostic.errors import SkelagnosticError
from skelagnostic.representations import MotionRepresentation

__all__ = ["STATS_CHUNK_VALUES", "WindowDataset", "check_statistics"]


#: Values (frames x elements x channels) per chunk of the normalisation pass. The
#: pass reads the training windows in chunks of this fixed size, so what it
#: allocates does not depend on the corpus or the clip lengths.
STATS_CHUNK_VALUES = 1 << 20


def check_statistics(
    dataset: str, representation: MotionRepresentation, label: str = "features"
) -> None:
    """Fail loudly if a fitted normalisation statistic is NaN or infinite.

    Non-finite statistics (a training clip with NaN or infinite values, e.g. a
    corrupt file) would otherwise train to ``loss=nan`` without an error.

    Args:
        dataset: Name of the dataset, for the message.
        representation: The representation whose statistics were just fitted.
        label: What the statistics describe (``features``, ``input``, ``pose``).

    Raises:
        SkelagnosticError: ``mean`` or ``std`` has a non-finite value (one line
            naming the dataset and the statistic).
    """
    for stat in ("mean", "std"):
        value = getattr(representation, stat)
        if value is not None and not bool(torch.isfinite(value).all()):
            bad = int((~torch.isfinite(value)).sum())
            raise SkelagnosticError(
                f"dataset {dataset!r}: the {label} normalisation statistic {stat!r} is not "
                f"finite ({bad} of {value.numel()} values); a training clip holds NaN or "
                "infinite values (check the source files, or run 'skelagnostic cache clear')"
            )


class WindowDataset(Dataset):
    """The cached windows of clips that share one skeleton topology.

    Items are dicts of tensors: ``features`` ``[window, N, C]`` float32 (not
    normalised), ``clip`` (index into :attr:`clip_ids`), ``start`` (first
    frame), and the clip's skeleton: ``offsets`` ``[J, 3]``, ``template``
    ``[J, 3]`` (:meth:`Skeleton.template`) and ``height``. Each item is read
    from its cache file when asked for (:meth:`CacheEntry.read`, no memory
    map), so a process holds only the windows of its current batches and the
    dataset pickles cheaply into workers.

    With an ``augmenter`` (training windows with ``data.augment.*``), every
    item is encoded from the clip's cached motion after the transform drawn for
    it (:class:`~skelagnostic.data.augment.WindowAugmenter`); the index is then
    a window index (epoch 0, the seed of ``$PL_GLOBAL_SEED``) or the ``(seed,
    epoch, window index)`` a keyed :class:`~skelagnostic.data.loaders.ResumableSampler`
    yields, so the transform depends on those only.

    Args:
        entries: Cache entries of the clips.
        augmenter: Augments the windows (default: none, the cached features).
    """

    def __init__(
        self, entries: Sequence[CacheEntry], augmenter: WindowAugmenter | None = None
    ) -> None:
        self.entries = list(entries)
        self.augmenter = augmenter
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

    def __getitem__(self, key: int | tuple[int, int, int]) -> dict[str, torch.Tensor]:
        if isinstance(key, tuple):
            seed, epoch, index = (int(v) for v in key)
        else:
            seed, epoch, index = int(os.environ.get("PL_GLOBAL_SEED", "0")), 0, int(key)
        if not 0 <= index < len(self):
            raise IndexError(f"window index {index} out of range [0, {len(self)})")
        clip = int(np.searchsorted(self._bounds, index, side="right") - 1)
        k = index - int(self._bounds[clip])
        offsets, template, height = self._skeletons[clip]
        start = self.entries[clip].meta["starts"][k]
        if self.augmenter is None:
            features = torch.from_numpy(self.entries[clip].read(k, k + 1)[0])
        else:
            draw = self.augmenter.options.draw(seed, epoch, index)
            features, start = self.augmenter.features(clip, start, draw)
        return {
            "features": features,
            "clip": torch.tensor(clip),
            "start": torch.tensor(start),
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
