r"""The amplitude codebook shared by every dataset's VQ-PAE, and its re-initialisation.

Quantisation (Sec. 3.2): the raw amplitude $\tilde A$ snaps to its nearest
entry $A$ (Euclidean), the gradient passes straight through to $\tilde A$, and
the loss is the codebook term $\|sg(\tilde A) - A\|^2$ plus $\beta$ times the
commitment term $\|\tilde A - sg(A)\|^2$ (means over the batch, as the authors'
code; $\beta = 0.25$). Entries start uniform in $[-1/K, 1/K]$.

Re-initialisation (Sec. 3.3, Eqs. 5-8; Zheng & Vedaldi 2023), every training
step before the optimiser step, for every dataset $k$ that produced amplitudes:

* usage EMA $N_{k,i} \leftarrow \gamma N_{k,i} + (1 - \gamma)\, n_{k,i} / N_k$ ($\gamma = 0.99$);
* a target $Z_{k,i}$ drawn among the step's raw amplitudes of dataset $k$ with
  $P(Z_{k,i} = \tilde A_j) \propto \exp(-\|A_i - \tilde A_j\|)$ (Eq. 6; the
  authors' code uses the squared distance: ``squared_distance=True``);
* $\alpha_{k,i} = \exp(-N_{k,i} K \cdot 10 / (1 - \gamma) - \epsilon)$, $\epsilon = 10^{-3}$
  (the authors' code and Zheng & Vedaldi have the factor $K$ that the
  paper's Eq. 7 leaves out);
* $A_i \leftarrow \operatorname{mean}_k\, [(1 - \alpha_{k,i}) A_i + \alpha_{k,i} Z_{k,i}]$.

Under DDP the counts are summed and the raw amplitudes gathered over ranks, so
every rank updates the same usage EMA; rank 0 draws the targets with its seeded
generator and broadcasts the new codebook, so every rank holds the same one.
"""

from __future__ import annotations

import torch
import torch.distributed as dist
from torch import Tensor, nn

from skelagnostic.errors import SkelagnosticError

__all__ = ["SharedCodebook", "reinit_alpha", "reinit_probabilities", "reinit_update"]


def reinit_alpha(usage: Tensor, num_codes: int, decay: float = 0.99, eps: float = 1e-3) -> Tensor:
    """Interpolation weights ``alpha_i = exp(-N_i * K * 10 / (1 - decay) - eps)`` (Eq. 7).

    Args:
        usage: ``[K]`` (or ``[D, K]``) usage EMA ``N_i``.
        num_codes: ``K``.
        decay: ``gamma``.
        eps: ``epsilon``.

    Returns:
        Same shape as ``usage``; 1 - eps-ish for unused entries, ~0 for used ones.

    Example:
        >>> round(float(reinit_alpha(torch.tensor(0.0), 32)), 6)
        0.999
    """
    return torch.exp(-usage * num_codes * 10.0 / (1.0 - decay) - eps)


def reinit_probabilities(codebook: Tensor, raw: Tensor, squared_distance: bool = False) -> Tensor:
    """``P(Z_i = raw_j)`` proportional to ``exp(-||codebook_i - raw_j||)`` (Eq. 6).

    Args:
        codebook: ``[K, D]`` entries.
        raw: ``[N, D]`` raw amplitudes of this step.
        squared_distance: Use the squared distance (the authors' code).

    Returns:
        ``[K, N]``, rows summing to 1.
    """
    dist_ = torch.cdist(codebook.detach().double(), raw.detach().double())
    if squared_distance:
        dist_ = dist_.square()
    return torch.softmax(-dist_, dim=1).to(codebook.dtype)


