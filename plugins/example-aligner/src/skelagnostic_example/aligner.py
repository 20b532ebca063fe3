"""The example aligner: a topology-agnostic per-joint GRU autoencoder over root-local positions.

Encoder: each joint's root-local position and its template (rest) position,
both divided by the skeleton height, go through a shared MLP; a mean and a max
over joints make the frame feature independent of the joint count and order;
a GRU over time gives a per-frame latent ``z``. Decoder: ``z`` and each target
joint's template position go through a shared MLP that outputs that joint's
root-local position. Any skeleton can be encoded or decoded, so retargeting is
"encode with the source skeleton, decode with the target's template"; the root
trajectory travels outside the latent, scaled by the height ratio. Positions
become rotations by inverse kinematics (no bone twist).
"""

from __future__ import annotations

from itertools import pairwise
from types import MappingProxyType
from typing import Any, ClassVar

import torch
from torch import nn

from skelagnostic.aligners import Aligner, Latent, batch_skeleton
from skelagnostic.aligners.export import ExportGraph, Method
from skelagnostic.aligners.optim import OptimizerSpec, check_specs, configure_optimization
from skelagnostic.core import quaternion as Q
from skelagnostic.core.motion import Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.data import MotionDataModule
from skelagnostic.errors import MotionError
from skelagnostic.representations import GlobalPositions, MotionRepresentation, inverse_kinematics


class ExampleDataModule(MotionDataModule):
    """Windows of root-local joint positions (``GlobalPositions(frame="root")``)."""

    def default_representation(self) -> MotionRepresentation:
        """Root-local joint positions."""
        return GlobalPositions(frame="root")


def _mlp(sizes: list[int]) -> nn.Sequential:
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(pairwise(sizes)):
        layers.append(nn.Linear(a, b))
        if i < len(sizes) - 2:
            layers.append(nn.ELU())
    return nn.Sequential(*layers)


#: Adam at 3e-3: what ``model.optimizer`` defaults to (``conf/example.yaml`` says the same).
OPTIMIZER = MappingProxyType({"_target_": "torch.optim.Adam", "_partial_": True, "lr": 3e-3})


