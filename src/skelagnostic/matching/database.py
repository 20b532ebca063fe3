"""A flat frame database for motion matching.

The frames of many clips are stored back to back, one tensor per *feature
group* (for example ``"manifold"``, ``"pose"``, ``"frequency"``), with clip
ranges so that no candidate window ever crosses a clip boundary. Every group is
normalised as a whole (per-channel mean, one scale for the group: the mean of its
channel standard deviations, as in Holden's Motion-Matching database) and
multiplied by a per-group weight, so groups of different sizes and units can be
mixed in one cost.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from skelagnostic.matching._errors import MatchingError

if TYPE_CHECKING:
    from skelagnostic.matching.windows import WindowIndex

ArrayLike = torch.Tensor | np.ndarray | Sequence[float] | Sequence[Sequence[float]]

_FORMAT = "skelagnostic.matching.MotionDatabase/1"


def as_features(value: Any, name: str, device: torch.device | str | None = None) -> torch.Tensor:
    """Convert per-frame features to a finite float32 tensor of shape ``[N, D]``.

    Args:
        value: Tensor, numpy array or nested sequence, shape ``[N]`` or ``[N, D]``.
        name: What the features are, used in error messages.
        device: Where the result lives (default: where ``value`` lives, or CPU).

    Returns:
        A contiguous float32 tensor ``[N, D]`` (1-D input becomes ``[N, 1]``).

    Raises:
        MatchingError: If the value is not numeric, has more than 2 dimensions, is
            empty or holds NaN/inf.
    """
    try:
        tensor = torch.as_tensor(value)
    except (TypeError, ValueError, RuntimeError) as exc:
        raise MatchingError(f"{name}: cannot convert to a tensor ({exc})") from exc
    if not (tensor.is_floating_point() or tensor.dtype in (torch.int32, torch.int64)):
        raise MatchingError(f"{name}: expected real numbers, got dtype {tensor.dtype}")
    if tensor.dim() == 1:
        tensor = tensor[:, None]
    if tensor.dim() != 2:
        raise MatchingError(f"{name}: expected shape [frames, dims], got {tuple(tensor.shape)}")
    if tensor.shape[0] == 0 or tensor.shape[1] == 0:
        raise MatchingError(f"{name}: is empty (shape {tuple(tensor.shape)})")
    tensor = tensor.to(device=device, dtype=torch.float32).contiguous()
    bad = ~torch.isfinite(tensor)
    if bool(bad.any()):
        frame = int(bad.any(dim=1).nonzero()[0, 0])
        raise MatchingError(f"{name}: holds NaN or inf (first at frame {frame})")
    return tensor


class MotionDatabase:
    """Per-frame features of many clips, normalised per feature group, for motion matching.

    Frames of all clips are concatenated; ``clip_starts[c]:clip_starts[c + 1]`` is
    the range of clip ``c``. Each group ``g`` is stored raw and normalised as
    ``(x - mean_g) / scale_g * weight_g``, where ``mean_g`` is the per-channel mean
    over the whole database and ``scale_g`` the mean of the per-channel standard
    deviations (1 for a constant group). A weight ``w`` therefore multiplies the
    squared distances of its group by ``w**2``.

    Args:
        features: Group name -> per-frame features ``[N, D_g]`` (or ``[N]``), all
            groups with the same number of frames ``N``, clips back to back.
        clip_lengths: Number of frames of every clip, summing to ``N``.
        fps: Frame rate of the database (frames per second).
        weights: Optional group name -> weight (default 1 for every group).
        clip_names: Optional name of every clip (for reports).
        device: Where the tensors live (default: CPU or the device of the input).

    Raises:
        MatchingError: On an empty database, mismatched frame counts, NaN/inf
            features, non-positive clip lengths or fps, or unknown/negative weights.

    Examples:
        >>> import torch
        >>> from skelagnostic.matching import MotionDatabase
        >>> db = MotionDatabase.from_clips(
        ...     [{"pose": torch.randn(50, 6)}, {"pose": torch.randn(70, 6)}], fps=30
        ... )
        >>> db.num_frames, db.num_clips, db.dims["pose"]
        (120, 2, 6)
        >>> db.clip_range(1)
        (50, 120)
    """

    def __init__(
        self,
        features: Mapping[str, ArrayLike],
        clip_lengths: Sequence[int],
        fps: float,
        weights: Mapping[str, float] | None = None,
        clip_names: Sequence[str] | None = None,
        device: torch.device | str | None = None,
    ) -> None:
        started = time.perf_counter()
        if not isinstance(features, Mapping) or len(features) == 0:
            raise MatchingError("features: the database needs at least one feature group")
        if not (isinstance(fps, (int, float)) and np.isfinite(fps) and fps > 0):
            raise MatchingError(f"fps: must be a positive number, got {fps!r}")
        self.fps = float(fps)
        lengths = [int(n) for n in clip_lengths]
        if len(lengths) == 0:
            raise MatchingError("clip_lengths: the database needs at least one clip")
        if any(n <= 0 for n in lengths):
            raise MatchingError(f"clip_lengths: every clip needs at least one frame, got {lengths}")
        total = sum(lengths)
        self._raw: dict[str, torch.Tensor] = {}
        for name, value in features.items():
            tensor = as_features(value, f"features[{name!r}]", device)
            if tensor.shape[0] != total:
                raise MatchingError(
                    f"features[{name!r}]: has {tensor.shape[0]} frames but clip_lengths sum "
                    f"to {total}"
                )
            self._raw[str(name)] = tensor
        self.device = next(iter(self._raw.values())).device
        self.clip_starts = torch.zeros(len(lengths) + 1, dtype=torch.int64, device=self.device)
        self.clip_starts[1:] = torch.cumsum(torch.tensor(lengths, device=self.device), 0)
        if clip_names is not None and len(clip_names) != len(lengths):
            raise MatchingError(f"clip_names: got {len(clip_names)} names for {len(lengths)} clips")
        self.clip_names = [str(n) for n in clip_names] if clip_names is not None else None
        self.weights = {name: 1.0 for name in self._raw}
        for name, weight in (weights or {}).items():
            if name not in self._raw:
                raise MatchingError(f"weights: unknown feature group {name!r}")
            try:
                number = float(weight)
            except (TypeError, ValueError):
                number = math.nan
            if not (math.isfinite(number) and number >= 0):
                raise MatchingError(f"weights[{name!r}]: must be finite and >= 0, got {weight!r}")
            self.weights[name] = number
        self.mean: dict[str, torch.Tensor] = {}
        self.scale: dict[str, torch.Tensor] = {}
        self._normalized: dict[str, torch.Tensor] = {}
        for name, raw in self._raw.items():
            mean = raw.double().mean(dim=0)
            scale = raw.double().std(dim=0, unbiased=False).mean()
            self.mean[name] = mean.float()
            self.scale[name] = (
                scale.float() if float(scale) > 0 else torch.ones((), device=mean.device)
            )
            self._normalized[name] = self.normalize(name, raw)
        self._indexes: dict[tuple[Any, ...], WindowIndex] = {}
        self.build_seconds = time.perf_counter() - started

    @classmethod
    def from_clips(
        cls,
        clips: Sequence[Mapping[str, ArrayLike]],
        fps: float,
        weights: Mapping[str, float] | None = None,
        clip_names: Sequence[str] | None = None,
        device: torch.device | str | None = None,
    ) -> MotionDatabase:
        """Build a database from one mapping of feature groups per clip.

        Args:
            clips: One ``{group: [T_c, D_g]}`` mapping per clip; every clip must have
                the same groups with the same widths.
            fps: Frame rate shared by all clips.
            weights: Optional group name -> weight.
            clip_names: Optional clip names.
            device: Where the tensors live.

        Returns:
            The database.

        Raises:
            MatchingError: If ``clips`` is empty or the clips disagree on their groups,
                widths or frame counts.
        """
        if len(clips) == 0:
            raise MatchingError("clips: the database needs at least one clip")
        groups = list(clips[0].keys())
        lengths: list[int] = []
        parts: dict[str, list[torch.Tensor]] = {name: [] for name in groups}
        for c, clip in enumerate(clips):
            if sorted(clip.keys()) != sorted(groups):
                raise MatchingError(
                    f"clips[{c}]: has groups {sorted(clip.keys())}, clip 0 has {sorted(groups)}"
                )
            frames = None
            for name in groups:
                tensor = as_features(clip[name], f"clips[{c}][{name!r}]", device)
                if frames is not None and tensor.shape[0] != frames:
                    raise MatchingError(
                        f"clips[{c}][{name!r}]: has {tensor.shape[0]} frames, the clip's other "
                        f"groups have {frames}"
                    )
                if parts[name] and tensor.shape[1] != parts[name][0].shape[1]:
                    raise MatchingError(
                        f"clips[{c}][{name!r}]: has {tensor.shape[1]} dims, clip 0 has "
                        f"{parts[name][0].shape[1]}"
                    )
                frames = tensor.shape[0]
                parts[name].append(tensor)
            lengths.append(int(frames or 0))
        stacked = {name: torch.cat(tensors) for name, tensors in parts.items()}
        return cls(stacked, lengths, fps, weights=weights, clip_names=clip_names, device=device)

    # ------------------------------------------------------------------ layout
    @property
    def groups(self) -> list[str]:
        """Names of the feature groups."""
        return list(self._raw)

    @property
    def dims(self) -> dict[str, int]:
        """Width of every feature group."""
        return {name: raw.shape[1] for name, raw in self._raw.items()}

    @property
    def num_frames(self) -> int:
        """Total number of frames over all clips."""
        return int(self.clip_starts[-1])

    @property
    def num_clips(self) -> int:
        """Number of clips."""
        return self.clip_starts.numel() - 1

    @property
    def nbytes(self) -> int:
        """Bytes held by the database tensors (raw + normalised), without built indexes."""
        tensors = [*self._raw.values(), *self._normalized.values(), self.clip_starts]
        return sum(t.numel() * t.element_size() for t in tensors)

    def clip_range(self, clip: int) -> tuple[int, int]:
        """Global ``(start, stop)`` frame range of one clip.

        Args:
            clip: Clip index in ``[0, num_clips)``.

        Returns:
            The half-open frame range.

        Raises:
            MatchingError: If the clip index is out of range.
        """
        if not 0 <= clip < self.num_clips:
            raise MatchingError(f"clip: {clip} is not in [0, {self.num_clips})")
        return int(self.clip_starts[clip]), int(self.clip_starts[clip + 1])

    def locate(self, frames: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Map global frame indices to ``(clip, frame within the clip)``.

        Args:
            frames: Integer tensor of global frame indices in ``[0, num_frames)``.

        Returns:
            Two int64 tensors shaped like ``frames``: clip indices and local frames.
        """
        frames = torch.as_tensor(frames, dtype=torch.int64, device=self.device)
        clips = torch.searchsorted(self.clip_starts, frames, right=True) - 1
        return clips, frames - self.clip_starts[clips]

    def clip_end_of(self, frames: torch.Tensor) -> torch.Tensor:
        """Global index one past the last frame of the clip holding each frame."""
        clips, _ = self.locate(frames)
        return self.clip_starts[clips + 1]

    # ----------------------------------------------------------------- features
    def _check_group(self, group: str) -> None:
        if group not in self._raw:
            raise MatchingError(f"group: unknown feature group {group!r}; have {self.groups}")

    def raw(self, group: str) -> torch.Tensor:
        """Raw (un-normalised) features of one group, ``[N, D_g]`` float32."""
        self._check_group(group)
        return self._raw[group]

    def normalized(self, group: str) -> torch.Tensor:
        """Normalised, weighted features of one group, ``[N, D_g]`` float32."""
        self._check_group(group)
        return self._normalized[group]

    def normalize(self, group: str, values: ArrayLike) -> torch.Tensor:
        """Normalise and weight features given in the group's raw units.

        Args:
            group: Feature group name.
            values: ``[..., D_g]`` raw values (a query, say).

        Returns:
            ``(values - mean) / scale * weight`` as float32 on the database device.

        Raises:
            MatchingError: If the group is unknown or the last dimension does not match.
        """
        self._check_group(group)
        x = torch.as_tensor(values, dtype=torch.float32, device=self.device)
        if x.dim() == 0 or x.shape[-1] != self.dims[group]:
            raise MatchingError(
                f"{group}: expected last dimension {self.dims[group]}, got shape {tuple(x.shape)}"
            )
        return (x - self.mean[group]) / self.scale[group] * self.weights[group]

    def denormalize(self, group: str, values: torch.Tensor) -> torch.Tensor:
        """Invert :meth:`normalize` (a zero weight cannot be inverted and raises).

        Args:
            group: Feature group name.
            values: ``[..., D_g]`` normalised values.

        Returns:
            The values in the group's raw units.

        Raises:
            MatchingError: If the group is unknown or its weight is zero.
        """
        self._check_group(group)
        if self.weights[group] == 0:
            raise MatchingError(f"weights[{group!r}]: is 0, cannot denormalise")
        return values / self.weights[group] * self.scale[group] + self.mean[group]

    # ---------------------------------------------------------------- indexing
    def window_index(
        self,
        control: Sequence[str] | str,
        pose: str | None = None,
        *,
        frequency: str | None = None,
        length: int | None = None,
        samples: int | None = None,
        basis_size: int = 32,
    ) -> WindowIndex:
        """The (cached) exact search index over the candidate windows of this database.

        Exactly one of ``frequency`` (windows of one period ``t(k)``, frequency-scaled
        matching) and ``length`` (windows of a fixed ``T0`` frames, classical
        matching) must be given. Indexes are built once per set of arguments and
        cached on the database.

        Args:
            control: Group(s) compared over the whole window (the phase manifold).
            pose: Group compared at the window's first frame (pose descriptor), or None.
            frequency: Group (1 channel, Hz) giving every frame's period.
            length: Fixed window length in frames.
            samples: Samples every window is resampled to (default: ``round(fps)``
                for frequency windows, ``length`` for fixed windows).
            basis_size: Size of the projection used for the search's lower bound.

        Returns:
            The :class:`~skelagnostic.matching.windows.WindowIndex`.
        """
        from skelagnostic.matching.windows import WindowIndex

        controls = (control,) if isinstance(control, str) else tuple(control)
        key = (controls, pose, frequency, length, samples, basis_size)
        if key not in self._indexes:
            self._indexes[key] = WindowIndex.build(
                self,
                controls,
                pose,
                frequency=frequency,
                length=length,
                samples=samples,
                basis_size=basis_size,
            )
        return self._indexes[key]

    # ---------------------------------------------------------------- devices
    def to(self, device: torch.device | str) -> MotionDatabase:
        """A copy of the database on another device (built indexes are rebuilt on demand)."""
        return MotionDatabase(
            {name: raw.to(device) for name, raw in self._raw.items()},
            (self.clip_starts[1:] - self.clip_starts[:-1]).tolist(),
            self.fps,
            weights=self.weights,
            clip_names=self.clip_names,
            device=device,
        )

    # ------------------------------------------------------------- persistence
    def save(self, path: str | Path) -> None:
        """Write the database (raw features, clip ranges, weights, statistics) to a file.

        Args:
            path: Destination file (``torch.save`` format, loadable with
                ``weights_only=True``).
        """
        payload = {
            "format": _FORMAT,
            "fps": self.fps,
            "clip_lengths": (self.clip_starts[1:] - self.clip_starts[:-1]).cpu(),
            "clip_names": self.clip_names,
            "weights": dict(self.weights),
            "features": {name: raw.cpu() for name, raw in self._raw.items()},
        }
        torch.save(payload, Path(path))

    @classmethod
    def load(cls, path: str | Path, device: torch.device | str | None = None) -> MotionDatabase:
        """Read a database written by :meth:`save`.

        Args:
            path: File written by :meth:`save`.
            device: Where to put the tensors (default CPU).

        Returns:
            The database, with the same normalisation statistics as the saved one.

        Raises:
            MatchingError: If the file is not a saved database.
        """
        try:
            payload = torch.load(Path(path), map_location="cpu", weights_only=True)
        except (OSError, RuntimeError, EOFError) as exc:
            raise MatchingError(f"path: cannot read a database from {path} ({exc})") from exc
        if not isinstance(payload, dict) or payload.get("format") != _FORMAT:
            raise MatchingError(f"path: {path} is not a saved MotionDatabase")
        return cls(
            payload["features"],
            payload["clip_lengths"].tolist(),
            payload["fps"],
            weights=payload["weights"],
            clip_names=payload["clip_names"],
            device=device,
        )

    def __repr__(self) -> str:
        groups = ", ".join(f"{name}:{dim}" for name, dim in self.dims.items())
        return (
            f"MotionDatabase(frames={self.num_frames}, clips={self.num_clips}, fps={self.fps:g}, "
            f"groups=[{groups}], device={self.device})"
        )