def reinit_update(
    codebook: Tensor,
    usages: list[Tensor],
    raws: list[Tensor],
    generator: torch.Generator | None = None,
    decay: float = 0.99,
    eps: float = 1e-3,
    squared_distance: bool = False,
) -> Tensor:
    """The re-initialised codebook: the mean over datasets of Eq. 8.

    Args:
        codebook: ``[K, D]`` current entries.
        usages: Per dataset, the ``[K]`` usage EMA *after* this step's update.
        raws: Per dataset, the ``[N_k, D]`` raw amplitudes of this step.
        generator: Random generator (CPU) for drawing the targets.
        decay: ``gamma`` of the EMA.
        eps: ``epsilon`` of Eq. 7.
        squared_distance: See :func:`reinit_probabilities`.

    Returns:
        ``[K, D]`` new entries.
    """
    num_codes = codebook.shape[0]
    updates = []
    for usage, raw in zip(usages, raws, strict=True):
        probs = reinit_probabilities(codebook, raw, squared_distance)
        pick = torch.multinomial(probs.cpu().double(), 1, generator=generator).view(-1)
        target = raw.detach()[pick.to(raw.device)].to(codebook.dtype)
        alpha = reinit_alpha(usage, num_codes, decay, eps).to(codebook).unsqueeze(1)
        updates.append((1 - alpha) * codebook.detach() + alpha * target)
    return torch.stack(updates).mean(0)


def _distributed() -> bool:
    return dist.is_available() and dist.is_initialized() and dist.get_world_size() > 1


def _gather_rows(x: Tensor) -> Tensor:
    """Concatenate ``[n_r, D]`` tensors of every rank (``n_r`` may differ)."""
    n = torch.tensor([x.shape[0]], device=x.device)
    sizes = [torch.zeros_like(n) for _ in range(dist.get_world_size())]
    dist.all_gather(sizes, n)
    longest = int(max(int(s) for s in sizes))
    padded = torch.zeros(longest, *x.shape[1:], dtype=x.dtype, device=x.device)
    padded[: x.shape[0]] = x
    parts = [torch.zeros_like(padded) for _ in sizes]
    dist.all_gather(parts, padded)
    return torch.cat([p[: int(s)] for p, s in zip(parts, sizes, strict=True)])