class ExampleAligner(Aligner):
    """Per-joint MLP + GRU autoencoder with a topology-agnostic per-frame latent.

    Args:
        hidden: Width of the joint MLPs and the GRU.
        latent: Size of the per-frame latent.
        optimizer: ``model.optimizer``: a ``_partial_`` spec or a callable taking the
            parameters (:mod:`skelagnostic.aligners.optim`); Adam at 3e-3 by default.
        scheduler: ``model.scheduler`` (``None``: a constant rate).
    """

    capabilities: ClassVar[frozenset[str]] = frozenset(
        {"encode", "decode", "retarget", "unseen_topology", "quadruped"}
    )

    def __init__(
        self,
        hidden: int = 64,
        latent: int = 16,
        optimizer: OptimizerSpec = OPTIMIZER,
        scheduler: OptimizerSpec | None = None,
    ) -> None:
        super().__init__()
        optimizer, scheduler = check_specs(optimizer, scheduler)  # a wrong key fails here
        self.save_hyperparameters()
        self.joint_encoder = _mlp([6, hidden, hidden])
        self.temporal = nn.GRU(2 * hidden, hidden, batch_first=True)
        self.to_latent = nn.Linear(hidden, latent)
        self.joint_decoder = _mlp([latent + 3, hidden, hidden, 3])

    # ------------------------------------------------------------------ network
    def encode_positions(self, positions: torch.Tensor, template: torch.Tensor) -> torch.Tensor:
        """``[B, T, J, 3]`` height-normalised root-local positions -> ``[B, T, latent]``."""
        frames = positions.shape[1]
        tmpl = template.unsqueeze(1).expand(-1, frames, -1, -1)
        h = self.joint_encoder(torch.cat([positions, tmpl], dim=-1))
        pooled = torch.cat([h.mean(dim=2), h.amax(dim=2)], dim=-1)
        out, _ = self.temporal(pooled)
        return self.to_latent(out)

    def decode_positions(self, z: torch.Tensor, template: torch.Tensor) -> torch.Tensor:
        """``[B, T, latent]`` and a ``[B, J, 3]`` template -> ``[B, T, J, 3]`` positions."""
        b, t, d = z.shape
        j = template.shape[1]
        x = torch.cat(
            [z.unsqueeze(2).expand(b, t, j, d), template.unsqueeze(1).expand(b, t, j, 3)], dim=-1
        )
        return self.joint_decoder(x)

    def _loss(self, batch: dict[str, torch.Tensor]) -> torch.Tensor:
        scale = batch["height"].view(-1, 1, 1, 1)
        pos = batch["features"] / scale
        template = batch["template"] / scale[:, 0]
        rec = self.decode_positions(self.encode_positions(pos, template), template)
        return nn.functional.mse_loss(rec, pos)

    # ---------------------------------------------------------------- lightning
    def training_step(self, batch: dict[str, Any], batch_idx: int) -> torch.Tensor:
        """Mean reconstruction loss over the datasets of the step."""
        loss = torch.stack([self._loss(b) for b in batch.values()]).mean()
        self.log(
            "train/loss",
            loss,
            prog_bar=True,
            batch_size=sum(len(b["features"]) for b in batch.values()),
        )
        return loss

    def _evaluate(self, batch: dict[str, Any], stage: str) -> torch.Tensor:
        parts = {name: b for name, b in batch.items() if b is not None}
        loss = torch.stack([self._loss(b) for b in parts.values()]).mean()
        size = sum(len(b["features"]) for b in parts.values())
        self.log(f"{stage}/loss", loss, prog_bar=True, batch_size=size, sync_dist=True)
        return loss

    def validation_step(self, batch: dict[str, Any], batch_idx: int) -> torch.Tensor:
        """Logs ``val/loss``."""
        return self._evaluate(batch, "val")

    def test_step(self, batch: dict[str, Any], batch_idx: int) -> torch.Tensor:
        """Logs ``test/loss``."""
        return self._evaluate(batch, "test")

    def predict_step(
        self, batch: dict[str, Any], batch_idx: int, dataloader_idx: int = 0
    ) -> dict[str, torch.Tensor]:
        """Per dataset, the per-frame latents ``[B, T, latent]`` of the windows."""
        out = {}
        for name, b in batch.items():
            scale = b["height"].view(-1, 1, 1, 1)
            out[name] = self.encode_positions(b["features"] / scale, b["template"] / scale[:, 0])
        return out

    @torch.no_grad()
    def render_sample(self, batch: dict[str, Any]) -> dict[str, Motion]:
        """Input and reconstruction of the first window (for ``callbacks=render``).

        The batch carries its dataset's skeleton and frame rate (``skeleton``,
        ``fps``); the window's own bone lengths are its ``offsets``.
        """
        name, b = next((n, b) for n, b in batch.items() if b is not None)
        base = batch_skeleton(b, name)
        skeleton = Skeleton(
            base.joint_names,
            base.parents,
            b["offsets"][0].cpu(),
            up_axis=base.up_axis,
            morphology=base.morphology,
        )
        scale = b["height"][:1].view(-1, 1, 1, 1)
        template = b["template"][:1] / scale[:, 0]
        rec = (
            self.decode_positions(
                self.encode_positions(b["features"][:1] / scale, template), template
            )
            * scale
        )
        rep, fps = GlobalPositions(frame="root"), float(b["fps"])
        return {
            "input": rep.decode(b["features"][0].double().cpu(), skeleton, fps),
            "output": rep.decode(rec[0].double().cpu(), skeleton, fps),
        }

    def configure_optimizers(self) -> Any:
        """``model.optimizer`` and ``model.scheduler``."""
        hp = self.hparams
        return configure_optimization(hp.optimizer, hp.scheduler, self.parameters(), self._trainer)

    # ------------------------------------------------------------------- export
    def export_graphs(self) -> list[ExportGraph]:
        """The encoder and the decoder, each over any batch, frame and joint count.

        This is the pattern for a third-party aligner: wrap the tensor-only
        methods with :class:`~skelagnostic.aligners.export.Method`, give example inputs
        whose dynamic axes have distinct sizes, name every input and output,
        and describe in ``metadata`` what the runtime does before and after.
        """
        hp = self.hparams
        positions, template = torch.randn(2, 7, 5, 3), torch.randn(2, 5, 3)
        z = torch.randn(2, 7, hp.latent)
        prepare = (
            "positions: GlobalPositions(frame='root') of the motion (root-local joint "
            "positions), divided by the skeleton height (Skeleton.height); template: "
            "Skeleton.template() divided by the same height"
        )
        common = {
            "representation": "GlobalPositions(frame='root')",
            "normalisation": {"divide_by": "skeleton height (Skeleton.height)"},
            "skeleton": "any: the template is an input",
            "preprocess": prepare,
        }
        return [
            ExportGraph(
                "encoder",
                Method(self, "encode_positions"),
                (positions, template),
                ("positions", "template"),
                ("z",),
                {
                    "positions": {0: "batch", 1: "time", 2: "joints"},
                    "template": {0: "batch", 1: "joints"},
                    "z": {0: "batch", 1: "time"},
                },
                description="height-normalised root-local positions and the skeleton "
                "template -> per-frame latent",
                metadata=common,
            ),
            ExportGraph(
                "decoder",
                Method(self, "decode_positions"),
                (z, template),
                ("z", "template"),
                ("positions",),
                {
                    "z": {0: "batch", 1: "time"},
                    "template": {0: "batch", 1: "joints"},
                    "positions": {0: "batch", 1: "time", 2: "joints"},
                },
                description="per-frame latent and a target template -> height-normalised "
                "root-local positions of the target's joints",
                metadata={
                    **common,
                    "postprocess": "multiply by the target skeleton height; "
                    "inverse kinematics gives rotations",
                },
            ),
        ]

    # ------------------------------------------------------------------ aligner
    @torch.no_grad()
    def encode(self, motion: Motion) -> Latent:
        """Per-frame latent ``[T, latent]``; extras: root path, facing, height."""
        height = _height(motion.skeleton)
        pos = GlobalPositions(frame="root").encode(motion).float() / height
        template = motion.skeleton.template().float() / height
        z = self.encode_positions(pos[None].to(self.device), template[None].to(self.device))[0]
        return Latent(
            z.cpu(),
            motion.fps,
            {
                "root_positions": motion.root_positions.float(),
                "facing": motion.facing().float(),
                "height": torch.tensor(height),
                "up": torch.tensor(motion.skeleton.up_index),
            },
        )

    @torch.no_grad()
    def decode(self, latent: Latent, skeleton: Skeleton) -> Motion:
        """Positions from the latent and ``skeleton``'s template, then inverse kinematics.

        With the encoder's extras the motion follows the source root path (scaled
        by the height ratio) and heading; without them the root stays above the origin.
        """
        height = _height(skeleton)
        template = skeleton.template().float() / height
        z = latent.z.to(self.device)
        local = self.decode_positions(z[None], template[None].to(self.device))[0].cpu() * height
        centre = local[:, :1].clone()  # the root sits on the root-local up axis by definition
        centre[..., skeleton.up_index] = 0.0
        local = local - centre
        if "root_positions" in latent.extras:
            up = int(latent.extras["up"])
            ground = latent.extras["root_positions"].clone() * (
                height / float(latent.extras["height"])
            )
            ground[:, up] = 0.0
            world = Q.rotate(latent.extras["facing"].unsqueeze(1), local) + ground.unsqueeze(1)
        else:
            world = local
        rotations, root = inverse_kinematics(world.double(), skeleton)
        return Motion(skeleton, rotations, root, latent.fps)


def _height(skeleton: Skeleton) -> float:
    """The skeleton height the positions are divided by.

    Raises:
        MotionError: The skeleton has height 0 (one joint, or every bone of zero length).
    """
    height = skeleton.height()
    if height <= 0:
        raise MotionError(
            f"model=example: skeleton {skeleton.name or ''!r} has height 0 "
            f"({skeleton.num_joints} joint(s), no bone of non-zero length); the example "
            "aligner normalises positions by the skeleton height"
        )
    return height
