r"""Supervised per-frame pose regression from one point cloud: how fast does an encoder learn?

A diagnostic for PC-MRL stage 1 (docs/reports/pcmrl.md, "What limits stage 1"):
every step draws 32 random frames of the training clips, one 256-point cloud
per frame (PC-MRL Eq. 3), centres it (with its height unless
``--horizontal-only``), turns it to the heading-free frame, and regresses the
joint positions relative to the centroid with the encoder and two linear
layers (MSE). Prints the mean joint error on held-out frames every 100 steps.

Usage::

    python benchmarks/pcmrl_encoder_check.py ../shared/data/human/lafan1 --encoder full \
        --test-pattern subject5 --units cm
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from pathlib import Path

import torch
from torch import nn

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "plugins" / "pcmrl" / "src"))

ENCODERS = ("full", "vector", "none", "pointnet")


class PointNet(nn.Module):
    """Point-wise MLP and a max-pool (Qi et al. 2017), the baseline of the check."""

    def __init__(self, in_channels: int, dim: int) -> None:
        super().__init__()
        self.mlp = nn.Sequential(
            nn.Linear(in_channels, dim),
            nn.ReLU(),
            nn.Linear(dim, 2 * dim),
            nn.ReLU(),
            nn.Linear(2 * dim, 16 * dim),
        )
        self.out_channels = 16 * dim

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        """``[B, N, C]`` -> ``[B, 16 dim]``."""
        return self.mlp(points).amax(dim=-2)


def main(argv: list[str] | None = None) -> None:
    """Parse the arguments, train, print the errors."""
    from skelagnostic_pcmrl.points import heading_frames, sample_layout
    from skelagnostic_pcmrl.recon.point_transformer import PointTransformerEncoder

    from skelagnostic.core import quaternion as Q
    from skelagnostic.errors import SkelagnosticError
    from skelagnostic.io.bvh import read_bvh

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("root", help="directory of BVH clips of one skeleton")
    parser.add_argument("--test-pattern", required=True, help="regex of the held-out clips")
    parser.add_argument("--units", default="cm", help="units of the clips")
    parser.add_argument("--encoder", choices=ENCODERS, default="full")
    parser.add_argument("--layer-scale", type=float, default=None)
    parser.add_argument("--dim", type=int, default=16)
    parser.add_argument("--lr", type=float, default=1e-3)
    parser.add_argument("--steps", type=int, default=600)
    parser.add_argument("--batch", type=int, default=32)
    parser.add_argument(
        "--horizontal-only",
        action="store_true",
        help="remove only the horizontal centroid (model.centre_up=false)",
    )
    args = parser.parse_args(argv)
    torch.manual_seed(0)
    torch.set_num_threads(1)
    files = sorted(Path(args.root).glob("*.bvh"))
    motions = {f: read_bvh(f).convert_units("m", from_=args.units).float() for f in files}
    test = [m for f, m in motions.items() if re.search(args.test_pattern, f.name)]
    train = [m for f, m in motions.items() if not re.search(args.test_pattern, f.name)]
    if not test or not train:
        raise SkelagnosticError(
            f"{args.root}: --test-pattern {args.test_pattern!r} must match some clips and not all"
        )
    skeleton = train[0].skeleton
    up = "xyz".index(skeleton.up_axis)
    offsets = skeleton.offsets.float()
    train_fk = [(m.global_rotations(), m.global_positions()) for m in train]
    test_fk = [(m.global_rotations(), m.global_positions()) for m in test]

    def batch(clips: list, size: int, gen: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
        layout = sample_layout(skeleton, 256, 0.05, (size,), gen)
        rot, pos = [], []
        for _ in range(size):
            r, p = clips[int(torch.randint(len(clips), (1,), generator=gen))]
            t = int(torch.randint(r.shape[0], (1,), generator=gen))
            rot.append(r[t : t + 1])
            pos.append(p[t : t + 1])
        rot_b, pos_b = torch.stack(rot), torch.stack(pos)
        points = layout.points(rot_b, pos_b, offsets)
        centre = points.mean(dim=2)
        if args.horizontal_only:
            centre[..., up] = 0.0
        cloud, joints = points - centre.unsqueeze(2), pos_b - centre.unsqueeze(2)
        turn = Q.inv(heading_frames(cloud, layout.groups, up, 1)).unsqueeze(2)
        cloud, joints = Q.rotate(turn, cloud), Q.rotate(turn, joints)
        onehot = layout.onehot().unsqueeze(1)
        return torch.cat([cloud, onehot], dim=-1)[:, 0], joints[:, 0].flatten(1)

    if args.encoder == "pointnet":
        encoder: nn.Module = PointNet(8, args.dim)
    else:
        encoder = PointTransformerEncoder(
            5, args.dim, 4, 4, 8, attention=args.encoder, layer_scale=args.layer_scale
        )
    joints = skeleton.num_joints
    net = nn.Sequential(
        encoder, nn.Linear(encoder.out_channels, 256), nn.ReLU(), nn.Linear(256, 3 * joints)
    )
    opt = torch.optim.AdamW(net.parameters(), lr=args.lr)
    gen = torch.Generator().manual_seed(1)
    x_test, y_test = batch(test_fk, 512, torch.Generator().manual_seed(2))

    def error(y: torch.Tensor, pred: torch.Tensor) -> float:
        return float((y - pred).unflatten(-1, (joints, 3)).norm(dim=-1).mean())

    start = time.perf_counter()
    for step in range(1, args.steps + 1):
        x, y = batch(train_fk, args.batch, gen)
        loss = (net(x) - y).pow(2).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        if step % 100 == 0 or step == args.steps:
            with torch.no_grad():
                print(
                    f"step {step}: test {error(y_test, net(x_test)):.3f} m, training batch "
                    f"{error(y, net(x)):.3f} m, {time.perf_counter() - start:.0f} s",
                    flush=True,
                )
    print(
        f"mean pose of the last training batch: "
        f"{error(y_test, y.mean(0, keepdim=True).expand_as(y_test)):.3f} m"
    )


if __name__ == "__main__":
    main()
