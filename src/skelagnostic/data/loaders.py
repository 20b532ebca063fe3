"""Training loaders that resume mid-epoch: a sharded sampler and a loader saved in checkpoints.

Also the collate functions of a dataset's loaders: :class:`SkeletonCollate` attaches
the dataset's skeleton and frame rate to every batch (what a model reads the
topology from), :class:`TaggedCollate` puts a batch under its dataset's name.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Any

from torch.utils.data import DataLoader, Dataset, DistributedSampler, default_collate

if TYPE_CHECKING:
    from skelagnostic.core.skeleton import Skeleton

__all__ = ["ResumableDataLoader", "ResumableSampler", "SkeletonCollate", "TaggedCollate"]


class ResumableSampler(DistributedSampler):
    """A :class:`DistributedSampler` (one shard per rank) that can start a pass part-way.

    The order of a pass depends only on ``seed`` and the epoch (never on the
    global RNG), so a resumed run sees the same windows as an uninterrupted one.
    A ``keyed`` sampler yields ``(seed, epoch, index)`` instead of ``index``: what
    an augmenting :class:`~skelagnostic.data.WindowDataset` draws its transform
    from, the same in every worker and on every rank.
    """

    def __init__(
        self,
        dataset: Dataset,
        num_replicas: int,
        rank: int,
        shuffle: bool,
        seed: int,
        keyed: bool = False,
    ) -> None:
        super().__init__(dataset, num_replicas=num_replicas, rank=rank, shuffle=shuffle, seed=seed)
        #: Indices to drop from the start of the next pass (set when resuming).
        self.skip = 0
        self.keyed = keyed

    def __iter__(self) -> Iterator[Any]:
        indices = list(super().__iter__())[self.skip :]
        self.skip = 0
        if self.keyed:
            return iter([(self.seed, self.epoch, i) for i in indices])
        return iter(indices)


class ResumableDataLoader(DataLoader):
    """A training :class:`DataLoader` whose position is saved in checkpoints.

    Lightning stores :meth:`state_dict` with every checkpoint (``combined_loader``
    in the fit-loop state) and calls :meth:`load_state_dict` before iterating
    again, so training resumed from a mid-epoch checkpoint continues with the
    very next batch of the interrupted pass: exact resume. It counts the
    batches handed to the training loop (not those prefetched by workers).

    The saved position belongs to the pass of one epoch. It is applied only if
    the next pass is of that same epoch: a checkpoint taken on the last batch
    of epoch ``k`` (the pass is over; Lightning resumes with epoch ``k + 1``
    and sets the sampler's epoch before iterating) starts the next pass at its
    first batch instead of skipping it whole.

    Args:
        dataset: The windows.
        batch_size: Windows per batch.
        sampler: The pass order.
        num_workers: Worker processes.
        collate_fn: How items become a batch (default: torch's ``default_collate``).
    """

    def __init__(
        self,
        dataset: Dataset,
        batch_size: int,
        sampler: ResumableSampler,
        num_workers: int = 0,
        collate_fn: Callable[[Any], Any] | None = None,
    ) -> None:
        super().__init__(
            dataset,
            batch_size=batch_size,
            sampler=sampler,
            num_workers=num_workers,
            persistent_workers=num_workers > 0,
            collate_fn=collate_fn,
        )
        self._served = 0
        #: ``(epoch, batches served)`` of the interrupted pass, set by :meth:`load_state_dict`.
        self._resume_at: tuple[int, int] | None = None

    def __iter__(self) -> Iterator[Any]:
        resume, self._resume_at = self._resume_at, None
        epoch = int(self.sampler.epoch)
        served = resume[1] if resume is not None and resume[0] == epoch else 0
        self.sampler.skip = served * int(self.batch_size)
        self._served = served
        for batch in super().__iter__():
            self._served += 1
            yield batch

    def state_dict(self) -> dict[str, int]:
        """The epoch of the sampler and the batches served in its current pass."""
        return {"epoch": int(self.sampler.epoch), "served": self._served}

    def load_state_dict(self, state_dict: dict[str, int]) -> None:
        """Continue the pass of :meth:`state_dict` with its next batch.

        The sampler is set to the saved epoch; if the epoch is changed before
        the next pass starts (the saved pass was complete), that pass starts
        from its beginning.
        """
        self.sampler.set_epoch(state_dict["epoch"])
        self._resume_at = (int(state_dict["epoch"]), int(state_dict["served"]))


class SkeletonCollate:
    """Collate function of one dataset's loaders: its items stacked, plus its skeleton and fps.

    Every batch gets ``skeleton`` (the dataset's
    :class:`~skelagnostic.core.skeleton.Skeleton`: joint names, parents, up axis,
    body groups) and ``fps`` (a float) next to its tensors, so a model reads the
    topology from the batch and runs without a Trainer or a data module. They are
    attached once per batch, not per item, and stay on the CPU when Lightning moves
    the batch to a device (neither is a tensor); the per-window tensors derived from
    each clip's skeleton (``offsets``, ``template``, ``height``) are items of their
    own. Picklable, so it goes to data-loader workers with the loader.

    Args:
        skeleton: The dataset's skeleton.
        fps: Frame rate of the dataset's windows.
        stacked: The dataset gathers whole batches itself (``__getitems__``): the
            batch is passed through, not collated.
    """

    def __init__(self, skeleton: Skeleton, fps: float, stacked: bool = False) -> None:
        self.skeleton = skeleton
        self.fps = float(fps)
        self.stacked = stacked

    def __call__(self, items: Any) -> dict[str, Any]:
        """The batch of ``items`` with ``skeleton`` and ``fps``."""
        batch = items if self.stacked else default_collate(items)
        return {**batch, "skeleton": self.skeleton, "fps": self.fps}


class TaggedCollate:
    """Collate function wrapping the batch as ``{name: batch}`` (picklable for workers).

    Args:
        name: The dataset's name.
        collate: How the items become the batch (default: torch's ``default_collate``;
            a data module passes its :class:`SkeletonCollate`).
    """

    def __init__(self, name: str, collate: Callable[[Any], Any] | None = None) -> None:
        self.name = name
        self.collate = collate

    def __call__(self, items: Any) -> dict[str, Any]:
        """Collate ``items`` and put the batch under the dataset's name."""
        return {self.name: (self.collate or default_collate)(items)}
