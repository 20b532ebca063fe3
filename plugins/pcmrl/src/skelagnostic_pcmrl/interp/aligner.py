"""PC-MRL stage 2: :class:`PcmrlInterpAligner`, the interpolation model as an aligner.

Training and validation steps, the loss, ``interpolate(motion, keyframes)``
and the export graphs. See :mod:`~skelagnostic_pcmrl.interp` for the model as
a whole.
"""

from __future__ import annotations

import itertools
import logging
import math
from collections.abc import Mapping, Sequence
from types import MappingProxyType
from typing import Any, ClassVar

import torch
from torch import Tensor

from skelagnostic.aligners.base import Aligner, Latent, batch_skeleton
from skelagnostic.aligners.export import ExportGraph, Method
from skelagnostic.aligners.optim import OptimizerSpec, check_specs, configure_optimization
from skelagnostic.core import quaternion as Q
from skelagnostic.core.kinematics import fk_from_global, global_from_local, local_from_global
from skelagnostic.core.motion import Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.errors import MotionError, SkelagnosticError
from skelagnostic_pcmrl.interp.keyframes import sign_invariant_l1, window_features, window_heading
from skelagnostic_pcmrl.interp.network import CITLInterpolator
from skelagnostic_pcmrl.interp.rpa import bone_tails
from skelagnostic_pcmrl.layouts import LAYOUTS
from skelagnostic_pcmrl.points import group_of_joints

log = logging.getLogger(__name__)


#: The paper's optimizer: rate 1e-4; AdamW without decay, as the authors' Adam.
PAPER_OPTIMIZER = MappingProxyType(
    {"_target_": "torch.optim.AdamW", "_partial_": True, "lr": 1e-4, "weight_decay": 0.0}
)
#: The paper's schedule: a 10,000-step linear warm-up (then constant here).
PAPER_SCHEDULER = MappingProxyType(
    {"_target_": "skelagnostic.aligners.optim.linear_warmup", "_partial_": True, "steps": 10000}
)


