"""``skelagnostic demo``: the core end to end on procedural or real motion.

Generates procedural gaits on four skeletons (or reads the BVH files given),
runs forward kinematics, writes each motion as BVH, reads it back to check the
round trip, and renders all characters side by side as a PNG contact sheet and
an animated GIF (and with ``--html`` the interactive 3D viewer page).
Everything lands in one output directory with a ``summary.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

_DEFAULT_CLIPS = (
    ("biped22", "walk"),
    ("biped31", "run"),
    ("biped17", "walk"),
    ("quadruped", "trot"),
)


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="skelagnostic demo",
        description="Procedural or BVH motion -> forward kinematics -> BVH files + rendering.",
    )
    parser.add_argument(
        "bvh", nargs="*", type=Path, help="BVH files to use instead of procedural motion"
    )
    parser.add_argument("--out", type=Path, default=Path("runs/demo"), help="output directory")
    parser.add_argument("--seconds", type=float, default=3.0, help="procedural clip length")
    parser.add_argument("--fps", type=float, default=30.0, help="procedural frame rate")
    parser.add_argument("--seed", type=int, default=0, help="procedural seed")
    parser.add_argument("--no-gif", action="store_true", help="skip the animated GIF")
    parser.add_argument(
        "--html",
        nargs="?",
        const="demo.html",
        default=None,
        metavar="PATH",
        help="also write the interactive 3D viewer (default name demo.html, in --out)",
    )
    return parser


def main(argv: Sequence[str]) -> int:
    """Run the demo; returns the exit code."""
    args = _parser().parse_args(list(argv))
    from rich.console import Console
    from rich.table import Table

    import skelagnostic as sa
    from skelagnostic.viz import render_motion, to_html

    console = Console(stderr=False)
    out: Path = args.out
    try:
        out.mkdir(parents=True, exist_ok=True)
        motions = []
        if args.bvh:
            for path in args.bvh:
                motions.append(sa.read_bvh(path))
            source = "bvh"
        else:
            for i, (kind, gait) in enumerate(_DEFAULT_CLIPS):
                motion, _ = sa.procedural.generate(
                    kind, gait, seconds=args.seconds, fps=args.fps, seed=args.seed + i
                )
                motions.append(motion)
            source = "procedural (synthetic)"
        table = Table(title=f"skelagnostic demo: {source}")
        for col in ("motion", "joints", "frames", "fps", "height", "speed/s", "BVH round trip"):
            table.add_column(col)
        summary = []
        bvh_dir = out / "bvh"
        bvh_dir.mkdir(exist_ok=True)
        for m in motions:
            pos = m.global_positions()
            speed = float(m.root_local_velocities()[:, 0, [0, 2]].norm(dim=-1).mean())
            path = bvh_dir / f"{m.name}.bvh"
            sa.write_bvh(m, path)
            back = sa.read_bvh(path)
            err = float((back.global_positions() - pos).abs().max())
            table.add_row(
                str(m.name),
                str(m.num_joints),
                str(m.num_frames),
                f"{m.fps:g}",
                f"{m.skeleton.height():.1f}",
                f"{speed:.1f}",
                f"max |dpos| {err:.1e}",
            )
            summary.append(
                {
                    "name": m.name,
                    "joints": m.num_joints,
                    "frames": m.num_frames,
                    "fps": m.fps,
                    "height": m.skeleton.height(),
                    "root_speed": speed,
                    "bvh": str(path),
                    "round_trip_max_position_error": err,
                }
            )
        console.print(table)
        labels = [str(m.name) for m in motions]
        sheet = render_motion(
            motions, out / "demo.png", labels=labels, sheet_frames=6, columns=3, follow=True
        )
        outputs = {"contact_sheet": str(sheet)}
        if not args.no_gif:
            gif = render_motion(
                motions, out / "demo.gif", labels=labels, max_frames=90, follow=True
            )
            outputs["animation"] = str(gif)
        if args.html is not None:
            page = out / args.html
            to_html(motions, names=labels, out=page)
            outputs["viewer"] = str(page)
        (out / "summary.json").write_text(
            json.dumps({"source": source, "motions": summary, "outputs": outputs}, indent=2)
        )
    except sa.SkelagnosticError as exc:
        print(f"skelagnostic demo: error: {exc}", file=sys.stderr)
        return 1
    for kind, path in outputs.items():
        console.print(f"{kind}: {path}")
    console.print(f"BVH files: {bvh_dir}  summary: {out / 'summary.json'}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main(sys.argv[1:]))
