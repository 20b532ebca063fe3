"""The HuMoT :class:`~skelagnostic.aligners.Aligner`: training, inference and retargeting.

Training (Sec. 3.4, App. A.4-A.5): each step takes one batch of chunks per
topology; every chunk gets two independent joint subsets, the first is
encoded with its template and decoded with the second's template, and the
loss ``L_rec + lambda_blc * L_blc`` is computed on the second subset. The
optimizer and its schedule are config (``model.optimizer``, ``model.scheduler``,
:mod:`skelagnostic.aligners.optim`); the defaults are the paper's: Adam (0.9,
0.999) with a triangular cyclic learning rate from 1e-5 up to 1e-4 and back
over 10 epochs.

Inference works on whole motions of any length: the motion is resampled to
30 fps, converted to metres, cut into ``chunk``-frame windows every
``chunk // 2`` frames, each centred by its major joints and encoded. Decoding
adds the chunk centres back (scaled by the target/source leg-length ratio,
Sec. A.6) and cross-fades the overlapping chunks with triangular weights.
Positions become a :class:`~skelagnostic.Motion` by
:func:`skelagnostic.representations.inverse_kinematics` (per-bone swing from
the rest pose onto the predicted bone direction, accumulated down the chain;
joints with several children take the best rotation of all their child bones;
no twist about the bone axis, since positions do not determine it).
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, ClassVar

import torch

from skelagnostic.aligners import Aligner, Latent, batch_skeleton
from skelagnostic.aligners.export import ExportGraph, Method
from skelagnostic.aligners.optim import OptimizerSpec, check_specs, configure_optimization
from skelagnostic.core.motion import UNITS, Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.core.units import infer_units
from skelagnostic.errors import SkelagnosticError
from skelagnostic.representations import inverse_kinematics
from skelagnostic_humot.data import Topology, gather_subset, prepare_chunks, sample_keep
from skelagnostic_humot.model import (
    HuMoT,
    HuMoTConfig,
    bone_length_consistency_loss,
    reconstruction_loss,
)
from skelagnostic_humot.template import from_model_frame, major_joints, to_model_frame
from skelagnostic_humot.xcit import XCA_SCOPES

if TYPE_CHECKING:
    import lightning as L

    from skelagnostic.callbacks import SummaryContent

__all__ = ["HumotAligner", "infer_units", "leg_length"]

#: Typical standing height (m) used to guess the units of a motion that does not state them.


def leg_length(template: torch.Tensor, skeleton: Skeleton) -> float:
    """Mean hip-knee-ankle length of the legs of ``template`` ``[J, 3]`` (0 without legs)."""
    major = major_joints(skeleton)
    legs = []
    for side in ("left", "right"):
        keys = [f"{side}_hip", f"{side}_knee", f"{side}_ankle"]
        if all(k in major for k in keys):
            a, b, c = (template[major[k]] for k in keys)
            legs.append(float((b - a).norm() + (c - b).norm()))
    return sum(legs) / len(legs) if legs else 0.0


def _chunk_starts(frames: int, chunk: int, hop: int) -> list[int]:
    if frames <= chunk:
        return [0]
    starts = list(range(0, frames - chunk + 1, hop))
    if starts[-1] != frames - chunk:
        starts.append(frames - chunk)
    return starts


#: The paper's optimizer (App. A.5): Adam (0.9, 0.999), starting at the cycle's lower bound.
PAPER_OPTIMIZER = MappingProxyType(
    {"_target_": "torch.optim.Adam", "_partial_": True, "lr": 1e-5, "betas": (0.9, 0.999)}
)
#: The paper's schedule: a triangular cycle from 1e-5 up to 1e-4 and back in 10 epochs.
PAPER_SCHEDULER = MappingProxyType(
    {
        "_target_": "skelagnostic.aligners.optim.cyclic_lr",
        "_partial_": True,
        "max_lr": 1e-4,
        "period_epochs": 10.0,
    }
)


class HumotAligner(Aligner):
    """HuMoT: topology-agnostic transformer autoencoder for human motion.

    Args:
        dim: Token channels (paper: 128).
        latent: Latent channels ``Z`` (paper: 128).
        blocks: XCiT blocks in the encoder and in the decoder (paper: 4).
        heads: Attention heads (paper: 8).
        kernel_size: Temporal kernel of the Conv1d layers (not in the paper; 5 gives
            2.36 M parameters against the paper's 2,475,511).
        mlp_ratio: XCiT MLP width ratio (XCiT default 4).
        layer_scale: Initial XCiT layer-scale value.
        lambda_blc: Weight of the bone-length consistency loss (paper: 0.5).
        subsampling: Stochastic joint subsampling (paper: on; off = "no SJS" ablation).
        p_major: Drop probability of major joints (paper: 0.1).
        p_other: Drop probability of other joints (paper: 0.5).
        optimizer: ``model.optimizer``, a ``_partial_`` spec or a callable taking the
            parameters (:mod:`skelagnostic.aligners.optim`); paper: Adam, betas (0.9,
            0.999), from the cycle's lower bound ``lr`` = 1e-5.
        scheduler: ``model.scheduler`` (``None``: a constant rate); paper: a
            triangular cycle (:func:`~skelagnostic.aligners.optim.cyclic_lr`) up to
            ``max_lr`` = 1e-4 and back over ``period_epochs`` = 10, stepped per batch.
        chunk: Frames per chunk at inference (paper's training chunks: 30).
        fast_path: Compute the network on the valid joints of each chunk only (packed
            tokens); ``False`` runs the padded computation, same values and gradients to
            float rounding, kept as the benchmarks' same-run baseline.
        xca: The tokens each XCA channel map spans: ``"frame"`` (one frame's joints and
            latent token, our reading of the paper's Sec. 3.3; every joint reaches the
            latent of its frame) or ``"sequence"`` (all joints and frames of a chunk:
            the reading before 0.x, kept for its checkpoints and comparisons; see
            :mod:`skelagnostic_humot.xcit`).

    Raises:
        SkelagnosticError: A hyper-parameter is out of range (the message names it).
    """

    capabilities: ClassVar[frozenset[str]] = frozenset(
        {"encode", "decode", "retarget", "unseen_topology", "denoise"}
    )
    # checkpoints from before model.xca were trained with one XCA map per chunk
    legacy_hparams: ClassVar[Mapping[str, Any]] = MappingProxyType({"xca": "sequence"})

    def __init__(
        self,
        dim: int = 128,
        latent: int = 128,
        blocks: int = 4,
        heads: int = 8,
        kernel_size: int = 5,
        mlp_ratio: float = 4.0,
        layer_scale: float = 1.0,
        lambda_blc: float = 0.5,
        subsampling: bool = True,
        p_major: float = 0.1,
        p_other: float = 0.5,
        optimizer: OptimizerSpec = PAPER_OPTIMIZER,
        scheduler: OptimizerSpec | None = PAPER_SCHEDULER,
        chunk: int = 30,
        fast_path: bool = True,
        xca: str = "frame",
    ) -> None:
        super().__init__()
        checks = (
            ("dim", dim > 0 and dim % heads == 0, "a positive multiple of heads"),
            ("lambda_blc", lambda_blc >= 0, ">= 0"),
            ("p_major", 0 <= p_major < 1, "in [0, 1)"),
            ("p_other", 0 <= p_other < 1, "in [0, 1)"),
            ("chunk", chunk > 0, "> 0"),
            ("kernel_size", kernel_size % 2 == 1, "odd"),
            ("xca", xca in XCA_SCOPES, f"one of {', '.join(XCA_SCOPES)}"),
        )
        for name, ok, what in checks:
            if not ok:
                raise SkelagnosticError(f"model.{name} must be {what}, got {locals()[name]!r}")
        optimizer, scheduler = check_specs(optimizer, scheduler)
        self.save_hyperparameters()
        self.net = HuMoT(
            HuMoTConfig(
                dim, latent, blocks, heads, kernel_size, mlp_ratio, layer_scale, fast_path, xca
            )
        )
        self._topologies: dict[tuple[Any, ...], Topology] = {}

    # ----------------------------------------------------------------- topology
    def topology(self, skeleton: Skeleton) -> Topology:
        """The cached :class:`~skelagnostic_humot.data.Topology` of ``skeleton``."""
        key = skeleton.topology_key()
        if key not in self._topologies:
            self._topologies[key] = Topology.of(skeleton)
        return self._topologies[key]

    # ------------------------------------------------------------------ losses
    def chunk_loss(
        self,
        world: torch.Tensor,
        topology: Topology,
        up_axis: str = "y",
        subsample: bool | None = None,
    ) -> dict[str, torch.Tensor]:
        """Losses of a batch of chunks of one topology.

        Args:
            world: ``[B, F, J, 3]`` world positions in metres.
            topology: Their topology.
            up_axis: Up axis of ``world``.
            subsample: Stochastic joint subsampling (default: the ``subsampling``
                hyper-parameter in training, off in evaluation).

        Returns:
            ``loss``, ``rec``, ``blc`` and ``mpjpe`` (metres, on the decoded joints).
        """
        pos, tmpl = prepare_chunks(world.float(), topology, up_axis)
        if subsample is None:
            subsample = self.hparams.subsampling and self.training
        if subsample:
            major = topology.major
            s1 = gather_subset(
                sample_keep(major, len(pos), self.hparams.p_major, self.hparams.p_other),
                topology.skeleton.parents,
            )
            s2 = gather_subset(
                sample_keep(major, len(pos), self.hparams.p_major, self.hparams.p_other),
                topology.skeleton.parents,
            )
            pred = self.net(
                s1.take(pos, 2),
                s1.take(tmpl, 1),
                s2.take(tmpl, 1),
                s1.mask.to(pos.device),
                s2.mask.to(pos.device),
            )
            target, mask = s2.take(pos, 2), s2.mask.to(pos.device)
            bones, bone_mask = s2.bones.to(pos.device), s2.bone_mask.to(pos.device)
        else:
            pred = self.net(pos, tmpl, tmpl)
            target, mask, bone_mask = pos, None, None
            bones = torch.tensor(topology.skeleton.bones(), device=pos.device).expand(
                len(pos), -1, -1
            )
        rec = reconstruction_loss(pred, target, mask)
        blc = bone_length_consistency_loss(pred, target, bones, bone_mask)
        err = (pred - target).norm(dim=-1)
        if mask is None:
            mpjpe = err.mean()
        else:
            m = mask[:, None].to(err.dtype).expand_as(err)
            mpjpe = (err * m).sum() / m.sum()
        return {"loss": rec + self.hparams.lambda_blc * blc, "rec": rec, "blc": blc, "mpjpe": mpjpe}

    def _step(self, batch: dict[str, Any], stage: str) -> torch.Tensor:
        parts = {n: b for n, b in batch.items() if b is not None}
        skeletons = [batch_skeleton(b, n) for n, b in parts.items()]
        out = [
            self.chunk_loss(b["features"], self.topology(sk), sk.up_axis)
            for b, sk in zip(parts.values(), skeletons, strict=True)
        ]
        size = sum(len(b["features"]) for b in parts.values())
        metrics = {k: torch.stack([o[k] for o in out]).mean() for k in out[0]}
        sync = stage != "train"
        self.log(f"{stage}/loss", metrics["loss"], prog_bar=True, batch_size=size, sync_dist=sync)
        for key in ("rec", "blc"):
            self.log(f"{stage}/{key}", metrics[key], batch_size=size, sync_dist=sync)
        self.log(f"{stage}/mpjpe_cm", 100 * metrics["mpjpe"], batch_size=size, sync_dist=sync)
        return metrics["loss"]

    # --------------------------------------------------------------- lightning
    def training_step(self, batch: dict[str, Any], batch_idx: int) -> torch.Tensor:
        """Mean over topologies of ``L_rec + lambda_blc * L_blc`` with joint subsampling."""
        return self._step(batch, "train")

    def validation_step(self, batch: dict[str, Any], batch_idx: int) -> torch.Tensor:
        """Full-skeleton reconstruction losses and MPJPE (cm): ``val/loss``, ``val/mpjpe_cm``."""
        return self._step(batch, "val")

    def test_step(self, batch: dict[str, Any], batch_idx: int) -> torch.Tensor:
        """As :meth:`validation_step`, logged under ``test/``."""
        return self._step(batch, "test")

    def predict_step(
        self, batch: dict[str, Any], batch_idx: int, dataloader_idx: int = 0
    ) -> dict[str, torch.Tensor]:
        """Per dataset, the latent codes ``[B, F, Z]`` of the (full-skeleton) chunks."""
        out = {}
        for name, b in batch.items():
            skeleton = batch_skeleton(b, name)
            pos, tmpl = prepare_chunks(
                b["features"].float(), self.topology(skeleton), skeleton.up_axis
            )
            out[name] = self.net.encoder(pos, tmpl)
        return out

    def configure_optimizers(self) -> Any:
        """``model.optimizer`` and ``model.scheduler`` (the paper's: Adam, cyclic rate per step)."""
        hp = self.hparams
        return configure_optimization(hp.optimizer, hp.scheduler, self.parameters(), self._trainer)

    @torch.no_grad()
    def render_sample(self, batch: dict[str, Any]) -> dict[str, Any]:
        """Input chunk, its reconstruction and its retargeting to another topology.

        The first dataset of ``batch`` gives the chunk; the retargeting goes to the
        skeleton of the next dataset in ``batch`` (none with one dataset).
        """
        from skelagnostic.viz import StickFigure

        parts = {n: b for n, b in batch.items() if b is not None}
        (src, first), others = next(iter(parts.items())), [n for n in parts][1:]
        source = batch_skeleton(first, src)
        topo = self.topology(source)
        pos, tmpl = prepare_chunks(first["features"][:1].float(), topo, source.up_axis)
        z = self.net.encoder(pos, tmpl)
        figs = {"input": (pos[0], topo), "reconstruction": (self.net.decoder(z, tmpl)[0], topo)}
        if others:
            dst = self.topology(batch_skeleton(parts[others[0]], others[0]))
            dst_tmpl = dst.templates(dst.skeleton.bone_lengths().float())[None].to(z)
            figs[f"retarget -> {others[0]}"] = (self.net.decoder(z, dst_tmpl)[0], dst)
        fps = float(first["fps"])
        return {
            k: StickFigure(
                p.cpu(), t.skeleton.parents, t.skeleton.body_groups, fps=fps, name=k, up_axis="z"
            )
            for k, (p, t) in figs.items()
        }

    def fit_summary(self, trainer: L.Trainer) -> SummaryContent:
        """The render of the fit summary: ``humot_retarget.gif`` / ``.png``.

        A validation chunk (input; a training chunk without validation data),
        its reconstruction and its retargeting onto another topology of the
        data, side by side (see :meth:`render_sample`, given the first window of
        every dataset: of its validation split, else of its training split).
        """
        dm = trainer.datamodule
        split = "val" if dm.datasets["val"] else "train"
        first = next(iter(dm.datasets[split]))
        batch = {}
        for name in [first, *(n for n in dm.datasets["train"] if n != first)]:
            dataset = dm.datasets["val" if name in dm.datasets["val"] else "train"][name]
            window = dm.collate(name)([dataset[0]])
            batch[name] = {**window, "features": window["features"].to(self.device)}
        return {"renders": {"retarget": list(self.render_sample(batch).values())}}

    # ------------------------------------------------------------------- export
    def export_graphs(self) -> list[ExportGraph]:
        """HuMoT's encoder and decoder, with the skeleton template as an input.

        Both take any batch, frame and joint count (the XCiT blocks attend over
        channels, the convolutions pad in time, the frame encoding is computed
        from the frame count). Padding masks are not exported: give one skeleton
        per batch.
        """
        from skelagnostic_humot.template import _TO_MODEL

        hp = self.hparams
        motion, template = torch.randn(2, 9, 5, 3), torch.randn(2, 5, 3)
        z = torch.randn(2, 9, hp.latent)
        meta = {
            "units": "m",
            "fps": 30.0,
            "chunk_frames": int(hp.chunk),
            "model_frame": {
                "description": "Z up, X the character's left, Y backward; "
                "model = positions @ matrix.T",
                "matrix_from_up_axis": {k: v for k, v in _TO_MODEL.items()},
            },
            "preprocess": (
                "resample to 30 fps, convert to metres, rotate to the model frame, cut into "
                f"{int(hp.chunk)}-frame chunks every {int(hp.chunk) // 2} frames, subtract from "
                "every chunk the mean of its major joints (hips, knees, ankles, shoulders, "
                "elbows, wrists; all joints if none) over all its frames"
            ),
            "template": (
                "[J, 3] neutral pose in the model frame, root at the origin, with the clip's "
                "median bone lengths: skelagnostic_humot.data.Topology.of(skeleton)"
                ".templates(lengths)"
            ),
            "postprocess": (
                "add the chunk centres back (scaled by the target/source leg-length ratio), "
                "cross-fade overlapping chunks with triangular weights, rotate back from the "
                "model frame; inverse kinematics gives rotations"
            ),
        }
        return [
            ExportGraph(
                "encoder",
                Method(self.net.encoder, "forward"),
                (motion, template),
                ("motion", "template"),
                ("z",),
                {
                    "motion": {0: "batch", 1: "time", 2: "joints"},
                    "template": {0: "batch", 1: "joints"},
                    "z": {0: "batch", 1: "time"},
                },
                description="E(X | T): centred joint positions [B, F, J, 3] (metres, model "
                "frame) and the source template [B, J, 3] -> latent [B, F, Z]",
                metadata=meta,
            ),
            ExportGraph(
                "decoder",
                Method(self.net.decoder, "forward"),
                (z, template),
                ("z", "template"),
                ("motion",),
                {
                    "z": {0: "batch", 1: "time"},
                    "template": {0: "batch", 1: "joints"},
                    "motion": {0: "batch", 1: "time", 2: "joints"},
                },
                description="D(z | T): latent [B, F, Z] and a target template [B, J, 3] -> "
                "centred joint positions [B, F, J, 3] of the target skeleton",
                metadata=meta,
            ),
        ]

    # ------------------------------------------------------------------ aligner
    def _motion_positions(self, motion: Motion, units: str | None) -> torch.Tensor:
        """``[T, J, 3]`` positions of the motion at 30 fps, in metres, model frame."""
        motion = motion.to_metres(units)
        if motion.fps != 30.0:
            motion = motion.resample(30.0)
        return to_model_frame(motion.global_positions().float(), motion.skeleton.up_axis)

    @torch.no_grad()
    def encode_positions(self, positions: torch.Tensor, skeleton: Skeleton) -> Latent:
        """Encode ``[T, J, 3]`` positions (metres, model frame, 30 fps) of ``skeleton``.

        Returns:
            A :class:`~skelagnostic.aligners.Latent` whose ``z`` is ``[C, chunk, Z]`` (one
            latent sequence per chunk); extras: ``starts`` ``[C]``, ``centres`` ``[C, 3]``
            (removed chunk means, model frame, metres), ``num_frames``, ``leg_length``
            (source template, metres).
        """
        topo = self.topology(skeleton)
        frames = positions.shape[0]
        chunk = min(self.hparams.chunk, frames)
        starts = _chunk_starts(frames, chunk, max(1, chunk // 2))
        world = torch.stack([positions[s : s + chunk] for s in starts]).to(self.device)
        major = topo.major.to(world.device)
        ref = world[:, :, major] if bool(major.any()) else world
        centres = ref.mean(dim=(1, 2))
        parents = topo.parents.to(world.device)
        # one template for the whole motion: the clip's median bone lengths (App. A.2)
        lengths = (positions - positions[:, parents.cpu()]).norm(dim=-1).median(dim=0).values
        tmpl = topo.templates(lengths.to(world))
        z = self.net.encoder(world - centres[:, None, None], tmpl.expand(len(starts), -1, -1))
        return Latent(
            z.cpu(),
            30.0,
            {
                "starts": torch.tensor(starts),
                "centres": centres.cpu(),
                "num_frames": torch.tensor(frames),
                "leg_length": torch.tensor(leg_length(tmpl.cpu(), skeleton)),
            },
        )

    @torch.no_grad()
    def decode_positions(
        self, latent: Latent, skeleton: Skeleton, lengths: torch.Tensor | None = None
    ) -> torch.Tensor:
        """Decode to ``[T, J, 3]`` positions (metres, model frame) of ``skeleton``.

        Args:
            latent: Output of :meth:`encode_positions` / :meth:`encode`.
            skeleton: Target skeleton.
            lengths: ``[J]`` target bone lengths in metres (default: the skeleton's
                offsets, assumed in metres).

        Returns:
            Positions; the chunk centres are scaled by the target/source leg-length ratio.
        """
        topo = self.topology(skeleton)
        if lengths is None:
            lengths = skeleton.bone_lengths()
        tmpl = topo.templates(lengths.float()).to(self.device)
        z = latent.z.to(self.device)
        out = self.net.decoder(z, tmpl.expand(len(z), -1, -1))
        src_leg = float(latent.extras["leg_length"])
        dst_leg = leg_length(tmpl.cpu(), skeleton)
        ratio = dst_leg / src_leg if src_leg > 0 and dst_leg > 0 else 1.0
        out = out + (latent.extras["centres"].to(out) * ratio)[:, None, None]
        frames = int(latent.extras["num_frames"])
        chunk = out.shape[1]
        ramp = torch.arange(chunk, dtype=out.dtype, device=out.device)
        weight = torch.minimum(ramp + 1, chunk - ramp)
        acc = out.new_zeros(frames, out.shape[2], 3)
        total = out.new_zeros(frames, 1, 1)
        for c, s in enumerate(latent.extras["starts"].tolist()):
            acc[s : s + chunk] += weight[:, None, None] * out[c]
            total[s : s + chunk] += weight[:, None, None]
        return (acc / total).cpu()

    def encode(self, motion: Motion, units: str | None = None) -> Latent:
        """Encode a motion of a human skeleton (any length, fps and unit).

        Args:
            motion: The motion.
            units: Its length unit (default: ``motion.units``, else guessed with
                :func:`infer_units`).

        Returns:
            The latent (see :meth:`encode_positions`), at 30 fps.
        """
        return self.encode_positions(self._motion_positions(motion, units), motion.skeleton)

    def decode(self, latent: Latent, skeleton: Skeleton, units: str | None = None) -> Motion:
        """Decode onto ``skeleton`` and fit rotations (see the module notes).

        Args:
            latent: A latent of :meth:`encode`.
            skeleton: The target skeleton; its bone lengths define the template.
            units: Length unit of ``skeleton`` (default: guessed with :func:`infer_units`).

        Returns:
            A 30 fps motion on ``skeleton`` in the skeleton's units.
        """
        scale = UNITS[infer_units(skeleton, units)]
        pos = self.decode_positions(latent, skeleton, skeleton.bone_lengths() * scale)
        pos = from_model_frame(pos.double(), skeleton.up_axis) / scale
        rotations, root = inverse_kinematics(pos, skeleton)
        return Motion(skeleton, rotations, root, latent.fps)

    def retarget(
        self,
        motion: Motion,
        target: Skeleton,
        source_units: str | None = None,
        target_units: str | None = None,
    ) -> Motion:
        """Encode with the source template, decode with the target's (Sec. 4.2).

        The root trajectory (chunk centres) is scaled by the leg-length ratio.
        Write the result with :func:`skelagnostic.write_bvh`.
        """
        self.require("retarget")
        return self.decode(self.encode(motion, source_units), target, target_units)

    def denoise(self, motion: Motion, units: str | None = None) -> Motion:
        """Encode and decode on the motion's own skeleton (Sec. 4.3)."""
        return self.decode(self.encode(motion, units), motion.skeleton, units)

    def upsample_joints(self, motion: Motion, full: Skeleton, units: str | None = None) -> Motion:
        """Motion of a joint subset of ``full`` -> motion of ``full`` (Sec. 4.4).

        Args:
            motion: Motion on a skeleton whose joints are a subset of ``full``'s
                (e.g. ``full.subset(names)``).
            full: The complete skeleton.
            units: Length unit of both.

        Raises:
            SkelagnosticError: ``motion``'s joints are not all in ``full``.
        """
        missing = set(motion.skeleton.joint_names) - set(full.joint_names)
        if missing:
            raise SkelagnosticError(
                f"motion: joints {sorted(missing)} are not in the full skeleton"
            )
        return self.decode(self.encode(motion, units), full, units)