class PcmrlInterpAligner(Aligner):
    """PC-MRL's interpolation model on one target skeleton (capability ``"interpolate"``).

    The network is built in :meth:`setup` from the data module's target skeleton
    (or from ``skeleton=`` / a checkpoint). Training batches come from
    :class:`~skelagnostic_pcmrl.interp.data.PcmrlInterpDataModule`.

    Args:
        dim: Transformer width (paper 512).
        heads: Attention heads (paper 8).
        layers: Blocks per stage (paper 6).
        ff_mult: Feed-forward expansion.
        max_relative: Clip distance of the relative positions.
        residual: Predict the FOQ/root as an additive correction of the LERP baseline
            (root LERP and local-rotation SLERP between the keys, expressed as FOQ;
            output layer zero-initialised, so the untrained model IS the baseline)
            instead of directly (paper: direct). A CPU option: the network only has
            to learn what interpolation misses, which a few thousand steps can do.
        residual_space: Where the ``residual`` correction is added: ``"foq"`` (to the
            baseline's FOQ, i.e. global rotations) or ``"local"`` (not in the paper: to
            the SLERPed local rotations, turned into FOQ by FK, so that a correction such
            as a knee bend does not depend on the heading or on the parents' pose). The
            output and the loss stay FOQ.
        interm_tokens: How CITL's intermediate tokens start: ``"zero"`` (CITL and the
            paper: zero tokens that learn where they are only through the relative
            positions) or ``"lerp"`` (not in the paper): an embedding of the
            LERP/SLERP baseline pose of the frame and its place in its gap
            (:func:`window_features` with ``interm=True``), as the two-stage
            transformers of Qin et al. 2022 start from interpolated frames.
        canonical_heading: Turn every window about the up axis so that its first
            frame faces a fixed direction (:func:`window_heading`), predict there and
            turn the result back (not in the paper; off by default). Makes the
            model exactly heading-equivariant, so it need not learn every heading
            from data; in measured 15-minute CPU runs it did not change the result.
        optimizer: ``model.optimizer``, a ``_partial_`` spec or a callable taking the
            parameters (:mod:`skelagnostic.aligners.optim`): AdamW with ``lr`` 1e-4 (the
            paper's) and ``weight_decay`` 0 (the authors' ``train_inpainter.py`` uses
            Adam, without decay).
        scheduler: ``model.scheduler``: a linear warm-up over ``steps`` = 10000 (the
            paper's; :func:`~skelagnostic.aligners.optim.linear_warmup`). The rate then
            stays at ``lr``; the authors' decays linearly to 0 at the last step.
        w_root: Weight of L1(root).
        w_foq: Weight of L1(FOQ).
        w_fk: Weight of L1(FK positions) (paper 0.1).
        w_quat: Weight of L1(global quaternions) (paper 0.1).
        skeleton: Target skeleton as :meth:`Skeleton.to_dict` (set by :meth:`setup`).
        fps: Frame rate of the training data (set by :meth:`setup`).
        window: Training window length (set by :meth:`setup`; long clips are split
            into chunks of at most this many frames by :meth:`interpolate`).
        layout: ``"skelagnostic"`` (pre-norm blocks) or ``"authors"`` (the blocks of the
            authors' CITL: post-norm with masked norms, every frame attending to itself,
            :class:`~skelagnostic_pcmrl.interp.network.CITLInterpolator`).
        fast_path: Run the keyframe encoder on the keyframe tokens only (default): the
            same values and gradients as ``False`` (the reference network, which
            encodes every frame) up to rounding, in less time; no parameter changes, so
            checkpoints load either way. The ``"authors"`` layout always takes the
            reference path.

    Raises:
        SkelagnosticError: An option is out of range.
    """

    capabilities: ClassVar[frozenset[str]] = frozenset({"interpolate"})

    def __init__(
        self,
        dim: int = 512,
        heads: int = 8,
        layers: int = 6,
        ff_mult: int = 4,
        max_relative: int = 128,
        residual: bool = False,
        residual_space: str = "foq",
        interm_tokens: str = "zero",
        canonical_heading: bool = False,
        optimizer: OptimizerSpec = PAPER_OPTIMIZER,
        scheduler: OptimizerSpec | None = PAPER_SCHEDULER,
        w_root: float = 1.0,
        w_foq: float = 1.0,
        w_fk: float = 0.1,
        w_quat: float = 0.1,
        skeleton: Mapping[str, Any] | None = None,
        fps: float | None = None,
        window: int = 128,
        layout: str = "skelagnostic",
        fast_path: bool = True,
    ) -> None:
        super().__init__()
        for arg, value in (
            ("dim", dim),
            ("heads", heads),
            ("layers", layers),
            ("ff_mult", ff_mult),
            ("max_relative", max_relative),
            ("window", window),
        ):
            if value <= 0:
                raise SkelagnosticError(f"model.{arg} must be positive, got {value}")
        optimizer, scheduler = check_specs(optimizer, scheduler)
        if residual_space not in ("foq", "local"):
            raise SkelagnosticError(
                f"model.residual_space must be 'foq' or 'local', got {residual_space!r}"
            )
        if layout not in LAYOUTS:
            raise SkelagnosticError(
                f"model.layout must be one of {', '.join(LAYOUTS)}, got {layout!r}"
            )
        if interm_tokens not in ("zero", "lerp"):
            raise SkelagnosticError(
                f"model.interm_tokens must be 'zero' or 'lerp', got {interm_tokens!r}"
            )
        self.save_hyperparameters()
        self.net: CITLInterpolator | None = None
        self.skeleton: Skeleton | None = None
        if skeleton is not None:
            self._build(Skeleton.from_dict(dict(skeleton)))

    # ------------------------------------------------------------------ building
    def _build(self, skeleton: Skeleton) -> None:
        hp = self.hparams
        self.skeleton = skeleton
        num_j = skeleton.num_joints
        self.parents = list(skeleton.parents)
        self.register_buffer("tails", bone_tails(skeleton).tails.float(), persistent=False)
        self.register_buffer("groups", group_of_joints(skeleton), persistent=False)
        interm = 10 * num_j + 3 if hp.interm_tokens == "lerp" else 0
        self.net = CITLInterpolator(
            10 * num_j + 1,
            4 * num_j + 3,
            hp.dim,
            hp.heads,
            hp.layers,
            hp.ff_mult,
            hp.max_relative,
            zero_output=hp.residual,
            interm_features=interm,
            layout=hp.get("layout", "skelagnostic"),
            fast_path=bool(hp.get("fast_path", True)),
        )

    def features(
        self, global_rotations: Tensor, root: Tensor, offsets: Tensor, tails: Tensor, keys: Tensor
    ) -> dict[str, Tensor]:
        """:func:`window_features` with what this model's options need (nothing more)."""
        hp = self.hparams
        return window_features(
            global_rotations,
            root,
            offsets,
            tails,
            keys,
            self.parents,
            baseline=bool(hp.residual),
            interm=hp.interm_tokens == "lerp",
            max_relative=int(hp.max_relative),
        )

    def configure_model(self) -> None:
        """Build the network from the data module's target skeleton (:meth:`stage_datamodule`)."""
        if self.net is not None:  # built already, or from a checkpoint's hyperparameters
            return
        dm = self.stage_datamodule()
        if dm is None:
            self._require_net()  # no data module to build from: say what to pass
        skeleton = dm.skeleton
        self.hparams["skeleton"] = skeleton.to_dict()
        self.hparams["fps"] = float(dm.fps)
        self.hparams["window"] = int(dm.window)
        self._build(skeleton)

    def canonical(
        self, global_rotations: Tensor, root: Tensor, offsets: Tensor
    ) -> tuple[Tensor, Tensor, Tensor]:
        """Windows turned into the heading-free frame (``canonical_heading``).

        Args:
            global_rotations: ``[B, T, J, 4]``.
            root: ``[B, T, 3]``.
            offsets: ``[B, J, 3]`` rest offsets.

        Returns:
            ``(global_rotations, root, turn [B, 4])``: the turned window and the
            rotation that turns it back (the identity when the option is off).
        """
        self._require_net()
        if not self.hparams.canonical_heading:
            turn = Q.identity(root.shape[0], dtype=root.dtype, device=root.device)
            return global_rotations, root, turn
        assert self.skeleton is not None  # built together with the network
        turn = window_heading(
            global_rotations, root, offsets, self.groups, self.parents, self.skeleton.up_index
        )
        back = Q.inv(turn)
        return Q.mul(back[:, None, None], global_rotations), Q.rotate(back[:, None], root), turn

    def _require_net(self) -> CITLInterpolator:
        if self.net is None:
            raise SkelagnosticError(
                "PcmrlInterpAligner has no skeleton yet: train it, load a checkpoint or pass "
                "skeleton="
            )
        return self.net

    # ------------------------------------------------------------------ network
    def predict_window(self, feats: Mapping[str, Tensor], keys: Tensor) -> dict[str, Tensor]:
        """Run the network on :func:`window_features` output.

        Returns:
            ``foq [B, T, J, 4]`` (unit), ``root [B, T, 3]`` (relative to ``center``),
            ``global [B, T, J, 4]``.
        """
        net = self._require_net()
        out = net(feats["inputs"], keys, feats.get("interm_inputs"))
        num_b, num_t = keys.shape
        foq = out[..., :-3].reshape(num_b, num_t, -1, 4)
        root = out[..., -3:]
        if self.hparams.residual and self.hparams.residual_space == "local":
            # additive correction of the SLERPed *local* rotations, then FK to FOQ
            local = Q.normalize(foq + feats["base_local"])
            foq = Q.mul(global_from_local(local, self.parents), Q.inv(feats["q0"])[:, None])
            root = root + feats["base_root"]
        elif self.hparams.residual:
            # additive correction of the LERP baseline: local-rotation SLERP between the
            # keys (as FOQ) and root LERP
            foq = foq + feats["base_foq"]
            root = root + feats["base_root"]
        foq = Q.normalize(foq)
        return {"foq": foq, "root": root, "global": Q.mul(foq, feats["q0"][:, None])}

    def predict_batch(
        self, batch: Mapping[str, Tensor]
    ) -> tuple[dict[str, Tensor], dict[str, Tensor], Tensor]:
        """Features, prediction and predicted positions of a batch of training windows.

        Args:
            batch: ``global_rotations``, ``root``, ``offsets``, ``tails`` and ``keys``
                as :class:`~skelagnostic_pcmrl.interp.data.PcmrlInterpDataModule` yields.

        Returns:
            ``(feats, pred, positions)``: :meth:`features` (targets included), the
            output of :meth:`predict_window`, and the predicted global positions
            ``[B, T, J, 3]`` (in the frame of ``feats["positions"]``).
        """
        keys = batch["keys"]
        grot, root, _ = self.canonical(batch["global_rotations"], batch["root"], batch["offsets"])
        feats = self.features(grot, root, batch["offsets"], batch["tails"], keys)
        pred = self.predict_window(feats, keys)
        pos = fk_from_global(
            pred["global"], pred["root"] + feats["center"], batch["offsets"], self.parents
        )
        return feats, pred, pos

    def _check_batch(self, batch: Mapping[str, Any]) -> None:
        """Refuse a batch of another skeleton than the one the network was built for."""
        self._require_net()
        given, own = batch_skeleton(batch, "target"), self.skeleton
        assert own is not None  # built together with the network
        if given.parents != own.parents:
            raise SkelagnosticError(
                f"PcmrlInterpAligner: the batch's skeleton {given!r} has another hierarchy than "
                f"the model's {own!r} ({given.num_joints} vs {own.num_joints} joints)"
            )

    def _losses(self, batch: Mapping[str, Any]) -> tuple[Tensor, dict[str, Tensor]]:
        hp = self.hparams
        self._check_batch(batch)
        feats, pred, pos = self.predict_batch(batch)
        parts = {
            "root": (pred["root"] - feats["root"]).abs().mean(),
            "foq": sign_invariant_l1(pred["foq"], feats["foq"]),
            "fk": (pos - feats["positions"]).abs().mean(),
            "quat": sign_invariant_l1(pred["global"], feats["global"]),
        }
        loss = (
            hp.w_root * parts["root"]
            + hp.w_foq * parts["foq"]
            + hp.w_fk * parts["fk"]
            + hp.w_quat * parts["quat"]
        )
        return loss, parts

    def on_train_epoch_start(self) -> None:
        """New random training windows every epoch (seeded by the epoch number)."""
        train_set = getattr(getattr(self.trainer, "datamodule", None), "train_set", None)
        if train_set is not None:
            train_set.epoch = self.current_epoch

    def training_step(self, batch: Mapping[str, Tensor], batch_idx: int) -> Tensor:
        """One optimisation step; logs ``train/loss`` and its parts."""
        loss, parts = self._losses(batch)
        size = batch["keys"].shape[0]
        self.log("train/loss", loss, prog_bar=True, batch_size=size)
        for name, value in parts.items():
            self.log(f"train/{name}", value, batch_size=size)
        return loss

    def validation_step(self, batch: Mapping[str, Tensor], batch_idx: int) -> None:
        """Logs ``val/loss`` (fixed windows and keyframes, no augmentation)."""
        loss, parts = self._losses(batch)
        size = batch["keys"].shape[0]
        self.log("val/loss", loss, prog_bar=True, batch_size=size, sync_dist=True)
        for name, value in parts.items():
            self.log(f"val/{name}", value, batch_size=size, sync_dist=True)

    def test_step(self, batch: Mapping[str, Tensor], batch_idx: int) -> None:
        """Logs ``test/loss`` on the held-out clips' windows."""
        loss, parts = self._losses(batch)
        size = batch["keys"].shape[0]
        self.log("test/loss", loss, batch_size=size, sync_dist=True)
        for name, value in parts.items():
            self.log(f"test/{name}", value, batch_size=size, sync_dist=True)

    def configure_optimizers(self) -> Any:
        """``model.optimizer`` and ``model.scheduler`` (the paper's: AdamW, linear warm-up)."""
        hp = self.hparams
        return configure_optimization(hp.optimizer, hp.scheduler, self.parameters(), self._trainer)

    # ------------------------------------------------------------------ inference
    def _check_motion(self, motion: Motion) -> Skeleton:
        self._require_net()
        skeleton = self.skeleton
        assert skeleton is not None  # built together with the network
        if list(motion.skeleton.parents) != list(skeleton.parents):
            raise MotionError(
                f"motion {motion.name or ''!r} has skeleton {motion.skeleton!r} whose hierarchy "
                f"differs from the trained target skeleton {skeleton!r} "
                f"({motion.skeleton.num_joints} vs {skeleton.num_joints} joints)"
            )
        return skeleton

    def _scale_to_training(self, motion: Motion) -> float:
        """Factor bringing ``motion``'s lengths to the training data's (metres).

        ``motion.units`` when known; otherwise the known unit (:data:`UNITS`)
        closest to the ratio of the trained and the given skeleton heights, or 1
        when that ratio is within a factor of 2 (same units, another body size).
        """
        from skelagnostic.core.motion import UNITS

        if motion.units is not None:
            return UNITS[motion.units]
        trained = self.skeleton.height() if self.skeleton is not None else 0.0
        own = motion.skeleton.height()
        if own <= 0 or trained <= 0 or 0.5 < trained / own < 2.0:
            return 1.0
        ratio = math.log(trained / own)
        return min(UNITS.values(), key=lambda f: abs(math.log(f) - ratio))

    def interpolate_window(
        self, global_rotations: Tensor, root: Tensor, keys: Tensor, offsets: Tensor, tails: Tensor
    ) -> tuple[Tensor, Tensor]:
        """Fill one window between its keys (what :meth:`interpolate` does per chunk).

        Args:
            global_rotations: ``[B, T, J, 4]`` global unit quaternions; only keyframes are read.
            root: ``[B, T, 3]`` root positions (training units, metres); only keyframes are read.
            keys: ``[B, T]`` boolean keyframe mask; frame 0 must be a key.
            offsets: ``[B, J, 3]`` rest offsets.
            tails: ``[B, J, 3]`` rest bone tails
                (:func:`~skelagnostic_pcmrl.interp.rpa.bone_tails`).

        Returns:
            ``(global_rotations [B, T, J, 4], root [B, T, 3])``: the keys as given,
            the other frames generated.
        """
        grot, base_root, turn = self.canonical(global_rotations, root, offsets)
        feats = self.features(grot, base_root, offsets, tails, keys)
        pred = self.predict_window(feats, keys)
        pred_global = Q.mul(turn[:, None, None], pred["global"])
        pred_root = Q.rotate(turn[:, None], pred["root"] + feats["center"])
        key = keys[..., None]
        return (
            torch.where(key[..., None], global_rotations, pred_global),
            torch.where(key, root, pred_root),
        )

    def export_graphs(self) -> list[ExportGraph]:
        """The interpolation network on one window: keyframes -> full window.

        Batch and time are dynamic (the relative positions are clipped at
        ``max_relative`` frames; the model was trained on ``window``-frame
        windows); the joint count is the target skeleton's.

        Raises:
            SkelagnosticError: The model has no skeleton yet.
        """
        self._require_net()
        skeleton = self.skeleton
        assert skeleton is not None  # built together with the network
        hp = self.hparams
        num_b, num_t, num_j = 2, 9, skeleton.num_joints
        rotations = Q.normalize(torch.randn(num_b, num_t, num_j, 4))
        keys = torch.zeros(num_b, num_t, dtype=torch.bool)
        keys[:, [0, 4, num_t - 1]] = True
        offsets = skeleton.offsets.float()[None].expand(num_b, -1, -1).contiguous()
        tails = self.tails.float()[None].expand(num_b, -1, -1).contiguous()
        return [
            ExportGraph(
                "interpolation",
                Method(self, "interpolate_window"),
                (rotations, torch.randn(num_b, num_t, 3), keys, offsets, tails),
                ("global_rotations", "root", "keys", "offsets", "tails"),
                ("out_global_rotations", "out_root"),
                {
                    "global_rotations": {0: "batch", 1: "time"},
                    "root": {0: "batch", 1: "time"},
                    "keys": {0: "batch", 1: "time"},
                    "offsets": {0: "batch"},
                    "tails": {0: "batch"},
                    "out_global_rotations": {0: "batch", 1: "time"},
                    "out_root": {0: "batch", 1: "time"},
                },
                description=(
                    f"a window of the target skeleton ({num_j} joints): global unit quaternions "
                    "(w, x, y, z) [B, T, J, 4] and root positions [B, T, 3] (metres; only the "
                    "keyframes are read), the keyframe mask [B, T] (frame 0 a key), rest offsets "
                    "and bone tails [B, J, 3] -> the window with the frames between the keys "
                    "generated"
                ),
                fixed_axes={
                    "joints": f"{num_j}: the network's input and output layers are per "
                    "joint of the trained skeleton"
                },
                metadata={
                    "skeleton": skeleton.to_dict(),
                    "offsets": skeleton.offsets.float(),
                    "tails": self.tails,
                    "units": "m (the training data's)",
                    "fps": hp.fps,
                    "training_window": int(hp.window),
                    "max_relative": int(hp.max_relative),
                    "canonical_heading": bool(hp.canonical_heading),
                    "preprocess": (
                        "global rotations by forward kinematics of the local ones; pass the "
                        "skeleton's offsets and tails (the values above for the trained skeleton)"
                    ),
                    "postprocess": (
                        "local rotations: inverse(parent global) * global; clips longer than "
                        "training_window: cut at keyframes into chained windows sharing their "
                        "boundary key, as PcmrlInterpAligner.interpolate does"
                    ),
                },
            )
        ]

    #: Chunks of equal length run through the network together, at most this many at a time.
    interpolate_batch: int = 16

    @staticmethod
    def _chunks(keys: Sequence[int], window: int) -> list[tuple[int, int, int, int]]:
        """Chained chunks ``(start, end, first key index, last key index)`` of a key list.

        Each chunk runs from a key to the furthest key within ``window`` frames (at
        least the next key); consecutive chunks share their boundary key.
        """
        chunks = []
        ki = 0
        while ki < len(keys) - 1:
            end_i = ki + 1
            while end_i + 1 < len(keys) and keys[end_i + 1] - keys[ki] + 1 <= window:
                end_i += 1
            chunks.append((keys[ki], keys[end_i], ki, end_i))
            ki = end_i
        return chunks

    @torch.no_grad()
    def interpolate(self, motion: Motion, keyframes: Sequence[int]) -> Motion:
        """Keep the keyframes of ``motion`` and generate the frames between them.

        Clips longer than the training window are cut at keyframes into chained
        chunks of at most ``window`` frames (consecutive chunks share their
        boundary key; a gap longer than the window becomes one longer chunk, which
        the relative positions allow); chunks of equal length run through the
        network as one batch (at most :attr:`interpolate_batch`). Each chunk is
        encoded relative to its first frame (a key) and, with
        ``canonical_heading``, turned so that this frame faces a fixed direction
        (the result is turned back). Lengths are brought
        to the training data's units (metres) and back: by ``motion.units`` when
        known, else by the known unit closest to the ratio of the skeleton
        heights (1 within a factor of 2). Animated non-root translations
        (``motion.translations``) are not interpolated: the result uses the
        skeleton offsets.

        Args:
            motion: A motion on the target skeleton's hierarchy (joint names and
                offsets may differ); only its keyframes are read.
            keyframes: Strictly increasing frame indices, the first 0 and the last
                ``motion.num_frames - 1``.

        Returns:
            A motion with the same skeleton, length, fps, name and units whose
            keyframes equal the input's.

        Raises:
            MotionError: Bad keyframes or a different skeleton hierarchy.
        """
        skeleton = self._check_motion(motion)
        keys = [int(k) for k in keyframes]
        num_t = motion.num_frames
        if not keys or keys[0] != 0 or keys[-1] != num_t - 1:
            raise MotionError(
                f"interpolate: keyframes must start at 0 and end at the last frame "
                f"({num_t - 1}), got {keys[:3]}...{keys[-3:]}"
            )
        if any(b <= a for a, b in itertools.pairwise(keys)):
            raise MotionError("interpolate: keyframes must be strictly increasing")
        fps = self.hparams.fps
        if fps is not None and abs(float(fps) - motion.fps) > 1e-6:
            log.warning(
                "interpolate: the model was trained at %.3g fps, motion %r is at %.3g fps",
                fps,
                motion.name,
                motion.fps,
            )
        scale = self._scale_to_training(motion)
        work = motion.scaled(scale) if scale != 1.0 else motion
        work = work.to(dtype=self.dtype, device=self.device)  # the weights' dtype
        grot = work.global_rotations()
        root = work.root_positions
        offsets = work.skeleton.offsets.to(self.device, self.dtype)
        tails_info = bone_tails(work.skeleton)
        tails = tails_info.tails.to(self.device, self.dtype)
        out_global = grot.clone()
        out_root = root.clone()
        chunks = self._chunks(keys, int(self.hparams.window))
        # chunks are independent: those of equal length run as one batch
        by_length: dict[int, list[tuple[int, int, int, int]]] = {}
        for chunk in chunks:
            by_length.setdefault(chunk[1] - chunk[0], []).append(chunk)
        for group in by_length.values():
            for first in range(0, len(group), self.interpolate_batch):
                batch = group[first : first + self.interpolate_batch]
                frames = torch.stack([torch.arange(s, e + 1) for s, e, _, _ in batch]).to(
                    self.device
                )
                mask = torch.zeros(frames.shape, dtype=torch.bool, device=self.device)
                for row, (s, _, ki, end_i) in enumerate(batch):
                    mask[row, [k - s for k in keys[ki : end_i + 1]]] = True
                # chunks share only their boundary keys, which the window keeps unchanged
                chunk_global, chunk_root = self.interpolate_window(
                    grot[frames],
                    root[frames],
                    mask,
                    offsets[None].expand(len(batch), -1, -1),
                    tails[None].expand(len(batch), -1, -1),
                )
                out_global[frames.reshape(-1)] = chunk_global.reshape(-1, *grot.shape[1:])
                out_root[frames.reshape(-1)] = chunk_root.reshape(-1, 3)
        local = local_from_global(out_global, skeleton.parents)
        local[keys] = work.rotations[keys]
        out_root[keys] = root[keys]
        result = Motion(
            work.skeleton,
            local.cpu(),
            out_root.cpu(),
            motion.fps,
            name=motion.name,
            units=work.units,
        )
        if scale != 1.0:
            result = result.scaled(1.0 / scale)
        return result.to(dtype=motion.dtype)

    # ------------------------------------------------------------------ Aligner API
    def encode(self, motion: Motion) -> Latent:
        """The FOQ representation the model works in: ``z = FOQ [T, J, 4]``.

        ``extras`` hold the first-frame global rotations ``q0 [J, 4]`` and the root
        trajectory ``root [T, 3]`` needed by :meth:`decode`.
        """
        grot = motion.global_rotations()
        foq = Q.continuity(Q.mul(grot, Q.inv(grot[:1])), dim=-3)
        return Latent(foq, motion.fps, {"q0": grot[0], "root": motion.root_positions})

    def decode(self, latent: Latent, skeleton: Skeleton) -> Motion:
        """Rebuild a motion on ``skeleton`` from :meth:`encode` output (FOQ decoding)."""
        grot = Q.mul(latent.z, latent.extras["q0"])
        local = local_from_global(grot, skeleton.parents)
        return Motion(skeleton, local, latent.extras["root"], latent.fps)
