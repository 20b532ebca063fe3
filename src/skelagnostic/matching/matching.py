"""Classical and frequency-scaled motion matching (WalkTheDog, supplement Alg. 1 and Alg. 1).

Both algorithms walk along a query sequence of control features (phase-manifold
points, say), pick at every step the database window of lowest cost, replay it,
and continue with the pose descriptor where that window's replay would continue
as the next start pose. Classical matching replays fixed windows of ``T0``
frames; frequency-scaled matching queries once per period ``t(i)`` of the input,
compares windows of one period resampled to a common length, and time-warps the
chosen window to the query's period.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import torch

from skelagnostic.matching._errors import MatchingError
from skelagnostic.matching.database import ArrayLike, MotionDatabase, as_features
from skelagnostic.matching.inertialization import inertialize
from skelagnostic.matching.windows import WindowIndex, cycle_lengths, sample_frames


@dataclass(frozen=True)
class Segment:
    """One replayed database window.

    Attributes:
        clip: Clip index in the database.
        frame: First replayed frame, counted within the clip.
        length: Database frames replayed (``t(k)`` or ``T0``).
        start: First output frame.
        out_length: Output frames (``t(i)``; the last segment may be cut short by
            the end of the query).
        cost: Matching cost of the window.
    """

    clip: int
    frame: int
    length: int
    start: int
    out_length: int
    cost: float


@dataclass
class MatchResult:
    """Output of a motion-matching run.

    Attributes:
        segments: The chosen windows, in output order.
        features: Group name -> ``[T, D_g]`` assembled output in raw units (time
            warped and inertialized at every transition).
        source_frames: ``[T]`` float64 global database frame (fractional when time
            warped) each output frame was taken from, before inertialization.
        windows: ``[S]`` int64 window ids in the index (for inspection and tests).
    """

    segments: list[Segment]
    features: dict[str, torch.Tensor] = field(default_factory=dict)
    source_frames: torch.Tensor | None = None
    windows: torch.Tensor | None = None


def _query_control(
    database: MotionDatabase, query: Mapping[str, ArrayLike], control: Sequence[str]
) -> torch.Tensor:
    if not isinstance(query, Mapping):
        raise MatchingError("query: expected a mapping of feature group -> [T, D] features")
    parts = []
    frames = None
    for name in control:
        if name not in query:
            raise MatchingError(f"query: missing control group {name!r}")
        values = as_features(query[name], f"query[{name!r}]", database.device)
        if values.shape[1] != database.dims.get(name, -1):
            raise MatchingError(
                f"query[{name!r}]: has {values.shape[1]} dims, the database has "
                f"{database.dims.get(name)}"
            )
        if frames is not None and values.shape[0] != frames:
            raise MatchingError(f"query[{name!r}]: has {values.shape[0]} frames, expected {frames}")
        frames = values.shape[0]
        parts.append(database.normalize(name, values))
    return torch.cat(parts, dim=1)


def _start_pose(
    database: MotionDatabase, pose: str | None, initial_pose: ArrayLike | None
) -> torch.Tensor | None:
    if initial_pose is None or pose is None:
        return None
    values = as_features(
        torch.as_tensor(initial_pose).reshape(1, -1), "initial_pose", database.device
    )
    if values.shape[1] != database.dims[pose]:
        raise MatchingError(
            f"initial_pose: has {values.shape[1]} dims, group {pose!r} has {database.dims[pose]}"
        )
    return database.normalize(pose, values)[0].double()


def _run(
    database: MotionDatabase,
    index: WindowIndex,
    control: torch.Tensor,
    starts: torch.Tensor,
    lengths: torch.Tensor,
    start_pose: torch.Tensor | None,
    *,
    lambda_pose: float,
    lambda_period: float,
    max_period_ratio: float | None,
    output: Sequence[str] | None,
    halflife: float | None,
    search: str,
) -> MatchResult:
    total = control.shape[0]
    last = torch.full_like(starts, total - 1)
    queries = sample_frames(control, starts, lengths, index.samples, index.samples, last)
    queries = queries.reshape(starts.numel(), -1)
    chosen = torch.empty_like(starts)
    costs = torch.empty(starts.numel(), dtype=torch.float64)
    pose = start_pose
    for q in range(starts.numel()):
        ids, cost = index.search(
            queries[q : q + 1],
            lengths[q : q + 1],
            pose[None] if pose is not None else None,
            lambda_pose=lambda_pose,
            lambda_period=lambda_period,
            max_period_ratio=max_period_ratio,
            method=search,
        )
        chosen[q] = ids[0]
        costs[q] = cost[0]
        next_pose = index.next_pose(int(ids[0]))
        pose = next_pose.double() if next_pose is not None else None
    src_start = index.starts[chosen]
    src_length = index.lengths[chosen]
    out_length = torch.minimum(lengths, total - starts)
    clips, local = database.locate(src_start)
    segments = [
        Segment(
            clip=int(clips[q]),
            frame=int(local[q]),
            length=int(src_length[q]),
            start=int(starts[q]),
            out_length=int(out_length[q]),
            cost=float(costs[q]),
        )
        for q in range(starts.numel())
    ]
    groups = database.groups if output is None else list(output)
    clip_last = database.clip_end_of(src_start) - 1
    features: dict[str, torch.Tensor] = {}
    for name in groups:
        raw = database.raw(name)
        pieces, conts = [], []
        for q in range(starts.numel()):
            s, w, n = src_start[q : q + 1], src_length[q : q + 1], int(out_length[q])
            played = sample_frames(raw, s, w, int(lengths[q]), n + 2, clip_last[q : q + 1])[0]
            pieces.append(played[:n].float())
            conts.append(played[n:].float())
        if halflife is None:
            features[name] = torch.cat(pieces)
        else:
            features[name] = inertialize(pieces, conts, 1.0 / database.fps, halflife)
    source = [
        src_start[q].double()
        + torch.arange(int(out_length[q]), dtype=torch.float64, device=src_start.device)
        * src_length[q].double()
        / lengths[q].double()
        for q in range(starts.numel())
    ]
    return MatchResult(
        segments=segments,
        features=features,
        source_frames=torch.cat(source),
        windows=chosen,
    )


def _check_common(
    database: MotionDatabase,
    pose: str | None,
    output: Sequence[str] | None,
    halflife: float | None,
    search: str,
) -> None:
    if not isinstance(database, MotionDatabase):
        raise MatchingError(f"database: expected a MotionDatabase, got {type(database).__name__}")
    if pose is not None and pose not in database.groups:
        raise MatchingError(f"pose: unknown feature group {pose!r}; have {database.groups}")
    for name in output or ():
        if name not in database.groups:
            raise MatchingError(f"output: unknown feature group {name!r}; have {database.groups}")
    if halflife is not None and not halflife > 0:
        raise MatchingError(f"halflife: must be > 0 seconds (or None), got {halflife}")
    if search not in ("fast", "naive"):
        raise MatchingError(f"search: expected 'fast' or 'naive', got {search!r}")


def motion_matching(
    database: MotionDatabase,
    query: Mapping[str, ArrayLike],
    replay_length: int,
    *,
    control: Sequence[str] | str = "manifold",
    pose: str | None = "pose",
    lambda_pose: float = 0.5,
    initial_pose: ArrayLike | None = None,
    output: Sequence[str] | None = None,
    halflife: float | None = 0.1,
    search: str = "fast",
) -> MatchResult:
    """Classical motion matching with a fixed replay length (WalkTheDog supplement, Alg. 1).

    Starting at query frame ``i = 0``, every ``T0 = replay_length`` frames::

        k = argmin_k ||P[i:i+T0] - Q[k:k+T0]||^2 + lambda_pose ||J_start - J_k||^2
        output Y[k:k+T0];  i += T0;  J_start = J[k+T0]

    The query is padded with its last frame so the last window is whole; only the
    frames up to the query's end are output.

    Args:
        database: The frame database (raw features are normalised with its stats).
        query: Group -> ``[T, D_g]`` raw control features of the query sequence, at
            the database frame rate.
        replay_length: ``T0``, frames replayed after each match.
        control: Group(s) compared over the window (the phase manifold ``P``/``Q``).
        pose: Pose-descriptor group ``J`` compared at the window start, or None.
        lambda_pose: Weight ``lambda`` of the pose term (the paper gives no value;
            0.5, the frequency-scaled default, is used).
        initial_pose: Raw pose descriptor to start from; None drops the pose term for
            the first match.
        output: Groups to assemble into ``MatchResult.features`` (default: all).
        halflife: Inertialization halflife in seconds; None concatenates with hard cuts.
        search: ``"fast"`` (exact bounded search) or ``"naive"`` (scan every window).

    Returns:
        The chosen segments and the assembled output.

    Raises:
        MatchingError: On bad groups, shapes, NaN values or parameters.

    Examples:
        >>> import torch
        >>> from skelagnostic.matching import MotionDatabase, motion_matching
        >>> t = torch.arange(200.0)[:, None]
        >>> clip = {"manifold": torch.cat([t.sin(), t.cos()], 1), "pose": (0.3 * t).sin()}
        >>> db = MotionDatabase.from_clips([clip], fps=30)
        >>> result = motion_matching(db, {"manifold": clip["manifold"][40:100]}, 20)
        >>> [s.frame for s in result.segments]
        [40, 60, 80]
        >>> result.features["pose"].shape
        torch.Size([60, 1])
    """
    _check_common(database, pose, output, halflife, search)
    if not (isinstance(replay_length, int) and replay_length >= 1):
        raise MatchingError(f"replay_length: must be an integer >= 1, got {replay_length!r}")
    controls = (control,) if isinstance(control, str) else tuple(control)
    values = _query_control(database, query, controls)
    index = database.window_index(controls, pose, length=replay_length)
    starts = torch.arange(0, values.shape[0], replay_length, device=database.device)
    lengths = torch.full_like(starts, replay_length)
    return _run(
        database,
        index,
        values,
        starts,
        lengths,
        _start_pose(database, pose, initial_pose),
        lambda_pose=lambda_pose,
        lambda_period=0.0,
        max_period_ratio=None,
        output=output,
        halflife=halflife,
        search=search,
    )


def frequency_scaled_motion_matching(
    database: MotionDatabase,
    query: Mapping[str, ArrayLike],
    *,
    control: Sequence[str] | str = "manifold",
    pose: str | None = "pose",
    frequency: str = "frequency",
    lambda1: float = 0.5,
    lambda2: float = 1.0,
    samples: int | None = None,
    max_period_ratio: float | None = None,
    initial_pose: ArrayLike | None = None,
    output: Sequence[str] | None = None,
    halflife: float | None = 0.1,
    search: str = "fast",
) -> MatchResult:
    """Frequency-scaled motion matching (WalkTheDog Alg. 1 and Eq. 9).

    With ``t(i)`` the period in frames at frame ``i`` (from the frequencies, see
    :func:`~skelagnostic.matching.windows.cycle_lengths`), starting at ``i = 0``::

        k = argmin_k c(i, k)
        output Y[k:k+t(k)] linearly resampled to t(i) frames
        i += t(i);  J_start = J[k + t(k)]

        c(i, k) = d(P[i:i+t(i)], Q[k:k+t(k)]) + lambda1 ||J_start - J_k||^2
                  + lambda2 (t(i) - t(k))^2

    where ``d`` resamples both windows to ``samples`` samples (default
    ``round(fps)``, i.e. ``1 / dt``) and sums the squared differences. Periods are
    counted in frames. The last query window is completed by extrapolating the last
    frequency and padding the query with its last frame; only frames up to the
    query's end are output.

    Args:
        database: Frame database with the control, pose and frequency groups.
        query: Group -> ``[T, D_g]`` raw features of the query, at the database
            frame rate; must hold the control groups and the ``frequency`` group.
        control: Group(s) compared over the window (the phase manifold).
        pose: Pose-descriptor group, or None to drop the pose term.
        frequency: 1-channel group of frequencies in Hz (database and query).
        lambda1: Weight of the start-pose term (paper: 0.5).
        lambda2: Weight of the period term (paper: 1).
        samples: Common resampling length of the windows (default ``round(fps)``;
            the authors' code uses 60).
        max_period_ratio: Optional cap on ``max(t(i) / t(k), t(k) / t(i))`` (the
            authors' code caps frequency ratios at 2); None (the paper) allows any.
        initial_pose: Raw pose descriptor to start from; None drops the pose term
            for the first match.
        output: Groups to assemble into ``MatchResult.features`` (default: all).
        halflife: Inertialization halflife in seconds; None for hard cuts.
        search: ``"fast"`` (exact bounded search) or ``"naive"`` (scan every window).

    Returns:
        The chosen segments and the assembled, time-warped output.

    Raises:
        MatchingError: On bad groups, shapes, NaN or negative frequencies, or
            parameters.

    Examples:
        >>> import math, torch
        >>> from skelagnostic.matching import MotionDatabase, frequency_scaled_motion_matching
        >>> def clip(hz, frames):
        ...     phase = 2 * math.pi * hz * torch.arange(frames) / 30
        ...     return {"manifold": torch.stack([phase.sin(), phase.cos()], 1),
        ...             "frequency": torch.full((frames,), hz)}
        >>> db = MotionDatabase.from_clips([clip(1.0, 120), clip(2.0, 120)], fps=30)
        >>> query = clip(2.0, 45)
        >>> result = frequency_scaled_motion_matching(db, query, pose=None)
        >>> [(s.clip, s.length, s.out_length) for s in result.segments]
        [(1, 15, 15), (1, 15, 15), (1, 15, 15)]
    """
    _check_common(database, pose, output, halflife, search)
    if frequency not in database.groups:
        raise MatchingError(
            f"frequency: unknown feature group {frequency!r}; have {database.groups}"
        )
    controls = (control,) if isinstance(control, str) else tuple(control)
    values = _query_control(database, query, controls)
    if frequency not in query:
        raise MatchingError(f"query: missing frequency group {frequency!r}")
    freq = as_features(query[frequency], f"query[{frequency!r}]", database.device)
    if freq.shape != (values.shape[0], 1):
        raise MatchingError(
            f"query[{frequency!r}]: expected {values.shape[0]} frames x 1 channel, "
            f"got {tuple(freq.shape)}"
        )
    index = database.window_index(controls, pose, frequency=frequency, samples=samples)
    periods = cycle_lengths(freq[:, 0], database.fps)
    starts_list = []
    i = 0
    while i < values.shape[0]:
        starts_list.append(i)
        i += int(periods[i])
    starts = torch.tensor(starts_list, dtype=torch.int64, device=database.device)
    return _run(
        database,
        index,
        values,
        starts,
        periods[starts],
        _start_pose(database, pose, initial_pose),
        lambda_pose=lambda1,
        lambda_period=lambda2,
        max_period_ratio=max_period_ratio,
        output=output,
        halflife=halflife,
        search=search,
    )
