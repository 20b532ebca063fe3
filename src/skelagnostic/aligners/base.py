"""The :class:`Aligner` base class: a LightningModule that maps motion to a shared latent space."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, ClassVar

import lightning as L
import torch

from skelagnostic.errors import SkelagnosticError

if TYPE_CHECKING:
    from skelagnostic.aligners.export import ExportGraph
    from skelagnostic.callbacks.fit_summary import SummaryContent
    from skelagnostic.core.motion import Motion
    from skelagnostic.core.skeleton import Skeleton

#: Capability names with an agreed meaning; aligners may declare others.
KNOWN_CAPABILITIES = frozenset(
    {
        "encode",  # encode(motion) works for the skeletons it was trained on
        "decode",  # decode(latent, skeleton) returns a Motion
        "retarget",  # retarget(motion, target) works between trained skeletons
        "unseen_topology",  # encode/decode/retarget also work for topologies not seen in training
        "quadruped",  # non-human skeletons are supported
        "phase",  # the latent carries phase/frequency/amplitude
        "denoise",  # decode(encode(noisy)) removes noise
        "interpolate",  # fills frames between keyframes: interpolate(motion, keyframes)
        "transfer",  # motion of one character -> another by matching: transfer(motion, targets)
    }
)


class CapabilityError(SkelagnosticError, NotImplementedError):
    """The aligner does not declare the capability an operation needs."""


@dataclass
class Latent:
    """What :meth:`Aligner.encode` returns.

    Attributes:
        z: The latent, method-specific shape; per-frame latents put time first (``[T, ...]``).
        fps: Frame rate of ``z`` along time.
        extras: What the method carries outside ``z`` (for example the root
            trajectory, which a root-local latent cannot hold).
    """

    z: torch.Tensor
    fps: float
    extras: dict[str, torch.Tensor] = field(default_factory=dict)


def batch_skeleton(batch: Mapping[str, Any], name: str | None = None) -> Skeleton:
    """The skeleton one dataset's batch carries (``batch["skeleton"]``).

    The data modules attach it to every batch
    (:class:`~skelagnostic.data.loaders.SkeletonCollate`), with the frame rate as
    ``batch["fps"]``, so a model reads the topology of what it trains on from the
    batch, not from ``self.trainer.datamodule``, and runs without either.

    Args:
        batch: One dataset's batch (a value of the step's ``{dataset: batch}``).
        name: The dataset's name, for the message.

    Returns:
        The dataset's :class:`~skelagnostic.core.skeleton.Skeleton`.

    Raises:
        SkelagnosticError: The batch carries no skeleton (its loader did not collate
            with the data module's :meth:`~skelagnostic.data.MotionDataModule.collate`).
    """
    from skelagnostic.core.skeleton import Skeleton

    skeleton = batch.get("skeleton")
    if not isinstance(skeleton, Skeleton):
        label = f" of dataset {name!r}" if name is not None else ""
        raise SkelagnosticError(
            f"the batch{label} carries no 'skeleton' (keys: {', '.join(map(str, batch))}); "
            "build its loader with the data module's collate function "
            "(MotionDataModule.collate, skelagnostic.data.loaders.SkeletonCollate)"
        )
    return skeleton


class Aligner(L.LightningModule, ABC):
    """Abstract LightningModule for skeleton-agnostic models.

    Subclasses implement :meth:`encode` and :meth:`decode` (plus the usual
    ``training_step``/``validation_step``/``configure_optimizers``) and declare
    :attr:`capabilities`. The training contract with ``skelagnostic fit``:

    * batches come from the registered :class:`~skelagnostic.data.MotionDataModule`:
      during training a ``dict`` with one batch per dataset (skeleton), during
      validation/test a ``dict`` where exhausted datasets map to ``None``, during
      predict a one-entry ``dict`` (``predict_step`` also gets ``dataloader_idx``);
    * each dataset's batch carries its ``skeleton`` and ``fps`` next to the tensors
      (read it with :func:`batch_skeleton`): a step needs no Trainer and no data
      module, so a model runs on batches from any loader built like the data module's;
    * ``validation_step`` logs ``"val/loss"`` (the default checkpoint monitor)
      and ``training_step`` logs ``"train/loss"``.

    Attributes:
        capabilities: What the aligner can do; see :data:`KNOWN_CAPABILITIES`.
        legacy_hparams: Hyper-parameters added after checkpoints were written with
            another behaviour: a checkpoint whose saved hyper-parameters lack a key
            is loaded with the value given here (the behaviour it was trained with),
            not with the constructor's current default.
    """

    capabilities: ClassVar[frozenset[str]] = frozenset()
    legacy_hparams: ClassVar[Mapping[str, Any]] = MappingProxyType({})

    @abstractmethod
    def encode(self, motion: Motion) -> Latent:
        """Encode a motion into the aligner's latent space.

        Args:
            motion: A motion on any skeleton the aligner supports.

        Returns:
            The latent.
        """

    @abstractmethod
    def decode(self, latent: Latent, skeleton: Skeleton) -> Motion:
        """Decode a latent onto a skeleton.

        Args:
            latent: Output of :meth:`encode` (possibly of another skeleton).
            skeleton: The skeleton to animate.

        Returns:
            A motion on ``skeleton`` at ``latent.fps``.
        """

    def retarget(self, motion: Motion, target: Skeleton) -> Motion:
        """Transfer a motion onto another skeleton: ``decode(encode(motion), target)``.

        Args:
            motion: The source motion.
            target: The target skeleton.

        Returns:
            The motion on ``target``.

        Raises:
            CapabilityError: The aligner does not declare ``"retarget"``.
        """
        self.require("retarget")
        return self.decode(self.encode(motion), target)

    def interpolate(self, motion: Motion, keyframes: Sequence[int]) -> Motion:
        """Fill the frames between keyframes (capability ``"interpolate"``).

        Aligners that declare ``"interpolate"`` override this.

        Args:
            motion: A motion whose frames at ``keyframes`` are the keys; other
                frames are ignored.
            keyframes: Increasing frame indices, the first being 0 and the last
                ``motion.num_frames - 1``.

        Returns:
            A motion of the same skeleton, length and fps whose keyframes equal
            the input's and whose other frames are generated.

        Raises:
            CapabilityError: The aligner does not declare ``"interpolate"``.
        """
        self.require("interpolate")
        raise NotImplementedError(
            f"{type(self).__name__} declares 'interpolate' but "
            "does not override Aligner.interpolate"
        )

    def transfer(self, motion: Motion, targets: Sequence[Motion]) -> Motion:
        """Re-enact ``motion`` with another character's motion (capability ``"transfer"``).

        Aligners that declare ``"transfer"`` override this (for example by
        matching in a shared latent space, as VQ-PAE does). An aligner that
        assembles the result from matched windows may set
        ``self.last_transitions`` to the result's frames where a new window
        starts; ``skelagnostic transfer html=...`` marks them on the viewer's
        timeline.

        Args:
            motion: The source motion.
            targets: Clips of the target character (all on one skeleton): the
                material the result is assembled from.

        Returns:
            A motion on the targets' skeleton following ``motion``.

        Raises:
            CapabilityError: The aligner does not declare ``"transfer"``.
        """
        self.require("transfer")
        raise NotImplementedError(
            f"{type(self).__name__} declares 'transfer' but does not override Aligner.transfer"
        )

    def export_graphs(self) -> list[ExportGraph]:
        """The networks an engine needs, for ``skelagnostic export`` (ONNX / TorchScript).

        The default exports nothing. Aligners that can be exported override this
        and return one :class:`~skelagnostic.aligners.export.ExportGraph` per network: a
        module taking and returning tensors only, example inputs, input/output
        names, the axes that may change size at run time, and sidecar metadata
        (normalisation statistics, skeleton). See ``docs/export.md``.

        Returns:
            The graphs; empty when the aligner cannot be exported.
        """
        return []

    def fit_summary(self, trainer: L.Trainer, mode: str = "full") -> SummaryContent:
        """What this aligner adds to the files written at the end of ``fit``.

        :class:`~skelagnostic.callbacks.FitSummary` (on by default for
        ``skelagnostic fit``) calls it once on global rank 0, in eval mode and
        without gradients, and writes the result with the logged metrics into
        the run directory: ``metrics`` merged into ``<name>_metrics.json``,
        ``renders`` as GIF + contact sheet, ``figures`` as PNG, ``notes`` in
        ``summary.md`` (see :class:`~skelagnostic.callbacks.SummaryContent`).
        The default adds nothing; override it rather than writing files in
        ``on_fit_end``.

        Args:
            trainer: The trainer that just fitted the aligner (its data module,
                logged metrics, ...).
            mode: ``"full"`` or ``"quick"`` (the run's ``summary=``, resolved by
                :func:`~skelagnostic.callbacks.summary_mode`): a quick summary
                should take seconds (fewer clips, shorter excerpts). An override
                without this argument is called without it (one summary).

        Returns:
            A :class:`~skelagnostic.callbacks.SummaryContent` mapping (every key optional).
        """
        return {}

    def stage_datamodule(self) -> Any | None:
        """The trainer's data module, set up for the stage running; ``None`` without one.

        For ``configure_model`` of an aligner whose layers depend on the data:
        Lightning calls that hook before every stage (after the data module's
        ``setup``), and callbacks that copy the model (``callbacks=ema``) call it
        before their copy, earlier than the module's ``setup``, so it sets the
        data module up itself.
        """
        dm = getattr(self._trainer, "datamodule", None)
        if dm is not None:
            fn = self.trainer.state.fn
            dm.setup(fn.value if fn is not None else "fit")
        return dm

    def supports(self, capability: str) -> bool:
        """Whether the aligner declares ``capability``."""
        return capability in self.capabilities

    def require(self, capability: str) -> None:
        """Raise :class:`CapabilityError` unless the aligner declares ``capability``."""
        if capability not in self.capabilities:
            declared = ", ".join(sorted(self.capabilities)) or "none"
            raise CapabilityError(
                f"{type(self).__name__} does not support {capability!r} (declared: {declared})"
            )
