"""Candidate windows of a :class:`MotionDatabase` and the exact search over them.

A *window* starts at database frame ``k`` and covers ``length[k]`` frames of one
clip (one period ``t(k)`` for frequency-scaled matching, ``T0`` frames for
classical matching). Its control features are linearly resampled to ``L``
samples: sample ``s`` sits at frame ``k + s * length / L`` (integer arithmetic,
so the positions are exact). The frame ``k + length`` (where replay would
continue) must lie in the same clip, so no window crosses a clip boundary.

The cost of window ``k`` for a query window ``q`` of ``t_q`` frames is (Eq. 9 of
WalkTheDog)::

    c(q, k) = ||P_q - Q_k||^2 + lambda_pose ||J_start - J_k||^2 + lambda_period (t_q - t_k)^2

with ``P_q`` and ``Q_k`` the resampled ``[L, D]`` windows and ``J`` the pose
descriptor at the window's first frame.

The exact search never materialises the ``[W, L * D]`` window matrix. At build
time every window is projected on a ``basis_size``-dimensional orthonormal basis
``V`` (principal directions of a sample of windows); the projection ``B_k`` and
the norm ``rho_k`` of the residual are stored. Because ``V`` is orthonormal,

    ||P - Q_k||^2 >= ||b - B_k||^2 + (rho_q - rho_k)^2,

so a lower bound of every cost (with the pose and period terms, which are
exact) is one ``[W, r + Dj + 1]`` matrix-vector product and a table look-up,
minus a safety margin that covers float32 rounding. The exact cost (float64,
recomputed from the per-frame features) is then evaluated only for windows
whose bound does not exceed the best exact cost among the smallest bounds. The
result is the window the naive scan returns, ties broken by the lowest window
(database frame) index in both. Memory per query is a few scalars per window,
never a ``[W, L * D]`` temporary.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import torch

from skelagnostic.matching._errors import MatchingError

if TYPE_CHECKING:  # annotations only: the database imports this module for its index
    from skelagnostic.matching.database import MotionDatabase

#: Relative safety margin subtracted from the float32 lower bound (about 10x the
#: worst-case rounding of a float32 dot product of a few dozen terms).
_LB_MARGIN = 3e-5
#: Rows of the window table per lower-bound matrix product.
_LB_CHUNK = 65536
#: Windows resampled and projected at a time while building (cache-sized).
_BUILD_CHUNK = 2048
#: Windows per exact (float64) cost evaluation.
_EXACT_CHUNK = 4096
#: Upper bound, in bytes, of the per-batch lower-bound matrix.
_LB_BUDGET = 64 * 2**20
#: Windows sampled to fit the projection basis.
_BASIS_SAMPLE = 8192
#: Phase (in cycles) by which a running sum may fall short of a whole cycle.
_CYCLE_TOLERANCE = 1e-9
#: Candidates evaluated exactly before the bound is tightened.
_FIRST_CANDIDATES = 32


def sample_frames(
    values: torch.Tensor,
    start: torch.Tensor,
    length: torch.Tensor,
    samples: int,
    count: int,
    last: torch.Tensor,
) -> torch.Tensor:
    """Linearly resample windows of per-frame values.

    Sample ``s`` of a window sits at frame ``start + s * length / samples``; the two
    neighbouring frames are clamped to ``last`` (the input is padded with its last
    frame). Positions are computed with integers, so equal inputs give bit-equal
    outputs however the windows are batched.

    Args:
        values: ``[N, D]`` per-frame values.
        start: ``[n]`` int64 first frame of every window.
        length: ``[n]`` int64 frames covered by every window.
        samples: Number of samples one whole window is resampled to.
        count: Number of samples to return (``samples`` for the whole window; one
            more gives the frame where replay would continue).
        last: ``[n]`` int64 highest frame index a window may read.

    Returns:
        ``[n, count, D]`` float64 resampled values.
    """
    steps = torch.arange(count, device=values.device, dtype=torch.int64)
    numer = steps[None, :] * length[:, None]
    lo = start[:, None] + torch.div(numer, samples, rounding_mode="floor")
    frac = (numer % samples).to(torch.float64) / samples
    cap = last[:, None]
    shape = (start.numel(), count, values.shape[1])
    a = values.index_select(0, torch.minimum(lo, cap).reshape(-1)).view(shape).double()
    b = values.index_select(0, torch.minimum(lo + 1, cap).reshape(-1)).view(shape).double()
    return torch.lerp(a, b, frac[..., None])


def cycle_lengths(
    frequency: torch.Tensor, fps: float, ends: torch.Tensor | None = None
) -> torch.Tensor:
    """Period ``t(i)`` in frames of every frame from per-frame frequencies.

    ``t(i)`` is the number of frames ``j >= 1`` such that the phase advanced over
    frames ``i .. i + j - 1`` reaches one cycle: ``sum f_k / fps >= 1`` (so a steady
    1 Hz signal at 30 fps has ``t = 30``). WalkTheDog writes the sum up to ``i + j``;
    counting the ``j`` frames of the window instead keeps ``t`` equal to the
    period.

    Args:
        frequency: ``[N]`` non-negative frequencies in Hz.
        fps: Frame rate.
        ends: Optional ``[N]`` int64 index one past the last frame of each frame's
            clip. When given, a cycle must finish with its continuation frame
            ``i + t(i)`` inside the clip, else ``t(i) = 0`` (no window). When
            omitted (a query), a cycle that runs past the end is extrapolated
            with the last frame's frequency.

    Returns:
        ``[N]`` int64 periods (0 where no complete window exists).

    Raises:
        MatchingError: If a frequency is negative, or a query cycle can never
            complete because the frequency is zero at the end.
    """
    f = frequency.reshape(-1).double()
    if bool((f < 0).any()):
        raise MatchingError("frequency: frequencies must be >= 0 Hz")
    n = f.numel()
    cumulative = torch.zeros(n + 1, dtype=torch.float64, device=f.device)
    cumulative[1:] = torch.cumsum(f / fps, 0)
    # A 1e-9 cycle tolerance keeps exact periods (2 Hz at 30 fps = 15 frames) from
    # gaining a frame through rounding of the running sum.
    stop = torch.searchsorted(cumulative, cumulative[:-1] + (1.0 - _CYCLE_TOLERANCE))
    frames = torch.arange(n, device=f.device)
    periods = stop - frames
    if ends is not None:
        return torch.where(stop <= ends - 1, periods, torch.zeros_like(periods))
    open_ = stop > n
    if bool(open_.any()):
        if float(f[-1]) <= 0:
            first = int(open_.nonzero()[0, 0])
            raise MatchingError(
                f"frequency: the cycle starting at query frame {first} never completes "
                "(zero frequency at the end of the query)"
            )
        missing = 1.0 - _CYCLE_TOLERANCE - (cumulative[n] - cumulative[:-1][open_])
        extra = torch.ceil(missing * fps / f[-1]).to(torch.int64).clamp_min(1)
        periods[open_] = n - frames[open_] + extra
    return periods


def _check_build_arguments(
    database: MotionDatabase,
    control: Sequence[str],
    pose: str | None,
    frequency: str | None,
    length: int | None,
    basis_size: int,
) -> None:
    """Raise :class:`MatchingError` on the arguments :meth:`WindowIndex.build` refuses."""
    if (frequency is None) == (length is None):
        raise MatchingError("frequency/length: give exactly one of them")
    if len(control) == 0:
        raise MatchingError("control: at least one control feature group is needed")
    for name in (*control, *([pose] if pose else []), *([frequency] if frequency else [])):
        if name not in database.groups:
            raise MatchingError(
                f"group: unknown feature group {name!r}; the database has {database.groups}"
            )
    if basis_size < 1:
        raise MatchingError(f"basis_size: must be >= 1, got {basis_size}")


def _window_lengths(
    database: MotionDatabase, frequency: str | None, length: int | None
) -> tuple[torch.Tensor, torch.Tensor, int]:
    """The window starting at every database frame: one period of ``frequency``, or ``length``.

    Returns:
        ``[N]`` frames covered by the window starting at each frame, ``[N]`` bool
        whether that window fits in its clip, and the default samples per window.

    Raises:
        MatchingError: ``frequency`` has more than one channel, or ``length`` < 1.
    """
    frames = torch.arange(database.num_frames, device=database.device)
    ends = database.clip_end_of(frames)
    if frequency is not None:
        if database.dims[frequency] != 1:
            raise MatchingError(
                f"frequency: group {frequency!r} must have 1 channel, "
                f"has {database.dims[frequency]}"
            )
        per_frame = cycle_lengths(database.raw(frequency)[:, 0], database.fps, ends)
        return per_frame, per_frame > 0, max(1, round(database.fps))
    fixed = int(length or 0)
    if fixed < 1:
        raise MatchingError(f"length: must be >= 1 frame, got {length}")
    per_frame = torch.full_like(frames, fixed)
    return per_frame, frames + per_frame <= ends - 1, fixed


def _projection_basis(
    windows: Callable[[torch.Tensor], torch.Tensor],
    count: int,
    dim: int,
    basis_size: int,
    device: torch.device,
) -> torch.Tensor:
    """``[dim, r]`` float64 orthonormal basis of the lower bound (``r = min(basis_size, dim)``).

    Args:
        windows: Resampled windows ``[len(sel), dim]`` of the window indices ``sel``.
        count: Number of windows.
        dim: Dimension of a resampled window.
        basis_size: Requested rank.
        device: Device of the database.
    """
    rank = min(basis_size, dim)
    if rank == dim:
        return torch.eye(dim, dtype=torch.float64, device=device)
    # principal directions of the (uncentred: the features are normalised to
    # zero mean) windows; any orthonormal basis gives a valid bound
    pick = torch.unique(torch.linspace(0, count - 1, min(count, _BASIS_SAMPLE), device=device))
    sample = windows(pick.long())
    _, vectors = torch.linalg.eigh(sample.T @ sample)
    return vectors[:, -rank:].flip(1).contiguous()


def _window_table(
    windows: Callable[[torch.Tensor], torch.Tensor],
    basis: torch.Tensor,
    starts: torch.Tensor,
    pose_values: torch.Tensor | None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """The rows ``[B_k, J_k, rho_k]`` of every window and their squared norms, chunk by chunk.

    Returns:
        ``[W, r + Dj + 1]`` float32 table and ``[3, W]`` float32 squared norms
        (projection, start pose, residual).
    """
    count, rank, device = starts.numel(), basis.shape[1], starts.device
    pose_dims = pose_values.shape[1] if pose_values is not None else 0
    table = torch.empty(count, rank + pose_dims + 1, dtype=torch.float32, device=device)
    norms = torch.empty(3, count, dtype=torch.float32, device=device)
    for lo in range(0, count, _BUILD_CHUNK):
        hi = min(count, lo + _BUILD_CHUNK)
        values = windows(torch.arange(lo, hi, device=device))
        coords = values @ basis
        resid = _residual_norm(values, coords)
        table[lo:hi, :rank] = coords.float()
        table[lo:hi, -1] = resid.float()
        norms[0, lo:hi] = coords.square().sum(1).float()
        norms[2, lo:hi] = resid.square().float()
        if pose_values is not None:
            pose_start = pose_values[starts[lo:hi]]
            table[lo:hi, rank:-1] = pose_start
            norms[1, lo:hi] = pose_start.double().square().sum(1).float()
        else:
            norms[1, lo:hi] = 0.0
    return table, norms


@dataclass
class WindowIndex:
    """Exact nearest-window search over the candidate windows of a database.

    Build it with :meth:`build` (or :meth:`MotionDatabase.window_index`, which
    caches it). All tensors live on the database device.

    Attributes:
        starts: ``[W]`` int64 first database frame of every window, ascending.
        lengths: ``[W]`` int64 frames covered by every window (``t(k)`` or ``T0``).
        samples: Samples ``L`` every window is resampled to.
        control: ``[N, Dc]`` normalised control features of the database.
        pose: ``[N, Dj]`` normalised pose descriptors, or None.
        basis: ``[L * Dc, r]`` float64 orthonormal projection basis.
        table: ``[W, r + Dj + 1]`` float32 rows ``[B_k, J_k, rho_k]``: projection,
            start pose descriptor and residual norm of every window.
        proj_sq: ``[W]`` float32 ``||B_k||^2``.
        pose_sq: ``[W]`` float32 ``||J_k||^2``.
        resid_sq: ``[W]`` float32 ``rho_k^2``.
        build_seconds: Wall time spent building the index.
    """

    starts: torch.Tensor
    lengths: torch.Tensor
    samples: int
    control: torch.Tensor
    pose: torch.Tensor | None
    basis: torch.Tensor
    table: torch.Tensor
    proj_sq: torch.Tensor
    pose_sq: torch.Tensor
    resid_sq: torch.Tensor
    build_seconds: float
    _window_terms: dict[float, torch.Tensor] = field(default_factory=dict, repr=False)

    @classmethod
    def build(
        cls,
        database: MotionDatabase,
        control: Sequence[str],
        pose: str | None = None,
        *,
        frequency: str | None = None,
        length: int | None = None,
        samples: int | None = None,
        basis_size: int = 32,
    ) -> WindowIndex:
        """Enumerate the valid windows of a database and precompute their projections.

        Args:
            database: The database.
            control: Groups compared over the window.
            pose: Group compared at the window's first frame, or None.
            frequency: 1-channel group of frequencies (Hz): windows of one period.
            length: Fixed window length ``T0`` in frames (classical matching).
            samples: Samples per window (default ``round(fps)`` with ``frequency``,
                ``length`` otherwise).
            basis_size: Dimension of the projection used for the lower bound.

        Returns:
            The index.

        Raises:
            MatchingError: On unknown groups, both or neither of ``frequency`` and
                ``length``, non-positive sizes, or when no window fits in any clip.
        """
        started = time.perf_counter()
        _check_build_arguments(database, control, pose, frequency, length, basis_size)
        per_frame, valid, default_samples = _window_lengths(database, frequency, length)
        samples = default_samples if samples is None else int(samples)
        if samples < 1:
            raise MatchingError(f"samples: must be >= 1, got {samples}")
        starts = valid.nonzero()[:, 0]
        if starts.numel() == 0:
            raise MatchingError(
                "database: no candidate window fits in any clip (clips too short for the "
                "window length or the frequencies' periods)"
            )
        lengths = per_frame[starts]
        if len(control) == 1:
            control_values = database.normalized(control[0])
        else:
            control_values = torch.cat([database.normalized(g) for g in control], dim=1)
        pose_values = database.normalized(pose) if pose is not None else None

        def windows(sel: torch.Tensor) -> torch.Tensor:
            s, w = starts[sel], lengths[sel]
            out = sample_frames(control_values, s, w, samples, samples, s + w)
            return out.reshape(sel.numel(), -1)

        dim = samples * control_values.shape[1]
        basis = _projection_basis(windows, starts.numel(), dim, basis_size, database.device)
        table, norms = _window_table(windows, basis, starts, pose_values)
        return cls(
            starts=starts,
            lengths=lengths,
            samples=samples,
            control=control_values,
            pose=pose_values,
            basis=basis,
            table=table,
            proj_sq=norms[0],
            pose_sq=norms[1],
            resid_sq=norms[2],
            build_seconds=time.perf_counter() - started,
        )

    @property
    def num_windows(self) -> int:
        """Number of candidate windows."""
        return self.starts.numel()

    @property
    def nbytes(self) -> int:
        """Bytes held by the index's own tensors (the per-frame features are shared)."""
        own = [self.starts, self.lengths, self.basis, self.table, self.proj_sq]
        own += [self.pose_sq, self.resid_sq]
        return sum(t.numel() * t.element_size() for t in own)

    def next_pose(self, window: int) -> torch.Tensor | None:
        """Normalised pose descriptor where replay continues after ``window`` (``J_{k+t(k)}``)."""
        if self.pose is None:
            return None
        return self.pose[self.starts[window] + self.lengths[window]]

    # ----------------------------------------------------------------- costs
    def exact_costs(
        self,
        windows: torch.Tensor,
        query: torch.Tensor,
        query_length: int,
        start_pose: torch.Tensor | None,
        lambda_pose: float,
        lambda_period: float,
        max_period_ratio: float | None = None,
    ) -> torch.Tensor:
        """Float64 cost of some windows for one query (the reference definition).

        Args:
            windows: ``[n]`` int64 window ids.
            query: ``[L * Dc]`` float64 resampled, normalised query window.
            query_length: Query window length ``t_q`` in frames.
            start_pose: ``[Dj]`` float64 normalised start pose descriptor, or None (no
                pose term).
            lambda_pose: Weight of the pose term.
            lambda_period: Weight of the period term.
            max_period_ratio: If set, windows whose length ratio to ``t_q`` exceeds it
                (either way) cost ``inf``.

        Returns:
            ``[n]`` float64 costs.
        """
        out = torch.empty(windows.numel(), dtype=torch.float64, device=windows.device)
        for lo in range(0, windows.numel(), _EXACT_CHUNK):
            ids = windows[lo : lo + _EXACT_CHUNK]
            s, w = self.starts[ids], self.lengths[ids]
            resampled = sample_frames(self.control, s, w, self.samples, self.samples, s + w)
            cost = (resampled.reshape(ids.numel(), -1) - query).square().sum(1)
            if start_pose is not None and self.pose is not None and lambda_pose != 0:
                cost += lambda_pose * (self.pose[s].double() - start_pose).square().sum(1)
            cost += lambda_period * (w - query_length).double().square()
            if max_period_ratio is not None:
                cost[_ratio_exceeded(w, query_length, max_period_ratio)] = math.inf
            out[lo : lo + ids.numel()] = cost
        return out

    def _window_term(self, lambda_pose: float) -> torch.Tensor:
        """``(1 - m) (||B_k||^2 + lambda_pose ||J_k||^2 + rho_k^2)``, cached per weight."""
        if lambda_pose not in self._window_terms:
            total = self.proj_sq.double() + lambda_pose * self.pose_sq.double()
            total += self.resid_sq.double()
            self._window_terms[lambda_pose] = ((1 - _LB_MARGIN) * total).float()
        return self._window_terms[lambda_pose]

    def _shifted_bounds(
        self,
        queries: torch.Tensor,
        query_lengths: torch.Tensor,
        start_pose: torch.Tensor | None,
        lambda_pose: float,
        lambda_period: float,
        max_period_ratio: float | None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        # With b = V^T P, r = the residual norm, m the margin:
        #   ||b - B_k||^2 + lambda_pose ||j - J_k||^2 + (r - rho_k)^2 + d_len
        #   - m (||b||^2 + ||B_k||^2 + lambda_pose (||j||^2 + ||J_k||^2) + r^2 + rho_k^2 + d_len)
        # = q_term + window_term_k - 2 [b, lambda_pose j, r] . [B_k, J_k, rho_k] + lut[t_k]
        # (one matrix product per chunk); the rounding of this float32 sum stays
        # well below the margin. Returned without q_term (a per-query constant).
        coords = queries @ self.basis
        q_resid = _residual_norm(queries, coords)
        use_pose = start_pose is not None and self.pose is not None and lambda_pose != 0
        weight = lambda_pose if use_pose else 0.0
        pose_dims = self.table.shape[1] - coords.shape[1] - 1
        pose_part: torch.Tensor
        if start_pose is not None and use_pose:
            pose_part = lambda_pose * start_pose
            pose_sq = lambda_pose * start_pose.square().sum(1)
        else:
            pose_part = coords.new_zeros(coords.shape[0], pose_dims)
            pose_sq = coords.new_zeros(coords.shape[0])
        q_vec = torch.cat([coords, pose_part, q_resid[:, None]], dim=1).float()
        q_term = (1 - _LB_MARGIN) * (coords.square().sum(1) + pose_sq + q_resid.square())
        longest = int(self.lengths.max())
        options = torch.arange(longest + 1, device=queries.device)
        delta = (query_lengths[:, None] - options[None, :]).double()
        lut = ((1 - _LB_MARGIN) * lambda_period * delta.square()).float()
        if max_period_ratio is not None:
            lut[_ratio_exceeded(options[None, :], query_lengths[:, None], max_period_ratio)] = (
                math.inf
            )
        window_term = self._window_term(weight)
        out = torch.empty(queries.shape[0], self.num_windows, device=queries.device)
        for lo in range(0, self.num_windows, _LB_CHUNK):
            hi = min(self.num_windows, lo + _LB_CHUNK)
            chunk = out[:, lo:hi]
            torch.addmm(window_term[lo:hi], q_vec, self.table[lo:hi].T, alpha=-2, out=chunk)
            chunk += lut[:, self.lengths[lo:hi]]
        return out, q_term

    def lower_bounds(
        self,
        queries: torch.Tensor,
        query_lengths: torch.Tensor,
        start_pose: torch.Tensor | None,
        lambda_pose: float,
        lambda_period: float,
        max_period_ratio: float | None = None,
    ) -> torch.Tensor:
        """Lower bounds of the costs of every window for a batch of queries.

        Args:
            queries: ``[B, L * Dc]`` float64 resampled, normalised query windows.
            query_lengths: ``[B]`` int64 query lengths.
            start_pose: ``[B, Dj]`` float64 start pose descriptors, or None.
            lambda_pose: Weight of the pose term.
            lambda_period: Weight of the period term.
            max_period_ratio: Optional period ratio cap (excluded windows get ``inf``).

        Returns:
            ``[B, W]`` float64 bounds, each at most the exact cost of that window.
        """
        shifted, q_term = self._shifted_bounds(
            queries, query_lengths, start_pose, lambda_pose, lambda_period, max_period_ratio
        )
        return shifted.double() + q_term[:, None]

    # ---------------------------------------------------------------- search
    def search(
        self,
        queries: torch.Tensor,
        query_lengths: torch.Tensor,
        start_pose: torch.Tensor | None = None,
        *,
        lambda_pose: float = 0.5,
        lambda_period: float = 1.0,
        max_period_ratio: float | None = None,
        method: str = "fast",
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Best window of every query (exact; ties go to the lowest window id).

        Args:
            queries: ``[B, L, Dc]`` (or ``[B, L * Dc]``) resampled, normalised queries.
            query_lengths: ``[B]`` query window lengths ``t_q`` in frames.
            start_pose: ``[B, Dj]`` normalised start pose descriptors, or None.
            lambda_pose: Weight of the pose term.
            lambda_period: Weight of the period term.
            max_period_ratio: Optional cap of ``max(t_q / t_k, t_k / t_q)``.
            method: ``"fast"`` (bounded search) or ``"naive"`` (exact cost of every
                window); both return the same windows.

        Returns:
            ``(windows [B] int64, costs [B] float64)``.

        Raises:
            MatchingError: On shape mismatches, an unknown method, or when no window
                satisfies ``max_period_ratio``.
        """
        if method not in ("fast", "naive"):
            raise MatchingError(f"method: expected 'fast' or 'naive', got {method!r}")
        queries, query_lengths, start_pose = self._checked_queries(
            queries, query_lengths, start_pose, max_period_ratio
        )
        device = self.starts.device
        batch = queries.shape[0]
        best = torch.empty(batch, dtype=torch.int64, device=device)
        costs = torch.empty(batch, dtype=torch.float64, device=device)
        group = max(1, _LB_BUDGET // (4 * self.num_windows))
        for b0 in range(0, batch, group):
            b1 = min(batch, b0 + group)
            poses = start_pose[b0:b1] if start_pose is not None else None
            shifted: tuple[torch.Tensor, torch.Tensor] | None = None
            if method == "fast":
                shifted = self._shifted_bounds(
                    queries[b0:b1],
                    query_lengths[b0:b1],
                    poses,
                    lambda_pose,
                    lambda_period,
                    max_period_ratio,
                )
            for b in range(b0, b1):
                args = (
                    queries[b],
                    int(query_lengths[b]),
                    start_pose[b] if start_pose is not None else None,
                    lambda_pose,
                    lambda_period,
                    max_period_ratio,
                )
                if shifted is None:
                    ids = torch.arange(self.num_windows, device=device)
                else:
                    ids = self._candidates(shifted[0][b - b0], float(shifted[1][b - b0]), args)
                cand = self.exact_costs(ids, *args)
                pick = int(torch.argmin(cand))
                if not math.isfinite(float(cand[pick])):
                    raise MatchingError(
                        f"max_period_ratio: no window has a period within {max_period_ratio}x "
                        f"of the query's {int(query_lengths[b])} frames"
                    )
                best[b] = ids[pick]
                costs[b] = cand[pick]
        return best, costs

    def _candidates(self, row: torch.Tensor, shift: float, args: tuple[Any, ...]) -> torch.Tensor:
        """The windows whose lower bound does not exceed the best exact cost of a first few.

        Args:
            row: ``[W]`` shifted lower bounds of one query (see :meth:`_shifted_bounds`).
            shift: The query's constant term ``q_term``.
            args: The query's arguments of :meth:`exact_costs` after the window ids.

        Returns:
            ``[C]`` int64 window ids that may hold the best window.
        """
        first = torch.topk(row, min(_FIRST_CANDIDATES, row.numel()), largest=False)
        best_first = float(self.exact_costs(first.indices, *args).min())
        # row + q_term <= best_first, with slack for rounding the threshold
        slack = 1e-6 * (abs(best_first) + abs(shift))
        return (row <= best_first - shift + slack).nonzero()[:, 0]

    def _checked_queries(
        self,
        queries: torch.Tensor,
        query_lengths: torch.Tensor,
        start_pose: torch.Tensor | None,
        max_period_ratio: float | None,
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
        """:meth:`search`'s inputs checked and moved to the index device.

        Returns:
            ``[B, L * Dc]`` float64 queries, ``[B]`` int64 lengths and ``[B, Dj]``
            float64 start poses (or None).

        Raises:
            MatchingError: On shape mismatches, non-finite values, lengths < 1 or a
                ``max_period_ratio`` < 1.
        """
        device = self.starts.device
        dim = self.samples * self.control.shape[1]
        queries = torch.as_tensor(queries, device=device).double()
        if queries.numel() == 0 or queries.numel() % dim:
            raise MatchingError(
                f"queries: expected [B, {self.samples}, {self.control.shape[1]}], "
                f"got {tuple(queries.shape)}"
            )
        queries = queries.reshape(-1, dim)
        if not bool(torch.isfinite(queries).all()):
            raise MatchingError("queries: hold NaN or inf")
        batch = queries.shape[0]
        query_lengths = torch.as_tensor(query_lengths, device=device, dtype=torch.int64).reshape(-1)
        if query_lengths.numel() != batch:
            raise MatchingError(
                f"query_lengths: {query_lengths.numel()} lengths for {batch} queries"
            )
        if bool((query_lengths < 1).any()):
            raise MatchingError("query_lengths: must be >= 1 frame")
        if start_pose is not None:
            if self.pose is None:
                raise MatchingError("start_pose: the index has no pose group")
            start_pose = torch.as_tensor(start_pose, device=device).double()
            start_pose = start_pose.reshape(batch, -1)
            if start_pose.shape[1] != self.pose.shape[1]:
                raise MatchingError(
                    f"start_pose: expected {self.pose.shape[1]} dims, got {start_pose.shape[1]}"
                )
            if not bool(torch.isfinite(start_pose).all()):
                raise MatchingError("start_pose: holds NaN or inf")
        if max_period_ratio is not None and not max_period_ratio >= 1:
            raise MatchingError(f"max_period_ratio: must be >= 1, got {max_period_ratio}")
        return queries, query_lengths, start_pose


def _residual_norm(values: torch.Tensor, coords: torch.Tensor) -> torch.Tensor:
    """``||x - V V^T x||`` from ``||x||^2 - ||V^T x||^2`` (float64; V orthonormal)."""
    return (values.square().sum(1) - coords.square().sum(1)).clamp_min(0).sqrt()


def _ratio_exceeded(
    window_length: torch.Tensor, query_length: torch.Tensor | int, ratio: float
) -> torch.Tensor:
    return (window_length > ratio * query_length) | (query_length > ratio * window_length)
