"""PC-MRL stage 1: unsupervised point cloud -> target-skeleton motion (paper Sec. 3.2, Fig. 3 I).

:class:`PcmrlReconAligner` is the ``model=pcmrl`` aligner. Per training
sequence it draws a 256-point cloud on the source motion (Eq. 3, sigma 0.05
m), encodes every frame with a Point Transformer
(:mod:`~skelagnostic_pcmrl.recon.point_transformer`), runs a temporal transformer
(:mod:`~skelagnostic_pcmrl.recon.temporal`) to the root position and global unit
quaternions of the target skeleton, derives the target joints with Eq. 1
(:func:`~skelagnostic.core.kinematics.fk_from_global`), draws a 1024-point
cloud on the reconstruction and minimises the temporal KNN loss per body group
(Eq. 5), plus the optional end-effector loss (Eq. 6) and ``0.01 (|q| - 1)^2``.

Inference (:meth:`~PcmrlReconAligner.encode` / ``decode`` / ``retarget``)
takes a motion on any skeleton, in any units (converted to metres), and
returns a :class:`~skelagnostic.Motion` on the trained target skeleton in its
own units, with local rotations (global rotations of joints that carry only
zero-length bones are not observable and stay at their parent's, Sec. 5).
"""

from __future__ import annotations

from types import MappingProxyType
from typing import Any, ClassVar

import torch

from skelagnostic.aligners import Aligner, batch_skeleton
from skelagnostic.aligners.base import Latent
from skelagnostic.aligners.export import ExportGraph
from skelagnostic.aligners.optim import OptimizerSpec, check_specs, configure_optimization
from skelagnostic.core import quaternion as Q
from skelagnostic.core.kinematics import fk_from_global, forward_kinematics, local_from_global
from skelagnostic.core.motion import UNITS, Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.errors import SkelagnosticError
from skelagnostic.representations import POINT_GROUPS
from skelagnostic_pcmrl.points import (
    effective_joints,
    end_effector_pairs,
    group_of_joints,
    heading_frames,
    infer_units,
    sample_layout,
    warn_zero_length_bones,
)
from skelagnostic_pcmrl.recon.losses import (
    authors_alpha,
    end_effector_loss,
    temporal_knn_loss,
    unit_norm_penalty,
)
from skelagnostic_pcmrl.recon.point_transformer import PointTransformerEncoder
from skelagnostic_pcmrl.recon.temporal import AUTHORS_POSITION_DIM, TemporalTransformer

__all__ = ["PcmrlReconAligner", "end_effector_pairs"]

_AXES = {"x": 0, "y": 1, "z": 2}
#: The authors' optimizer: AdamW at their ``config.json`` rate, torch's default weight decay.
AUTHORS_OPTIMIZER = MappingProxyType(
    {"_target_": "torch.optim.AdamW", "_partial_": True, "lr": 1e-4, "weight_decay": 0.01}
)


def _batch_size(batch: dict[str, Any]) -> int:
    """Windows in a ``{dataset: batch}`` step (Lightning cannot infer it from a dict)."""
    return sum(len(sub["features"]) for sub in batch.values() if sub is not None)


