"""The VQ-PAE model: one VQ-PAE per dataset, one shared codebook, trained with Lightning.

Training step (Sec. 3.3, Eq. 4): for every dataset's batch, reconstruct the
window (MSE) and add ``lambda_vq`` times the codebook loss; the step's loss is
the mean over datasets (the authors' code). The optional average-pose MLP per
dataset (Sec. 5.2, Eq. 10) learns the root-local pose of every window frame
from its manifold point, alongside (``pose_mlp="detached"``: its gradient does
not reach the VQ-PAE, equivalent to the paper's separate training) or jointly
(``"joint"``: the authors' code, whose pose loss also trains the VQ-PAE).
The codebook is re-initialised in ``on_before_optimizer_step`` (after the
backward pass, before the optimiser step, as in the paper).

Optimiser (``model.optimizer``, ``model.scheduler``: config, see
:mod:`skelagnostic.aligners.optim`): AdamW (lr 1e-4, weight decay 1e-4) with the
authors' ``CyclicLRWithRestarts``
(:func:`~skelagnostic_vqpae.schedule.authors_restarts`: cosine cycles of 10
epochs doubling at each restart, an epoch is one pass over the smallest dataset,
a 1e-7 floor, normalised weight decay annealed with the rate), stepped per
batch; the pose MLPs keep a constant rate (``pose_lr`` 1e-3, no weight decay:
the authors' separate Adam).
:func:`~skelagnostic_vqpae.schedule.cosine_restarts` is PyTorch's
``CosineAnnealingWarmRestarts`` over the data module's epochs, on every group.

The defaults are the authors' training (``train_vq.py``);
:data:`~skelagnostic_vqpae.options.PLUS_OPTIONS` are skelagnostic's changes, enabled together
by ``experiment=vqpae_plus``.

Validation logs ``val/loss``, ``val/rec``, the manifold overlap of the
validation codes (``val/usage``, ``val/overlap``, ``val/overlap/<dataset>``),
the codebook usage per dataset (``val/codes/<dataset>``: number of codes used)
and, with a pose MLP, ``val/pose_mpjpe/<dataset>`` in metres at the pivot frames.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar

import torch
from lightning.pytorch.utilities import rank_zero_info
from torch import Tensor, nn

from skelagnostic.aligners import Aligner, Latent
from skelagnostic.aligners.export import ExportGraph
from skelagnostic.aligners.optim import OptimizerSpec, check_specs
from skelagnostic.core.motion import Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.core.units import UNITS, infer_units
from skelagnostic.errors import SkelagnosticError
from skelagnostic.metrics import ManifoldOverlap
from skelagnostic.representations import RootLocalVelocities, inverse_kinematics
from skelagnostic_vqpae.codebook import SharedCodebook
from skelagnostic_vqpae.features import authors_features
from skelagnostic_vqpae.graphs import export_graphs
from skelagnostic_vqpae.losses import phase_rate_loss, pivot_mpjpe
from skelagnostic_vqpae.model import (
    Character,
    PhaseParameters,
    phase_manifold,
)
from skelagnostic_vqpae.options import (
    AUTHORS_OPTIMIZER,
    AUTHORS_SCHEDULER,
    PHASE_RATE_GRADS,
    POSE_MODES,
    PREVIOUS_DEFAULTS,
    DatasetSpec,
)
from skelagnostic_vqpae.predictions import write_embeddings
from skelagnostic_vqpae.schedule import configure_optimizers

__all__ = ["VqpaeModel"]


class VqpaeModel(Aligner):
    """VQ-PAEs of several characters sharing one amplitude codebook (WalkTheDog).

    The model floor of the plugin: training, ``encode``/``decode`` and export. The
    public aligner, :class:`skelagnostic_vqpae.aligner.VqpaeAligner`, is this class with
    the fit summary and ``transfer``, whose work lives on higher floors (embedding,
    transfer, protocols); the lower floors take a ``VqpaeModel``.

    The networks are built from the data module in :meth:`setup` (or from
    ``datasets``, which checkpoints store), one per dataset.

    Args:
        latent: ``d``, latent / phase-manifold channels (10).
        num_codes: Codebook size ``K`` (32 human-dog, 64 stylized).
        kernel_size: Encoder/decoder kernel (23).
        freq_layers: Layers of the frequency MLP (7, the authors' ``--n_layers_fft``;
            the paper: 5).
        amp_layers: Layers of the amplitude MLP (5).
        decoder_centering: Temporal centering after the first decoder conv (default
            ``True``, the authors' code; the paper has ELU only).
        spectrum: Frequency-MLP input, ``"power"`` (default, the authors' raw power
            spectrum) or ``"normalized"``; see :class:`~skelagnostic_vqpae.model.VQPAE`.
        frequency_head: ``"mlp"`` (default, the paper) or ``"centroid_residual"``
            (the MLP corrects PAE's spectral centroid); see
            :class:`~skelagnostic_vqpae.model.VQPAE`. Checkpoints saved before this
            option existed load with ``"mlp"``.
        padding_mode: Padding of the encoder/decoder convolutions: ``"zeros"``
            (default, the authors' ``padding='same'``) or ``"replicate"``; see
            :class:`~skelagnostic_vqpae.model.VQPAE` and docs/reports/vqpae.md.
        phase_kernel: Kernel of the timing branch's convolution (23, the authors'
            code; the paper's Fig. 3: 1).
        freq_hidden_elu: ELU after every hidden LeakyReLU of the frequency MLP
            (default ``True``, the authors' code); see :class:`~skelagnostic_vqpae.model.VQPAE`.
        center_windows: Reconstruct each window's deviation from its temporal mean
            instead of the window itself (default ``False``: the window, the paper's
            and the authors' ``L_rec``); the manifold, a sum of sinusoids, cannot
            carry the mean except by a degenerate frequency near 0 (see
            docs/reports/vqpae.md).
        beta: Commitment weight (0.25).
        lambda_vq: Weight of the codebook loss (1).
        lambda_phase_rate: Weight of the phase-rate loss (default 0: off, as the
            paper and the authors; ``experiment=vqpae_plus`` sets 1): the L1 distance, in
            Hz, between the predicted frequency of a training window (and of its
            partner ``data.pair_seconds`` later) and the rate at which the
            predicted pivot phase advances from the one to the other, the phase
            difference detached. The paper trains the frequency through the
            reconstruction only; on our procedural gaits that left the frequency
            up to 46 % off while the phase advanced at the true rate
            (docs/reports/vqpae.md).
        phase_rate_grad: What the phase-rate loss trains: ``"network"`` (the
            encoder and the timing branch), ``"timing"`` (the timing branch only:
            its kernel-1 convolution and the frequency MLP; the shared latent is
            detached) or ``"head"`` (the frequency MLP only).
        reinit: Re-initialise the codebook every step (``False``: ablation).
        reinit_decay: ``gamma`` of the usage EMA (0.99).
        reinit_eps: ``epsilon`` of Eq. 7 (1e-3).
        reinit_squared_distance: Draw targets with the squared distance (default
            ``True``, the authors' code; the paper's Eq. 6 has the distance).
        seed: Seed of the re-initialisation generator.
        optimizer: ``model.optimizer``, a ``_partial_`` spec or a callable taking the
            parameter groups (:mod:`skelagnostic.aligners.optim`); the authors':
            AdamW, ``lr`` 1e-4, ``weight_decay`` 1e-4
            (:data:`~skelagnostic_vqpae.options.AUTHORS_OPTIMIZER`).
        scheduler: ``model.scheduler`` (``None``: constant); the authors'
            :func:`~skelagnostic_vqpae.schedule.authors_restarts` (``period`` 10
            epochs, ``mult`` 2), or
            :func:`~skelagnostic_vqpae.schedule.cosine_restarts`. Checkpoints
            saved without it resume with the cosine one.
        pose_mlp: ``"none"``, ``"detached"`` or ``"joint"`` (default: the authors'
            phase decoders train with the VQ-PAE; see the module docstring).
        pose_layers: Layers of the average-pose MLP (8).
        pose_lr: Learning rate of the pose MLPs (1e-3).
        datasets: Dataset name -> :data:`DatasetSpec` (filled in by :meth:`setup`).

    Raises:
        SkelagnosticError: An option is out of range.
    """

    capabilities: ClassVar[frozenset[str]] = frozenset({"encode", "decode", "phase", "quadruped"})

    def __init__(
        self,
        latent: int = 10,
        num_codes: int = 32,
        kernel_size: int = 23,
        freq_layers: int = 7,
        amp_layers: int = 5,
        decoder_centering: bool = True,
        spectrum: str = "power",
        padding_mode: str = "zeros",
        frequency_head: str = "mlp",
        phase_kernel: int = 23,
        freq_hidden_elu: bool = True,
        center_windows: bool = False,
        beta: float = 0.25,
        lambda_vq: float = 1.0,
        lambda_phase_rate: float = 0.0,
        phase_rate_grad: str = "network",
        reinit: bool = True,
        reinit_decay: float = 0.99,
        reinit_eps: float = 1e-3,
        reinit_squared_distance: bool = True,
        seed: int = 0,
        optimizer: OptimizerSpec = AUTHORS_OPTIMIZER,
        scheduler: OptimizerSpec | None = AUTHORS_SCHEDULER,
        pose_mlp: str = "joint",
        pose_layers: int = 8,
        pose_lr: float = 1e-3,
        datasets: Mapping[str, DatasetSpec] | None = None,
    ) -> None:
        super().__init__()
        if pose_mlp not in POSE_MODES:
            raise SkelagnosticError(f"model.pose_mlp must be one of {POSE_MODES}, got {pose_mlp!r}")
        if phase_rate_grad not in PHASE_RATE_GRADS:
            raise SkelagnosticError(
                f"model.phase_rate_grad must be one of {PHASE_RATE_GRADS}, got {phase_rate_grad!r}"
            )
        if not lambda_phase_rate >= 0:
            raise SkelagnosticError(
                f"model.lambda_phase_rate must be >= 0, got {lambda_phase_rate}"
            )
        for arg, value in (
            ("latent", latent),
            ("num_codes", num_codes),
        ):
            if value <= 0:
                raise SkelagnosticError(f"model.{arg} must be positive, got {value}")
        optimizer, scheduler = check_specs(optimizer, scheduler)
        self.save_hyperparameters()
        self.dataset_names: list[str] = []
        self.characters = nn.ModuleList()
        self.codebook: SharedCodebook | None = None
        self._metrics: dict[str, ManifoldOverlap] = {}  # not a submodule: rebuilt per epoch
        self._overlap_na_reported = False  # one character: said once per run
        #: Per dataset, the ``[K]`` code histogram of the last validation/test epoch.
        self.last_code_counts: dict[str, Tensor] = {}
        self._predictions: dict[str, list[dict[str, Tensor]]] = {}
        self.predictions_path: Path | None = None
        if datasets:
            self._build(datasets)

    # ------------------------------------------------------------------ building
    def _build(self, datasets: Mapping[str, DatasetSpec]) -> None:
        hp = self.hparams
        self.dataset_names = list(datasets)
        self.characters = nn.ModuleList(
            Character(
                spec,
                hp.latent,
                hp.pose_layers,
                kernel_size=hp.kernel_size,
                freq_layers=hp.freq_layers,
                amp_layers=hp.amp_layers,
                decoder_centering=hp.decoder_centering,
                spectrum=hp.spectrum,
                padding_mode=hp.padding_mode,
                frequency_head=hp.frequency_head,
                phase_kernel=hp.phase_kernel,
                freq_hidden_elu=hp.freq_hidden_elu,
            )
            for spec in datasets.values()
        )
        self.codebook = SharedCodebook(
            hp.num_codes,
            2 * hp.latent,
            len(datasets),
            hp.beta,
            hp.reinit_decay,
            hp.reinit_eps,
            hp.reinit,
            hp.reinit_squared_distance,
            hp.seed,
        )

    def configure_model(self) -> None:
        """Build the networks from the data module's datasets and copy its statistics.

        The data module is set up for the running stage first (:meth:`stage_datamodule`).
        """
        if self.codebook is not None:  # built already, or from a checkpoint's hyperparameters
            return
        dm = self.stage_datamodule()
        if dm is None:
            self._require_built()  # no data module to build from: say what to pass
        specs = {
            name: {
                "channels": dm.channels(name),
                "window": dm.window,
                "fps": dm.fps,
                "skeleton": dm.skeletons[name].to_dict(),
                **({"features": dm.features} if getattr(dm, "features", "raw") != "raw" else {}),
            }
            for name in dm.dataset_names
        }
        self.hparams["datasets"] = specs
        self._build(specs)
        for name, char in zip(self.dataset_names, self.characters, strict=True):
            rep, pose = dm.representations[name], dm.pose_representations[name]
            char.input_mean.copy_(rep.mean.reshape(-1))
            char.input_std.copy_(rep.std.reshape(-1))
            char.pose_mean.copy_(pose.mean.reshape(-1))
            char.pose_std.copy_(pose.std.reshape(-1))

    def on_load_checkpoint(self, checkpoint: dict[str, Any]) -> None:
        """A checkpoint lacking an option was trained with that option's value of its time.

        Without ``frequency_head``: the paper's head; without ``lambda_phase_rate``:
        no phase-rate loss (a resumed run keeps the objective it was trained with);
        without another key of :data:`PREVIOUS_DEFAULTS` (checkpoints written before
        the defaults became the authors'): its previous default. The networks are
        rebuilt when that changes their layout, before the weights are loaded.
        """
        saved = checkpoint.get("hyper_parameters", {})
        legacy = {**PREVIOUS_DEFAULTS, "lambda_phase_rate": 0.0}
        changed = {k: v for k, v in legacy.items() if k not in saved and self.hparams.get(k) != v}
        self.hparams.update(changed)
        if changed and self.codebook is not None:
            self._build({name: self.hparams["datasets"][name] for name in self.dataset_names})

    def _require_built(self) -> SharedCodebook:
        if self.codebook is None:
            raise SkelagnosticError(
                "VqpaeAligner: no datasets yet; train it, load a checkpoint or pass datasets="
            )
        return self.codebook

    # ------------------------------------------------------------------ network
    def forward_dataset(self, index: int, windows: Tensor) -> tuple[Tensor, PhaseParameters]:
        """Run dataset ``index``'s VQ-PAE on normalised windows ``[B, C, T]``."""
        book = self._require_built()
        return self.characters[index].pae(windows, book.quantizer(index))

    def encode_dataset(self, index: int, windows: Tensor) -> PhaseParameters:
        """:meth:`forward_dataset` without the decoder: the parameters of the windows only."""
        book = self._require_built()
        return self.characters[index].pae.encode(windows, book.quantizer(index))

    def _losses(self, batch: Mapping[str, Any]) -> tuple[Tensor, dict[str, Tensor]]:
        hp = self.hparams
        parts: list[Tensor] = []
        logs: dict[str, Tensor] = {}
        for name, b in batch.items():
            if b is None:
                continue
            k = self.dataset_names.index(name)
            x = b["features"]
            rec, params = self.forward_dataset(k, x)
            if hp.center_windows:  # reconstruct each window's deviation from its temporal mean
                x = x - x.mean(dim=-1, keepdim=True)
                rec = rec - rec.mean(dim=-1, keepdim=True)
            rec_loss = nn.functional.mse_loss(rec, x)
            loss = rec_loss + hp.lambda_vq * params.vq_loss
            logs[f"rec/{name}"] = rec_loss.detach()
            logs[f"vq/{name}"] = params.vq_loss.detach()
            if self.training and hp.lambda_phase_rate > 0:
                rate_loss = phase_rate_loss(
                    self.characters[k].pae, name, b, params, hp.phase_rate_grad
                )
                loss = loss + hp.lambda_phase_rate * rate_loss
                logs[f"phase_rate/{name}"] = rate_loss.detach()
            if hp.pose_mlp != "none":
                points = params.manifold.transpose(1, 2)
                if hp.pose_mlp == "detached":
                    points = points.detach()
                pose_loss = nn.functional.mse_loss(self.characters[k].pose(points), b["poses"])
                loss = loss + pose_loss
                logs[f"pose/{name}"] = pose_loss.detach()
            parts.append(loss)
            if "overlap" in self._metrics and not self.training:
                self._metrics["overlap"].update(params.code, dataset=k)
            if not self.training and hp.pose_mlp != "none":
                logs[f"pose_mpjpe/{name}"] = pivot_mpjpe(self.characters[k], params, b["poses"])
        return torch.stack(parts).mean(), logs

    # ---------------------------------------------------------------- lightning
    def training_step(self, batch: Mapping[str, Any], batch_idx: int) -> Tensor:
        """Mean over datasets of reconstruction + lambda_vq * VQ (+ pose) losses."""
        loss, logs = self._losses(batch)
        size = sum(len(b["features"]) for b in batch.values() if b is not None)
        self.log("train/loss", loss, prog_bar=True, batch_size=size)
        self.log_dict({f"train/{k}": v for k, v in logs.items()}, batch_size=size)
        return loss

    def on_before_optimizer_step(self, optimizer: torch.optim.Optimizer) -> None:
        """Re-initialise the codebook (Eqs. 5-8) before the gradient step."""
        self._require_built().reinitialize()

    def validation_step(self, batch: Mapping[str, Any], batch_idx: int) -> Tensor:
        """Logs ``val/loss`` and per-dataset terms; counts codes for the overlap."""
        return self._evaluate(batch, "val")

    def test_step(self, batch: Mapping[str, Any], batch_idx: int) -> Tensor:
        """Logs ``test/loss`` and per-dataset terms."""
        return self._evaluate(batch, "test")

    def _evaluate(self, batch: Mapping[str, Any], stage: str) -> Tensor:
        loss, logs = self._losses(batch)
        size = sum(len(b["features"]) for b in batch.values() if b is not None)
        self.log(f"{stage}/loss", loss, prog_bar=True, batch_size=size, sync_dist=True)
        self.log_dict({f"{stage}/{k}": v for k, v in logs.items()}, batch_size=size, sync_dist=True)
        return loss

    def _start_overlap(self) -> None:
        if self.codebook is not None:
            self._metrics["overlap"] = ManifoldOverlap(
                self.codebook.num_codes, len(self.dataset_names)
            ).to(self.device)

    def _log_overlap(self, stage: str) -> None:
        metric = self._metrics.pop("overlap", None)
        if metric is None:
            return
        out = metric.compute()
        with metric.sync_context():
            counts = metric.counts.clone()
        if int(counts.sum()) > 0:
            self.log(f"{stage}/usage", out["usage"])
            # torchmetrics squeezes a one-dataset result to a 0-d tensor
            shares = out["per_dataset"].reshape(-1)
            single = len(self.dataset_names) < 2
            if single:  # codes shared by every character: meaningless with one character
                if not self._overlap_na_reported:
                    rank_zero_info(f"{stage}/overlap: not applicable (one dataset)")
                    self._overlap_na_reported = True
            else:
                self.log(f"{stage}/overlap", out["overlap"])
            for name, share, row in zip(self.dataset_names, shares, counts, strict=True):
                if not single and not torch.isnan(share):
                    self.log(f"{stage}/overlap/{name}", share)
                self.log(f"{stage}/codes/{name}", (row > 0).sum().float())
            self.last_code_counts = dict(zip(self.dataset_names, counts.cpu(), strict=True))

    def on_validation_epoch_start(self) -> None:
        """Start counting the validation codes."""
        self._start_overlap()

    def on_test_epoch_start(self) -> None:
        """Start counting the test codes."""
        self._start_overlap()

    def on_validation_epoch_end(self) -> None:
        """Log manifold overlap and codebook usage of the validation codes."""
        self._log_overlap("val")

    def on_test_epoch_end(self) -> None:
        """Log manifold overlap and codebook usage of the test codes."""
        self._log_overlap("test")

    def predict_step(
        self, batch: Mapping[str, Any], batch_idx: int, dataloader_idx: int = 0
    ) -> dict[str, dict[str, Tensor]]:
        """Per dataset: pivot phase, frequency, code, amplitude and manifold point of every window.

        The outputs are also collected; at the end of the predict epoch they are
        written per clip to ``<default_root_dir>/embeddings.npz`` (see
        :meth:`on_predict_epoch_end`).
        """
        out = {}
        for name, b in batch.items():
            out[name] = self.pivot_embedding(self.dataset_names.index(name), b)
            self._predictions.setdefault(name, []).append(
                {k: v.detach().cpu() for k, v in out[name].items()}
            )
        return out

    def on_predict_epoch_start(self) -> None:
        """Start collecting the per-window embeddings."""
        self._predictions = {}

    def on_predict_epoch_end(self) -> None:
        """Write the collected embeddings per clip (:func:`.predictions.write_embeddings`)."""
        collected = getattr(self, "_predictions", {})
        self._predictions = {}
        path = write_embeddings(self, collected)
        if path is not None:
            self.predictions_path = path

    def configure_optimizers(self) -> Any:
        """``model.optimizer`` + ``model.scheduler`` (per step); pose MLPs in their own group.

        See :func:`skelagnostic_vqpae.schedule.configure_optimizers`.
        """
        return configure_optimizers(self)

    @torch.no_grad()
    def average_pose(self, points: Tensor, dataset: int | str) -> Tensor:
        """The average-pose MLP (or the authors' phase decoder) at manifold points, denormalised.

        Args:
            points: ``[..., d]`` phase-manifold points.
            dataset: Index or name of the dataset (character).

        Returns:
            ``[..., P]``: root-local joint positions ``[J * 3]`` for a skelagnostic model;
            for an authors' run, their phase decoder's features (``pose_features`` of
            the dataset's spec, concatenated).

        Raises:
            SkelagnosticError: No datasets yet, an unknown dataset, or its MLP was not trained.
        """
        k = self._dataset_index(dataset)
        char = self.characters[k]
        if not bool(char.pose_fitted):
            raise SkelagnosticError(
                f"VqpaeAligner: the average-pose MLP of {self.dataset_names[k]!r} is not trained"
            )
        return char.pose(points.to(char.pose_mean)) * char.pose_std + char.pose_mean

    def _dataset_index(self, dataset: int | str) -> int:
        """Index of a dataset given by index or name (clear errors otherwise)."""
        self._require_built()
        if isinstance(dataset, str):
            if dataset not in self.dataset_names:
                raise SkelagnosticError(
                    f"VqpaeAligner: unknown dataset {dataset!r}; known: {self.dataset_names}"
                )
            return self.dataset_names.index(dataset)
        if 0 <= dataset < len(self.dataset_names):
            return int(dataset)
        raise SkelagnosticError(
            f"VqpaeAligner: dataset index {dataset} out of range [0, {len(self.dataset_names)})"
        )

    @torch.no_grad()
    def embed_windows(self, x: Tensor, dataset: int | str) -> dict[str, Tensor]:
        """Embed normalised windows of one dataset (no grouping into clips).

        Args:
            x: ``[B, C, T]`` windows, normalised as the network receives them.
            dataset: Index or name of the dataset (character).

        Returns:
            ``phase`` ``[B]`` (cycles), ``frequency`` ``[B]`` (Hz), ``code`` ``[B]``,
            ``amplitude`` ``[B, 2d]`` (the quantised amplitude: first half the
            sine, second half the cosine coefficients), ``manifold`` ``[B, d]``
            (the point ``Psi(A, phi)`` at the pivot) and ``reconstruction``
            ``[B, C, T]`` (the decoder's output, normalised).

        Raises:
            SkelagnosticError: No datasets yet, an unknown dataset, or ``x`` of the wrong shape.
        """
        k = self._dataset_index(dataset)
        rec, p = self.forward_dataset(k, x.to(self.device))
        return {
            "phase": p.phase,
            "frequency": p.frequency,
            "code": p.code,
            "amplitude": p.amplitude,
            "manifold": phase_manifold(p.amplitude, p.phase.unsqueeze(-1))[..., 0],
            "reconstruction": rec,
        }

    def pivot_embedding(self, k: int, batch: Mapping[str, Tensor]) -> dict[str, Tensor]:
        """Dataset ``k``'s embedding of each window's pivot, with its ``clip`` and ``pivot``."""
        p = self.encode_dataset(k, batch["features"])
        return {
            "phase": p.phase,
            "frequency": p.frequency,
            "code": p.code,
            "amplitude": p.amplitude,
            "manifold": p.manifold[..., p.manifold.shape[-1] // 2],
            "clip": batch["clip"],
            "pivot": batch["pivot"],
        }

    def on_train_epoch_end(self) -> None:
        """Mark the pose MLPs as trained (they learn alongside, unless ``pose_mlp="none"``)."""
        if self.hparams.pose_mlp != "none":
            for char in self.characters:
                char.pose_fitted.fill_(True)

    def export_graphs(self) -> list[ExportGraph]:
        """Per character: the encoder and, when trained, the average-pose decoder.

        See :func:`skelagnostic_vqpae.graphs.export_graphs`.

        Raises:
            SkelagnosticError: The aligner has no datasets yet.
        """
        return export_graphs(self)

    def dataset_of(self, skeleton: Skeleton) -> int:
        """Index of the dataset whose skeleton has ``skeleton``'s topology.

        Raises:
            SkelagnosticError: No trained dataset has that topology.
        """
        specs = self.hparams["datasets"] or {}
        for k, spec in enumerate(specs.values()):
            sk = spec.get("skeleton")  # absent for an authors' run (skelagnostic_vqpae.authors)
            if sk is None:
                continue
            if list(sk["joint_names"]) == list(skeleton.joint_names) and list(
                sk["parents"]
            ) == list(skeleton.parents):
                return k
        raise SkelagnosticError(
            f"VqpaeAligner: no trained dataset has the topology of {skeleton!r} "
            f"({skeleton.num_joints} joints); datasets: {self.dataset_names}"
        )

    def _windows(self, k: int, motion: Motion) -> tuple[Tensor, Motion]:
        """Normalised windows centred on every frame ``[F, C, T]`` (edges repeat the end frames).

        The features are those of the motion in metres (:meth:`Motion.to_metres`:
        its ``units``, else the guess from its skeleton's height), as the data
        sources give them in training, computed as in training (the dataset's
        ``features``: :class:`RootLocalVelocities`, or the authors' exporter's
        velocities of the whole clip, :func:`~skelagnostic_vqpae.features.authors_features`).
        """
        spec = self.hparams["datasets"][self.dataset_names[k]]
        fps, window = float(spec["fps"]), int(spec["window"])
        motion = motion.to_metres()
        if motion.fps != fps:
            motion = motion.resample(fps)
        char = self.characters[k]
        if spec.get("features", "raw") == "authors":
            vel = authors_features(motion)[0]
        else:
            vel = RootLocalVelocities().encode(motion)
        feats = vel.float().flatten(1).to(char.input_mean)
        feats = (feats - char.input_mean) / char.input_std
        half = window // 2
        padded = torch.cat([feats[:1].expand(half, -1), feats, feats[-1:].expand(half, -1)])
        return padded.unfold(0, window, 1), motion

    @torch.no_grad()
    def encode(self, motion: Motion, batch_size: int = 512) -> Latent:
        """Per-frame embedding of a whole clip (each frame = pivot of its own 1 s window).

        Args:
            motion: A clip on a trained skeleton, any frame rate and length unit
                (``motion.units``, else guessed from the skeleton's height: the model
                sees it in metres, as in training).
            batch_size: Windows per forward pass.

        Returns:
            ``Latent`` with ``z`` the ``[F, d]`` manifold points at the dataset frame
            rate; extras: ``phase`` ``[F]`` (cycles), ``frequency`` ``[F]`` (Hz),
            ``code`` ``[F]``, ``amplitude`` ``[F, 2d]``, ``raw_amplitude`` ``[F, 2d]``
            and ``dataset`` (index).
        """
        k = self.dataset_of(motion.skeleton)
        windows, motion = self._windows(k, motion)
        was_training = self.training
        self.eval()
        outs: dict[str, list[Tensor]] = {
            n: [] for n in ("z", "phase", "frequency", "code", "amplitude", "raw_amplitude")
        }
        for chunk in windows.split(batch_size):
            p = self.encode_dataset(k, chunk)
            outs["z"].append(p.manifold[..., p.manifold.shape[-1] // 2])
            outs["phase"].append(p.phase)
            outs["frequency"].append(p.frequency)
            outs["code"].append(p.code)
            outs["amplitude"].append(p.amplitude)
            outs["raw_amplitude"].append(p.raw_amplitude)
        self.train(was_training)
        cat = {n: torch.cat(v).cpu() for n, v in outs.items()}
        z = cat.pop("z")
        return Latent(z, motion.fps, {**cat, "dataset": torch.tensor(k)})

    @torch.no_grad()
    def decode(self, latent: Latent, skeleton: Skeleton, units: str | None = None) -> Motion:
        """The average pose at every manifold point, on ``skeleton`` (Sec. 5.2).

        The dataset's average-pose MLP gives root-local joint positions (metres);
        inverse kinematics turns them into a motion standing at the origin, in the
        skeleton's units.

        Args:
            latent: A latent of :meth:`encode`.
            skeleton: A trained skeleton.
            units: Length unit of ``skeleton`` (default: guessed from its height with
                :func:`~skelagnostic.core.units.infer_units`).

        Raises:
            SkelagnosticError: ``skeleton`` is not a trained topology or its pose MLP
                was never trained.
        """
        k = self.dataset_of(skeleton)
        char = self.characters[k]
        features = self.hparams["datasets"][self.dataset_names[k]].get("pose_features")
        if features:
            raise SkelagnosticError(
                f"VqpaeAligner: {self.dataset_names[k]!r} has the authors' phase decoder, which "
                f"predicts their exporter's features {list(features)}, not root-local joint "
                "positions: run it with average_pose() (skelagnostic_vqpae.authors)"
            )
        if not bool(char.pose_fitted):
            raise SkelagnosticError(
                f"VqpaeAligner: the average-pose MLP of {self.dataset_names[k]!r} is not "
                "trained (train with model.pose_mlp=detached|joint or call "
                "skelagnostic_vqpae.embed.fit_average_pose)"
            )
        pose = char.pose(latent.z.to(char.pose_mean)) * char.pose_std + char.pose_mean
        unit = infer_units(skeleton, units)
        positions = pose.view(len(pose), -1, 3).double().cpu() / UNITS[unit]
        rotations, root = inverse_kinematics(positions, skeleton)
        return Motion(skeleton, rotations, root, latent.fps, units=unit)
