"""HuMoT's templates of a clip whose static root carries the trajectory (Bandai-Namco layout)."""

from __future__ import annotations

from pathlib import Path

import torch
from skelagnostic_humot.template import median_bone_lengths, skeleton_template

import skelagnostic as sa


def test_humot_templates_of_a_carrier_clip(tmp_path: Path) -> None:
    """HuMoT's template from the skeleton and from a clip's median bone lengths."""
    files = {}
    for name, layout in {
        "plain": {},
        "carrier_all6": {"root_carrier": "static", "channels": "all6"},
    }.items():
        motion, _ = sa.procedural.generate("biped22", "walk", seconds=5.0, fps=30, seed=0, **layout)
        files[name] = tmp_path / f"{name}.bvh"
        sa.write_bvh(motion, files[name])
    plain = sa.read_bvh(files["plain"])
    motion = sa.read_bvh(files["carrier_all6"])
    lengths = median_bone_lengths(motion.global_positions(), motion.skeleton)
    assert float(lengths[:2].abs().sum()) == 0.0
    torch.testing.assert_close(
        lengths[1:],
        median_bone_lengths(plain.global_positions(), plain.skeleton),
        atol=1e-4,
        rtol=0,
    )
    for positions in (None, motion.global_positions()):
        template = skeleton_template(motion.skeleton, positions)
        want = skeleton_template(
            plain.skeleton, None if positions is None else plain.global_positions()
        )
        torch.testing.assert_close(template[1:] - template[1], want, atol=1e-4, rtol=0)


def test_humot_topology_of_a_carrier_skeleton() -> None:
    """The bone directions HuMoT derives from a carrier skeleton are the ordinary ones."""
    from skelagnostic_humot.data import Topology

    plain = sa.procedural.generate("biped22", "walk", seconds=2.0)[0].skeleton
    carrier = sa.procedural.generate("biped22", "walk", seconds=2.0, root_carrier="static")[0]
    directions = Topology.of(carrier.skeleton).directions
    assert float(directions[:2].abs().sum()) == 0.0
    torch.testing.assert_close(directions[1:], Topology.of(plain).directions)