class PcmrlReconAligner(Aligner):
    """PC-MRL point-cloud-to-motion reconstruction onto one target skeleton.

    The target skeleton comes from the data module (``data.target``) when
    training starts, or from the checkpoint; it is saved in every checkpoint.

    Args:
        stage: ``"reconstruction"`` (this model). Stage 2 is ``model=pcmrl_interp``.
        num_source_points: Points of the source cloud (256).
        num_target_points: Points of the cloud drawn on the reconstruction (1024).
        sigma: Gaussian offset of the points, metres (0.05).
        dim: Point-encoder width after the input MLP (64), doubled at every stage.
        stages: Point-encoder pooling stages (4).
        point_heads: Heads of the point self-attention.
        group_k: Neighbours of the kNN grouping in the pooling stages (8).
        point_attention: Self-attention of the point encoder: ``"full"`` (over all the
            points of a frame, the authors' encoder), ``"vector"`` (the Point
            Transformer layer of [52] over each point's ``attention_k`` nearest
            points) or ``"none"`` (ablation).
        attention_k: Neighbours of ``point_attention="vector"`` (16, as in [52]).
        layer_scale: Initial residual scale of the point attention blocks
            (LayerScale; ``None``: none).
        temporal_dim: Width of the temporal transformer (``None``: the frame feature width;
            with ``layout="authors"`` it must be ``None``: the width is the frame feature
            width + 16).
        temporal_layers: Temporal transformer blocks (6).
        temporal_heads: Temporal attention heads (4).
        dropout: Dropout of the temporal transformer.
        knn_k: Neighbours of the KNN loss (8).
        knn_variant: ``"paper"`` (Eq. 5) or ``"authors"`` (the authors' code:
            :func:`~skelagnostic_pcmrl.recon.losses.authors_knn_terms`, global +
            ``alpha`` x normalised + velocity terms).
        knn_alpha_warmup: ``knn_variant="authors"``: steps of the linear ramp of the
            normalised term's weight ``alpha``, which then decays linearly to 0 at
            ``trainer.max_steps`` (:func:`~skelagnostic_pcmrl.recon.losses.authors_alpha`;
            500 in the authors' code; 0: ``alpha = 1`` throughout; no decay when
            ``trainer.max_steps`` is not set).
        knn_reduction: ``"sum"`` (Eq. 5 as is) or ``"mean"`` (per point, neighbour and
            frame: the same minimum at another scale, relative to ``lambda_q``).
        lambda_q: Weight of the unit-norm penalty (0.01).
        lambda_end: Weight of the end-effector loss (0: off; the paper's loss is optional).
        optimizer: ``model.optimizer``, a ``_partial_`` spec or a callable taking the
            parameters (:mod:`skelagnostic.aligners.optim`): AdamW with ``lr`` 1e-4 (the
            authors' ``config.json``; the paper gives none) and ``weight_decay`` 0.01 (the
            default of the authors' ``torch.optim.AdamW``).
        scheduler: ``model.scheduler``: ``None`` (a constant rate, as the authors).
        centre: Subtract the source cloud's (horizontal) centroid in every frame before
            encoding and add it back to the root (horizontal translation invariance:
            the network predicts the root relative to the cloud's centroid, so clips
            of any length and position stay in the training distribution). The paper
            does not say; the authors subtract each window's mean point (all axes).
        centre_up: With ``centre``, subtract the centroid's height too (not in the paper:
            datasets disagree on the floor height).
        canonical_yaw: Also remove the heading: rotate every centred cloud about the
            up axis so that its left-minus-right direction
            (:func:`~skelagnostic_pcmrl.points.heading_frames`, from the body groups)
            points along one fixed axis, predict the root and the global rotations in
            that frame, and rotate them back. The network then never has to learn
            the heading equivariance of global quaternions from data (not in the
            paper; docs/reports/pcmrl.md gives the measurements). Checkpoints saved
            before this option existed load with it off.
        yaw_window: Frames of the moving average of the heading estimate (15).
        chunk: Frames per temporal-transformer chunk at inference (``None``: the
            training window); chunks overlap by half and are blended.
        target: Target skeleton (procedural kind or BVH path) when built without
            a data module; ``None``: from the data module or the checkpoint.
        target_units: Units of ``target`` (``None``: guessed).
        sample_seed: Seed of the point clouds drawn at inference and validation.
        layout: ``"skelagnostic"`` or ``"authors"``: the point encoder and temporal
            transformer of the authors' code
            (:class:`~skelagnostic_pcmrl.recon.point_transformer.PointTransformerEncoder`,
            :class:`~skelagnostic_pcmrl.recon.temporal.TemporalTransformer`;
            ``point_heads``, ``point_attention``, ``attention_k``, ``layer_scale``
            and ``dropout`` do not apply to it). The output layer starts from the
            target's rest pose in both.
    """

    capabilities: ClassVar[frozenset[str]] = frozenset({"encode", "decode", "retarget"})

    def __init__(
        self,
        stage: str = "reconstruction",
        num_source_points: int = 256,
        num_target_points: int = 1024,
        sigma: float = 0.05,
        dim: int = 64,
        stages: int = 4,
        point_heads: int = 4,
        group_k: int = 8,
        point_attention: str = "full",
        attention_k: int = 16,
        layer_scale: float | None = None,
        temporal_dim: int | None = None,
        temporal_layers: int = 6,
        temporal_heads: int = 4,
        dropout: float = 0.0,
        knn_k: int = 8,
        knn_variant: str = "paper",
        knn_alpha_warmup: int = 500,
        knn_reduction: str = "sum",
        lambda_q: float = 0.01,
        lambda_end: float = 0.0,
        optimizer: OptimizerSpec = AUTHORS_OPTIMIZER,
        scheduler: OptimizerSpec | None = None,
        centre: bool = True,
        centre_up: bool = False,
        canonical_yaw: bool = False,
        yaw_window: int = 15,
        chunk: int | None = None,
        target: str | None = None,
        target_units: str | None = None,
        sample_seed: int = 0,
        layout: str = "skelagnostic",
    ) -> None:
        super().__init__()
        if stage != "reconstruction":
            raise SkelagnosticError(
                f"model.stage={stage!r}: model=pcmrl is PC-MRL stage 1 (reconstruction); the "
                "interpolation stage is model=pcmrl_interp"
            )
        for name, value in (
            ("num_source_points", num_source_points),
            ("num_target_points", num_target_points),
            ("knn_k", knn_k),
        ):
            if value < 1:
                raise SkelagnosticError(f"model.{name} must be positive, got {value}")
        if num_target_points < knn_k:
            raise SkelagnosticError(
                f"model.num_target_points={num_target_points} is below model.knn_k={knn_k}"
            )
        if sigma < 0:
            raise SkelagnosticError(f"model.sigma must be non-negative, got {sigma}")
        if yaw_window < 1:
            raise SkelagnosticError(f"model.yaw_window must be at least 1 frame, got {yaw_window}")
        optimizer, scheduler = check_specs(optimizer, scheduler)
        self.save_hyperparameters()
        self.encoder = PointTransformerEncoder(
            len(POINT_GROUPS),
            dim,
            stages,
            point_heads,
            group_k,
            attention=point_attention,
            attention_k=attention_k,
            layer_scale=layer_scale,
            layout=layout,
        )
        if layout == "authors" and temporal_dim is not None:
            raise SkelagnosticError(
                "model.temporal_dim must be null with model.layout=authors "
                "(the width is the frame feature width + 16)"
            )
        self.temporal: TemporalTransformer | None = None
        self.target_skeleton: Skeleton | None = None
        self.target_units: str | None = None
        self.window: int | None = chunk
        if target is not None:
            from skelagnostic_pcmrl.recon.data import load_target_skeleton

            self.set_target(*load_target_skeleton(target, target_units))

    # ----------------------------------------------------------------- target
    def set_target(self, skeleton: Skeleton, units: str) -> None:
        """Build the output heads for ``skeleton`` (in metres), which came in ``units``."""
        if self.target_skeleton is not None:
            if not self.target_skeleton.same_topology(skeleton):
                raise SkelagnosticError(
                    f"model=pcmrl was built for target {self.target_skeleton!r}, not {skeleton!r}"
                )
            return
        warn_zero_length_bones(skeleton, "target skeleton")
        self.target_skeleton = skeleton
        self.target_units = units
        joints = effective_joints(skeleton)
        self._effective = joints
        # every joint takes the global rotation of its nearest predicted ancestor-or-self
        slot = {j: i for i, j in enumerate(joints)}
        source_of = []
        for j, p in enumerate(skeleton.parents):
            source_of.append(slot[j] if j in slot else source_of[p])
        self.register_buffer("_source_of", torch.tensor(source_of), persistent=False)
        self.register_buffer("_target_offsets", skeleton.offsets.float(), persistent=False)
        rest_heading = heading_frames(
            skeleton.rest_positions().float()[None, None],
            group_of_joints(skeleton)[None],
            _AXES[skeleton.up_axis],
            1,
        )[0, 0]
        self.register_buffer("_rest_heading_inv", Q.inv(rest_heading), persistent=False)
        hp = self.hparams
        layout = hp.get("layout", "skelagnostic")
        width = hp.temporal_dim or self.encoder.out_channels
        if layout == "authors":
            width = self.encoder.out_channels + AUTHORS_POSITION_DIM
        self.temporal = TemporalTransformer(
            self.encoder.out_channels,
            width,
            hp.temporal_layers,
            hp.temporal_heads,
            3 + 4 * len(joints),
            hp.dropout,
            layout=layout,
        )
        out = self.temporal.out
        last = out if isinstance(out, torch.nn.Linear) else out[-1]
        with torch.no_grad():  # start from the target's rest pose at the cloud centre
            last.weight.mul_(0.01)
            last.bias.zero_()
            last.bias[3::4] = 1.0
        if self.device.type != "cpu":
            self.to(self.device)

    def _require_target(self) -> Skeleton:
        if self.target_skeleton is None or self.temporal is None:
            raise SkelagnosticError(
                "model=pcmrl has no target skeleton yet: train it with a data module "
                "(data.target=...), load a checkpoint, or pass target=..."
            )
        return self.target_skeleton

    def setup(self, stage: str) -> None:
        """Take the target skeleton and window from the data module (before training)."""
        dm = getattr(self.trainer, "datamodule", None) if self._trainer is not None else None
        if dm is not None and hasattr(dm, "target_skeleton"):
            self.set_target(dm.target_skeleton, dm.target_units)
            if self.window is None:
                self.window = int(dm.window)
            for name, source in getattr(dm, "skeletons", {}).items():
                warn_zero_length_bones(source, f"source skeleton {name!r}")
        self._require_target()

    def on_save_checkpoint(self, checkpoint: dict[str, Any]) -> None:
        """Store the target skeleton, its units and the window."""
        skeleton = self._require_target()
        checkpoint["pcmrl"] = {
            "target": skeleton.to_dict(),
            "target_units": self.target_units,
            "window": self.window,
        }

    def on_load_checkpoint(self, checkpoint: dict[str, Any]) -> None:
        """Rebuild the output heads before the weights are loaded."""
        state = checkpoint.get("pcmrl")
        if state is None:
            raise SkelagnosticError("checkpoint has no 'pcmrl' entry: not a model=pcmrl checkpoint")
        saved = checkpoint.get("hyper_parameters")
        for option in ("canonical_yaw", "centre_up"):  # saved before the option existed
            if saved is not None and option not in saved:
                self.hparams[option] = False
        self.set_target(Skeleton.from_dict(state["target"]), state["target_units"])
        if self.window is None:
            self.window = state["window"]

    # ---------------------------------------------------------------- network
    def _centre(self, points: torch.Tensor, up: int) -> torch.Tensor:
        """``[B, T, 3]`` per-frame mean of ``[B, T, P, 3]`` clouds.

        Horizontal only without ``centre_up``, zero without ``centre``.
        """
        centre = points.detach().mean(dim=2)
        if not self.hparams.centre:
            return torch.zeros_like(centre)
        if not self.hparams.centre_up:
            centre[..., up] = 0.0
        return centre

    def encode_points(
        self, points: torch.Tensor, groups: torch.Tensor, frames_per_call: int | None = None
    ) -> torch.Tensor:
        """``[B, T, F]`` frame features of centred clouds ``[B, T, P, 3]``, groups ``[B, P]``."""
        onehot = torch.nn.functional.one_hot(groups, len(POINT_GROUPS)).to(points.dtype)
        x = torch.cat([points, onehot.unsqueeze(1).expand(*points.shape[:3], -1)], dim=-1)
        if frames_per_call is None:
            return self.encoder(x)
        parts = [
            self.encoder(x[:, s : s + frames_per_call])
            for s in range(0, x.shape[1], frames_per_call)
        ]
        return torch.cat(parts, dim=1)

    def heads(self, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(root [B, T, 3], raw quaternions [B, T, J_eff, 4])`` from frame features."""
        self._require_target()
        out = self.temporal(features)
        return out[..., :3], out[..., 3:].unflatten(-1, (-1, 4))

    def full_rotations(self, raw: torch.Tensor) -> torch.Tensor:
        """``[..., J, 4]`` unit global rotations of all target joints from the predicted ones."""
        return Q.normalize(raw)[..., self._source_of, :]

    def canonical(
        self, points: torch.Tensor, groups: torch.Tensor, up: int
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """The clouds ``[B, T, P, 3]`` as the encoder sees them, and how to undo that.

        Returns:
            ``(cloud, centre [B, T, 3], heading [B, T, 4])``: the cloud minus its
            centroid (``centre``; see ``centre_up``), turned by the inverse of its
            ``heading`` (identity when ``canonical_yaw`` is off).
        """
        centre = self._centre(points, up)
        cloud = points - centre.unsqueeze(2)
        if not self.hparams.canonical_yaw:
            return (
                cloud,
                centre,
                Q.identity(*cloud.shape[:2], dtype=cloud.dtype, device=cloud.device),
            )
        heading = heading_frames(
            cloud.detach(), groups.expand(cloud.shape[0], -1), up, int(self.hparams.yaw_window)
        )
        return Q.rotate(Q.inv(heading).unsqueeze(2), cloud), centre, heading

    def to_world(
        self,
        root: torch.Tensor,
        rotations: torch.Tensor,
        centre: torch.Tensor,
        heading: torch.Tensor,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Root ``[B, T, 3]`` and global rotations ``[B, T, J, 4]`` from the heading-free frame.

        The target's rest pose faces the canonical axis at identity rotations, so the
        untrained network stands in the rest pose facing the way the source faces.
        """
        if not self.hparams.canonical_yaw:
            return root + centre, rotations
        root = Q.rotate(heading, root) + centre
        turn = Q.mul(heading, self._rest_heading_inv.to(heading))
        return root, Q.mul(turn.unsqueeze(-2), rotations)

    def reconstruct(
        self, points: torch.Tensor, groups: torch.Tensor, up: int = 1
    ) -> dict[str, torch.Tensor]:
        """Run the network on source clouds ``[B, T, P, 3]`` (metres), groups ``[B, P]``.

        Returns:
            ``root`` ``[B, T, 3]``, ``raw`` ``[B, T, J_eff, 4]``, ``rotations``
            ``[B, T, J, 4]`` (global, unit) and ``positions`` ``[B, T, J, 3]``.
        """
        target = self._require_target()
        cloud, centre, heading = self.canonical(points, groups, up)
        root, raw = self.heads(self.encode_points(cloud, groups))
        root, rot = self.to_world(root, self.full_rotations(raw), centre, heading)
        pos = fk_from_global(rot, root, self._target_offsets, target.parents)
        return {"root": root, "raw": raw, "rotations": rot, "positions": pos}

    # ----------------------------------------------------------------- export
    def export_graphs(self) -> list[ExportGraph]:
        """The reconstruction network: source point clouds -> target-skeleton motion.

        The graph includes the cloud centring, the heading canonicalisation
        (``canonical_yaw``), the point and temporal transformers and forward
        kinematics. Batch and time are dynamic; the number of points is fixed
        (the pooling stages reduce it to one point).

        Raises:
            SkelagnosticError: The model has no target skeleton yet.
        """
        target = self._require_target()
        hp = self.hparams
        up = _AXES[target.up_axis]
        points = torch.randn(2, 6, hp.num_source_points, 3)
        groups = (
            torch.arange(hp.num_source_points)
            .remainder(len(POINT_GROUPS))[None]
            .expand(2, -1)
            .contiguous()
        )
        return [
            ExportGraph(
                "reconstruction",
                _ReconstructionGraph(self, up),
                (points, groups),
                ("points", "groups"),
                ("root", "global_rotations", "local_rotations", "positions"),
                {
                    "points": {0: "batch", 1: "time"},
                    "groups": {0: "batch"},
                    "root": {0: "batch", 1: "time"},
                    "global_rotations": {0: "batch", 1: "time"},
                    "local_rotations": {0: "batch", 1: "time"},
                    "positions": {0: "batch", 1: "time"},
                },
                description=(
                    f"source point clouds [B, T, {hp.num_source_points}, 3] (metres, "
                    f"{target.up_axis} up) with their body groups [B, {hp.num_source_points}] -> "
                    f"motion of the target skeleton ({target.num_joints} joints): root [B, T, 3], "
                    "global and local unit quaternions (w, x, y, z) [B, T, J, 4], joint positions "
                    "[B, T, J, 3] (metres)"
                ),
                fixed_axes={
                    "points": f"{hp.num_source_points} points per cloud: the point "
                    f"encoder pools them to one in {hp.stages} stages"
                },
                metadata={
                    "target_skeleton": target.to_dict(),
                    "target_units": self.target_units,
                    "units": "m",
                    "up_axis": target.up_axis,
                    "point_groups": list(POINT_GROUPS),
                    "sigma": float(hp.sigma),
                    "training_window": self.window,
                    "canonical_yaw": bool(hp.canonical_yaw),
                    "preprocess": (
                        "draw the cloud layout once per source skeleton "
                        "(skelagnostic_pcmrl.points.sample_layout: a bone per point with "
                        "probability proportional to its length, a position along it and a "
                        "Gaussian offset of sigma metres) and place it on every frame "
                        "(PointLayout.points); groups are the layout's body-group ids"
                    ),
                    "postprocess": (
                        "rotations are unit quaternions (w, x, y, z); sequences longer than "
                        "the training window: run overlapping chunks and blend them, as "
                        "PcmrlReconAligner.decode does"
                    ),
                },
            )
        ]

    # --------------------------------------------------------------- training
    def _step(
        self, batch: dict[str, Any], generator: torch.Generator | None, prefix: str
    ) -> torch.Tensor:
        hp = self.hparams
        target = self._require_target()
        losses = []
        for name, sub in batch.items():
            if sub is None:
                continue
            source = batch_skeleton(sub, name)
            feats = sub["features"].float()
            size = feats.shape[0]
            rot_l, trans = Q.normalize(feats[..., :4]), feats[..., 4:]
            grot, gpos = forward_kinematics(
                rot_l, trans[..., 0, :], sub["offsets"][0], source.parents, translations=trans
            )
            src_layout = sample_layout(
                source, hp.num_source_points, hp.sigma, (size,), generator, self.device
            )
            src_pts = src_layout.points(grot, gpos, sub["offsets"])
            out = self.reconstruct(src_pts, src_layout.groups, _AXES[source.up_axis])
            tgt_layout = sample_layout(
                target, hp.num_target_points, hp.sigma, (size,), generator, self.device
            )
            tgt_pts = tgt_layout.points(out["rotations"], out["positions"], self._target_offsets)
            knn = temporal_knn_loss(
                tgt_pts,
                src_pts,
                tgt_layout.groups,
                src_layout.groups,
                hp.knn_k,
                hp.knn_reduction,
                hp.knn_variant,
                alpha=self._knn_alpha(),
            )
            norm = unit_norm_penalty(out["raw"])
            end = end_effector_loss(out["positions"], gpos, end_effector_pairs(source, target))
            loss = knn + hp.lambda_q * norm + hp.lambda_end * end
            sync = prefix != "train"
            self.log(f"{prefix}/knn", knn, batch_size=size, sync_dist=sync)
            self.log(f"{prefix}/end", end, batch_size=size, sync_dist=sync)
            self.log(f"{prefix}/qnorm", norm, batch_size=size, sync_dist=sync)
            losses.append(loss)
        if not losses:
            return torch.zeros((), device=self.device, requires_grad=prefix == "train")
        return torch.stack(losses).mean()

    def _knn_alpha(self) -> float:
        """Weight of the authors' normalised KNN term at this step (1 outside training)."""
        trainer = self._trainer
        if trainer is None or not self.training:
            return 1.0
        total = trainer.max_steps if trainer.max_steps and trainer.max_steps > 0 else 0
        return authors_alpha(self.global_step + 1, int(self.hparams.knn_alpha_warmup), total)

    def training_step(self, batch: dict[str, Any], batch_idx: int) -> torch.Tensor:
        """KNN + unit-norm (+ end-effector) loss on fresh clouds; logs ``train/loss``."""
        loss = self._step(batch, None, "train")
        self.log("train/loss", loss, prog_bar=True, batch_size=_batch_size(batch))
        return loss

    def validation_step(self, batch: dict[str, Any], batch_idx: int) -> torch.Tensor:
        """The same loss on clouds seeded by ``sample_seed`` and the batch index."""
        gen = torch.Generator().manual_seed(self.hparams.sample_seed + batch_idx)
        loss = self._step(batch, gen, "val")
        self.log("val/loss", loss, prog_bar=True, sync_dist=True, batch_size=_batch_size(batch))
        return loss

    def test_step(self, batch: dict[str, Any], batch_idx: int) -> torch.Tensor:
        """As :meth:`validation_step`, logged as ``test/*``."""
        gen = torch.Generator().manual_seed(self.hparams.sample_seed + batch_idx)
        loss = self._step(batch, gen, "test")
        self.log("test/loss", loss, sync_dist=True, batch_size=_batch_size(batch))
        return loss

    def configure_optimizers(self) -> Any:
        """``model.optimizer`` (the authors' AdamW) and ``model.scheduler`` (none by default)."""
        hp = self.hparams
        return configure_optimization(hp.optimizer, hp.scheduler, self.parameters(), self._trainer)

    @torch.no_grad()
    def render_sample(self, batch: dict[str, Any]) -> dict[str, Motion]:
        """The first validation window and its reconstruction (``callbacks=render``)."""
        name, sub = next((n, b) for n, b in batch.items() if b is not None)
        feats = sub["features"][0].float().cpu()
        source = batch_skeleton(sub, name)
        rotations = Q.normalize(feats[..., :4])
        motion = Motion(source, rotations, feats[:, 0, 4:], float(sub["fps"]), units="m")
        result = self.decode(self.encode(motion), self._require_target())
        return {"source": motion, "pcmrl": result}

    # -------------------------------------------------------------- inference
    @torch.no_grad()
    def encode(self, motion: Motion) -> Latent:
        """Per-frame Point Transformer features of a 256-point cloud on ``motion``.

        Returns:
            ``Latent(z=[T, F], fps, extras={"centre": [T, 3], "heading": [T, 4]})``: the
            per-frame centroid of the cloud (see ``centre`` and ``centre_up``), which
            the predicted root is relative to, and the heading the cloud was encoded without
            (identity if ``canonical_yaw`` is off).
        """
        metric = motion.to_metres().to(torch.float32, self.device)
        warn_zero_length_bones(metric.skeleton, "source skeleton")
        gen = torch.Generator().manual_seed(self.hparams.sample_seed)
        layout = sample_layout(
            metric.skeleton,
            self.hparams.num_source_points,
            self.hparams.sigma,
            (),
            gen,
            self.device,
        )
        pts = layout.points(
            metric.global_rotations(),
            metric.global_positions(),
            metric.skeleton.offsets.float().to(self.device),
        )[None]
        up = _AXES[metric.skeleton.up_axis]
        cloud, centre, heading = self.canonical(pts, layout.groups[None], up)
        feats = self.encode_points(cloud, layout.groups[None], frames_per_call=256)
        return Latent(feats[0], motion.fps, {"centre": centre[0], "heading": heading[0]})

    def _output_units(self, skeleton: Skeleton) -> str:
        """Units of ``skeleton``: the target file's or metres if the offsets match, else a guess."""
        target = self._require_target()
        for units in dict.fromkeys((self.target_units or "m", "m")):
            scaled = skeleton.offsets.double() * UNITS[units]
            if torch.allclose(scaled, target.offsets.double(), rtol=1e-3, atol=1e-6):
                return units
        return infer_units(skeleton)

    def _chunks(self, frames: int) -> list[int]:
        chunk = int(self.hparams.chunk or self.window or frames)
        if frames <= chunk:
            return [0]
        hop = max(1, chunk // 2)
        starts = list(range(0, frames - chunk + 1, hop))
        if starts[-1] != frames - chunk:
            starts.append(frames - chunk)
        return starts

    @torch.no_grad()
    def decode(self, latent: Latent, skeleton: Skeleton) -> Motion:
        """The target-skeleton motion of ``latent`` (chunks of the training window, blended).

        Args:
            latent: Output of :meth:`encode`.
            skeleton: The trained target skeleton, in any units (the result uses them).

        Raises:
            SkelagnosticError: ``skeleton`` is not the trained target topology.
        """
        target = self._require_target()
        if not target.same_topology(skeleton):
            raise SkelagnosticError(
                f"model=pcmrl reconstructs onto its trained target {target!r} "
                f"({target.num_joints} joints); got {skeleton!r}. Train another model with "
                "data.target=<that skeleton>"
            )
        feats = latent.z.to(self.device)[None]
        frames = feats.shape[1]
        chunk = int(self.hparams.chunk or self.window or frames)
        root = feats.new_zeros(frames, 3)
        quat = feats.new_zeros(frames, len(self._effective), 4)
        weight = feats.new_zeros(frames)
        for start in self._chunks(frames):
            stop = min(frames, start + chunk)
            r, q = self.heads(feats[:, start:stop])
            q = Q.normalize(q[0])
            n = stop - start
            ramp = torch.minimum(
                torch.arange(1, n + 1, device=feats.device),
                torch.arange(n, 0, -1, device=feats.device),
            ).float()
            sign = torch.where((quat[start:stop] * q).sum(-1, keepdim=True) < 0, -1.0, 1.0)
            root[start:stop] += ramp[:, None] * r[0]
            quat[start:stop] += ramp[:, None, None] * sign * q
            weight[start:stop] += ramp
        heading = latent.extras.get("heading")
        if heading is None:  # a latent of a model without canonical_yaw
            heading = Q.identity(frames, dtype=root.dtype, device=root.device)
        root, rot = self.to_world(
            root / weight[:, None],
            self.full_rotations(quat),
            latent.extras["centre"].to(root),
            heading.to(root),
        )
        rot = Q.continuity(rot, dim=-3)
        units = self._output_units(skeleton)
        local = Q.normalize(local_from_global(rot, skeleton.parents))
        return Motion(skeleton, local.cpu(), (root / UNITS[units]).cpu(), latent.fps, units=units)


class _ReconstructionGraph(torch.nn.Module):
    """:meth:`PcmrlReconAligner.reconstruct` for one up axis, plus local rotations."""

    def __init__(self, aligner: PcmrlReconAligner, up: int) -> None:
        super().__init__()
        self.aligner = aligner
        self.up = up

    def forward(
        self, points: torch.Tensor, groups: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """Clouds ``[B, T, P, 3]``, groups ``[B, P]`` -> root, rotations (global, local), joints."""
        out = self.aligner.reconstruct(points, groups, self.up)
        parents = self.aligner._require_target().parents
        local = Q.normalize(local_from_global(out["rotations"], parents))
        return out["root"], out["rotations"], local, out["positions"]
