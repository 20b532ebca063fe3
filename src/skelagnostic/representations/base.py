"""The :class:`MotionRepresentation` base class and its normalisation statistics."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterable
from typing import Any, ClassVar

import torch

from skelagnostic.core.motion import Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.errors import MotionError, NotInvertibleError, SkelagnosticError


class MotionRepresentation(ABC):
    """Turns a :class:`~skelagnostic.Motion` into a feature tensor and, where possible, back.

    Features are ``[T, N, C]``: per frame, ``N`` elements (joints or points)
    with ``C`` channels named by :attr:`channels`. Each subclass documents its
    layout and whether :meth:`decode` can rebuild a motion.

    Normalisation: :meth:`fit_normalization` computes a per-(element, channel)
    mean and standard deviation (or per channel, shared by all elements, with
    ``per_element=False``) over any number of leading dimensions;
    :meth:`normalize`/:meth:`denormalize` apply them. Channels listed in
    :attr:`unnormalized_channels` (one-hot codes) keep mean 0, std 1. Standard
    deviations below ``eps`` become 1, so constant channels do not divide by zero.

    Attributes:
        name: Registry name of the representation.
        channels: Names of the ``C`` channels.
        unnormalized_channels: Indices of channels that normalisation leaves alone.
        window_dependent: Whether a window's features depend on where the window
            starts (e.g. relative to its first frame); if not, data modules encode
            whole clips once and slice windows out of them.
    """

    name: ClassVar[str]
    channels: ClassVar[tuple[str, ...]]
    unnormalized_channels: ClassVar[tuple[int, ...]] = ()
    window_dependent: ClassVar[bool] = False

    def __init__(self) -> None:
        self.mean: torch.Tensor | None = None
        self.std: torch.Tensor | None = None

    @abstractmethod
    def encode(self, motion: Motion) -> torch.Tensor:
        """Features of ``motion``, ``[T, N, C]`` in the motion's dtype."""

    def decode(self, features: torch.Tensor, skeleton: Skeleton, fps: float = 30.0) -> Motion:
        """Rebuild a motion from features (unnormalised).

        Raises:
            NotInvertibleError: The representation does not determine a motion.
        """
        raise NotInvertibleError(
            f"{type(self).__name__} features cannot be decoded back to a Motion"
        )

    def config(self) -> dict[str, Any]:
        """The constructor options (JSON-serialisable), used in cache keys."""
        return {}

    def num_elements(self, skeleton: Skeleton) -> int:
        """``N``, the number of feature elements for ``skeleton`` (joints by default)."""
        return skeleton.num_joints

    # -------------------------------------------------------------- normalisation
    @property
    def is_fitted(self) -> bool:
        """Whether normalisation statistics are set."""
        return self.mean is not None

    def fit_normalization(
        self,
        features: torch.Tensor | Iterable[torch.Tensor],
        per_element: bool = True,
        eps: float = 1e-6,
    ) -> None:
        """Compute normalisation statistics from ``[..., N, C]`` features.

        Args:
            features: Training features, or an iterable of chunks of them (for
                data larger than memory); every leading dimension is reduced.
            per_element: One statistic per (element, channel); ``False`` shares
                them over elements (needed when ``N`` varies, e.g. across skeletons).
            eps: Standard deviations below this become 1.

        Raises:
            MotionError: A chunk has the wrong channel count, or there are no values.
        """
        chunks = [features] if isinstance(features, torch.Tensor) else features
        count, total, squares = 0, None, None
        for chunk in chunks:
            self._check(chunk, "features")
            flat = chunk.reshape(-1, *chunk.shape[-2:]).double()
            if not per_element:
                flat = flat.reshape(-1, 1, flat.shape[-1])
            if total is not None and flat.shape[1:] != total.shape:
                raise MotionError(
                    f"fit_normalization: chunks have {flat.shape[1]} and {total.shape[0]} elements"
                )
            count += flat.shape[0]
            total = flat.sum(0) if total is None else total + flat.sum(0)
            squares = (flat**2).sum(0) if squares is None else squares + (flat**2).sum(0)
        if total is None or squares is None or count == 0:
            raise MotionError("fit_normalization: features has no frames")
        mean = total / count
        std = (squares / count - mean**2).clamp_min(0.0).sqrt()
        std = torch.where(std < eps, torch.ones_like(std), std)
        keep = list(self.unnormalized_channels)
        mean[..., keep] = 0.0
        std[..., keep] = 1.0
        self.mean, self.std = mean.float(), std.float()

    def normalize(self, features: torch.Tensor) -> torch.Tensor:
        """``(features - mean) / std`` with the fitted statistics."""
        mean, std = self._stats(features)
        return (features - mean) / std

    def denormalize(self, features: torch.Tensor) -> torch.Tensor:
        """Inverse of :meth:`normalize`."""
        mean, std = self._stats(features)
        return features * std + mean

    def normalization_state(self) -> dict[str, torch.Tensor]:
        """The statistics as a ``state_dict``-style mapping (``mean``, ``std``)."""
        if self.mean is None or self.std is None:
            raise SkelagnosticError(f"{type(self).__name__}: normalisation statistics not fitted")
        return {"mean": self.mean.clone(), "std": self.std.clone()}

    def load_normalization_state(self, state: dict[str, torch.Tensor]) -> None:
        """Set statistics saved by :meth:`normalization_state`."""
        for key in ("mean", "std"):
            if key not in state:
                raise SkelagnosticError(f"normalisation state lacks {key!r}")
        self.mean, self.std = state["mean"].float(), state["std"].float()

    def _stats(self, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        if self.mean is None or self.std is None:
            raise SkelagnosticError(
                f"{type(self).__name__}: call fit_normalization (or load_normalization_state) first"
            )
        self._check(features, "features")
        if self.mean.shape[0] not in (1, features.shape[-2]):
            raise MotionError(
                f"features have {features.shape[-2]} elements but the statistics were fitted "
                f"for {self.mean.shape[0]}"
            )
        return (
            self.mean.to(features.device, features.dtype),
            self.std.to(features.device, features.dtype),
        )

    def _check(self, features: torch.Tensor, what: str) -> None:
        if features.dim() < 2 or features.shape[-1] != len(self.channels):
            raise MotionError(
                f"{what} must have shape [..., N, {len(self.channels)}] for "
                f"{type(self).__name__}, got {list(features.shape)}"
            )

    def _check_decodable(self, features: torch.Tensor, skeleton: Skeleton) -> None:
        self._check(features, "features")
        if features.dim() != 3 or features.shape[1] != self.num_elements(skeleton):
            raise MotionError(
                f"features must have shape [T, {self.num_elements(skeleton)}, "
                f"{len(self.channels)}] for {skeleton!r}, got {list(features.shape)}"
            )
