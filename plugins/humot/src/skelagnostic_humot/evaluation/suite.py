"""Every HuMoT evaluation on groups of clips at once (the benchmarks' quality suite).

:func:`evaluate_clips` runs the reconstruction, both curves and optionally the
cycle error per group of one topology; :func:`evaluate_procedural` does it on
held-out procedural clips and adds the paired retargeting.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch

from skelagnostic import procedural
from skelagnostic.core.motion import Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.errors import SkelagnosticError
from skelagnostic.evaluation import skate_feet
from skelagnostic_humot.aligner import HumotAligner
from skelagnostic_humot.evaluation.held_out import HELD_OUT_SEED, HUMAN_KINDS
from skelagnostic_humot.evaluation.reconstruction import (
    chunk_contacts,
    chunks_of,
    denoising_curve,
    reconstruction,
    upsampling_curve,
)
from skelagnostic_humot.evaluation.retarget import cycle_error, retargeting_procedural

__all__ = ["evaluate_clips", "evaluate_procedural"]


def evaluate_clips(
    model: HumotAligner,
    groups: dict[str, list[Motion]],
    cycle_via: Sequence[Skeleton] = (),
    units: dict[str, str] | None = None,
) -> dict[str, Any]:
    """Reconstruction and both curves for each named group of clips (one topology per group).

    Args:
        model: The model.
        groups: ``name -> clips`` of one skeleton topology.
        cycle_via: Also measure :func:`cycle_error` of every clip through the first of
            these skeletons whose topology differs from the group's.
        units: ``name -> length unit`` of a group's files (default: guessed).

    Raises:
        SkelagnosticError: A group is empty or mixes topologies.
    """
    results: dict[str, Any] = {}
    for name, motions in groups.items():
        if not motions:
            raise SkelagnosticError(f"group {name!r}: no clips")
        sk = motions[0].skeleton
        for m in motions[1:]:
            if m.skeleton.topology_key() != sk.topology_key():
                raise SkelagnosticError(
                    f"group {name!r}: clip {m.name!r} has another topology "
                    f"than {motions[0].name!r}; one topology per group"
                )
        unit = (units or {}).get(name)
        chunks = torch.cat([chunks_of(m, model.hparams.chunk, unit) for m in motions])
        topo, feet = model.topology(sk), skate_feet(sk)
        results[name] = {
            "joints": sk.num_joints,
            "clips": [m.name for m in motions],
            "reconstruction": reconstruction(
                model,
                chunks,
                topo,
                sk.up_axis,
                feet,
                chunk_contacts(chunks, sk, feet, unit or motions[0].units),
            ),
            "denoising": denoising_curve(model, chunks, topo, up_axis=sk.up_axis),
            "upsampling": upsampling_curve(model, chunks, topo, up_axis=sk.up_axis),
        }
        via = next((v for v in cycle_via if v.topology_key() != sk.topology_key()), None)
        if via is not None:
            cycles = [cycle_error(model, m, via, unit) for m in motions]
            results[name]["cycle"] = {k: sum(c[k] for c in cycles) / len(cycles) for k in cycles[0]}
            results[name]["cycle"]["via"] = via.name or f"{via.num_joints} joints"
    return results


def evaluate_procedural(
    model: HumotAligner,
    kinds: Sequence[str] = HUMAN_KINDS,
    clips_per_gait: int = 2,
    seconds: float = 6.0,
    seed: int = HELD_OUT_SEED,
) -> dict[str, Any]:
    """Held-out procedural clips (walk and run, seeds from ``seed``): every evaluation.

    Returns:
        ``{"kinds": <evaluate_clips result per kind>, "retargeting":
        <retargeting_procedural result>}``.
    """
    groups = {
        k: [
            m
            for m, _ in procedural.dataset(
                kinds=(k,),
                gaits=("walk", "run"),
                clips_per_gait=clips_per_gait,
                seconds=seconds,
                seed=seed,
            )
        ]
        for k in kinds
    }
    return {
        "kinds": evaluate_clips(model, groups, units=dict.fromkeys(kinds, "cm")),
        "retargeting": retargeting_procedural(
            model, kinds, clips_per_gait=clips_per_gait, seconds=seconds, seed=seed
        ),
    }