class SharedCodebook(nn.Module):
    """The codebook ``A`` of ``K`` amplitudes shared by all VQ-PAEs, with re-initialisation.

    Args:
        num_codes: ``K`` (32 human-dog, 64 stylized).
        dim: ``2d``, size of an amplitude.
        num_datasets: Number of datasets (VQ-PAEs) sharing it.
        beta: Commitment weight (0.25).
        decay: ``gamma`` of the usage EMA (0.99).
        eps: ``epsilon`` of Eq. 7 (1e-3).
        reinit: Re-initialise every training step (``False``: the paper's ablation).
        squared_distance: Sample targets with the squared distance (authors' code).
        seed: Seed of the target-drawing generator.

    Raises:
        SkelagnosticError: A size is not positive or ``decay`` is not in (0, 1).

    Example:
        >>> book = SharedCodebook(num_codes=4, dim=2, num_datasets=1)
        >>> raw = torch.randn(8, 2, requires_grad=True)
        >>> amp, codes, loss = book.quantize(raw)
        >>> amp.shape, codes.shape, bool(torch.allclose(amp, book.weight[codes], atol=1e-7))
        (torch.Size([8, 2]), torch.Size([8]), True)
    """

    usage: Tensor

    def __init__(
        self,
        num_codes: int,
        dim: int,
        num_datasets: int = 1,
        beta: float = 0.25,
        decay: float = 0.99,
        eps: float = 1e-3,
        reinit: bool = True,
        squared_distance: bool = False,
        seed: int = 0,
    ) -> None:
        super().__init__()
        for arg, value in (("num_codes", num_codes), ("dim", dim), ("num_datasets", num_datasets)):
            if value <= 0:
                raise SkelagnosticError(f"SharedCodebook: {arg} must be positive, got {value}")
        if not 0 < decay < 1:
            raise SkelagnosticError(f"SharedCodebook: decay must be in (0, 1), got {decay}")
        self.num_codes, self.dim, self.num_datasets = num_codes, dim, num_datasets
        self.beta, self.decay, self.eps = beta, decay, eps
        self.reinit, self.squared_distance = reinit, squared_distance
        self.weight = nn.Parameter(
            torch.empty(num_codes, dim).uniform_(-1 / num_codes, 1 / num_codes)
        )
        self.register_buffer("usage", torch.zeros(num_datasets, num_codes))
        self.generator = torch.Generator().manual_seed(seed)
        self._pending: dict[int, tuple[Tensor, Tensor]] = {}

    def nearest(self, raw: Tensor) -> Tensor:
        """``[..., 2d]`` raw amplitudes -> ``[...]`` index of the nearest entry (Euclidean)."""
        flat = raw.detach().reshape(-1, self.dim)
        d2 = (
            flat.square().sum(1, keepdim=True)
            - 2 * flat @ self.weight.detach().t()
            + self.weight.detach().square().sum(1)
        )
        return d2.argmin(dim=1).view(raw.shape[:-1])

    def quantize(self, raw: Tensor, dataset: int | None = None) -> tuple[Tensor, Tensor, Tensor]:
        """Vector-quantise ``raw [B, 2d]``.

        Args:
            raw: Raw amplitudes ``A~``.
            dataset: Index of the dataset they come from; in training mode with
                re-initialisation on, they are kept for the next :meth:`reinitialize`.

        Returns:
            ``(A with straight-through gradient [B, 2d], codes [B], vq loss)``.
        """
        if raw.shape[-1] != self.dim:
            raise SkelagnosticError(
                f"SharedCodebook: raw amplitudes must end in {self.dim}, got {list(raw.shape)}"
            )
        codes = self.nearest(raw)
        quantized = self.weight[codes]
        loss = (quantized - raw.detach()).square().mean() + self.beta * (
            raw - quantized.detach()
        ).square().mean()
        if self.training and self.reinit and dataset is not None:
            if not 0 <= dataset < self.num_datasets:
                raise SkelagnosticError(
                    f"SharedCodebook: dataset must be in [0, {self.num_datasets}), got {dataset}"
                )
            prev = self._pending.get(dataset)
            flat, flat_codes = raw.detach().reshape(-1, self.dim), codes.reshape(-1)
            if prev is not None:
                flat, flat_codes = torch.cat([prev[0], flat]), torch.cat([prev[1], flat_codes])
            self._pending[dataset] = (flat, flat_codes)
        return raw + (quantized - raw).detach(), codes, loss

    def quantizer(self, dataset: int) -> _BoundQuantizer:
        """``quantize`` bound to ``dataset`` (the callable a :class:`~.model.VQPAE` takes)."""
        return _BoundQuantizer(self, dataset)

    @torch.no_grad()
    def reinitialize(self) -> bool:
        """Apply the step's re-initialisation (Eqs. 5-8) and clear the kept amplitudes.

        Only datasets that produced amplitudes since the last call take part.
        Under DDP this is a collective call: every rank must make it.

        Returns:
            Whether the codebook was updated.
        """
        pending, self._pending = self._pending, {}
        if not self.reinit:
            return False
        ddp = _distributed()
        datasets = sorted(pending)
        if ddp:  # the same datasets on every rank (ranks may lack some in a step)
            flags = torch.zeros(self.num_datasets, device=self.weight.device)
            flags[datasets] = 1.0
            dist.all_reduce(flags)
            datasets = [int(i) for i in torch.nonzero(flags).view(-1)]
        if not datasets:
            return False
        usages, raws = [], []
        for k in datasets:
            empty = (
                self.weight.new_zeros(0, self.dim),
                torch.zeros(0, dtype=torch.long, device=self.weight.device),
            )
            raw, codes = pending.get(k, empty)
            counts = torch.bincount(codes, minlength=self.num_codes).to(self.usage)
            total = counts.new_tensor(float(codes.numel()))
            if ddp:
                dist.all_reduce(counts)
                dist.all_reduce(total)
                raw = _gather_rows(raw.to(self.weight))
            self.usage[k].mul_(self.decay).add_(counts / total.clamp_min(1.0), alpha=1 - self.decay)
            usages.append(self.usage[k].clone())
            raws.append(raw)
        new = reinit_update(
            self.weight, usages, raws, self.generator, self.decay, self.eps, self.squared_distance
        )
        if ddp:
            dist.broadcast(new, src=0)
        self.weight.data.copy_(new)
        return True


class _BoundQuantizer:
    """``SharedCodebook.quantize`` with a fixed dataset index."""

    def __init__(self, book: SharedCodebook, dataset: int) -> None:
        self.book, self.dataset = book, dataset

    def __call__(self, raw: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        return self.book.quantize(raw, self.dataset)
