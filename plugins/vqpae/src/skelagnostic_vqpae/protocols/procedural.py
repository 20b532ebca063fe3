"""Held-out procedural gaits: phase linearity and frequency error where the truth is known.

:func:`procedural_gaits` generates clips of :mod:`skelagnostic.procedural` on every
character whose rig is a procedural kind (:func:`procedural_kind`), with seeds no
training source used, and compares the model's phase and frequency with the
generator's stride frequency.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from skelagnostic.core.skeleton import Skeleton
from skelagnostic.evaluation import HeldOut
from skelagnostic_vqpae.embed import embed_clip
from skelagnostic_vqpae.protocols.tables import phase_line

__all__ = ["PROCEDURAL_SECONDS", "PROCEDURAL_SEED", "procedural_gaits", "procedural_kind"]


#: Smallest seed of :func:`procedural_gaits`' clips (higher when a training source reaches it).
PROCEDURAL_SEED = 1000


#: Duration (seconds) of each held-out procedural gait.
PROCEDURAL_SECONDS = 6.0


def procedural_kind(skeleton: Skeleton, tolerance: float = 0.02) -> str | None:
    """The :mod:`skelagnostic.procedural` kind whose rig ``skeleton`` is, if any.

    The generator animates only its own skeletons (:data:`skelagnostic.procedural.KINDS`):
    a rig is one of them when it has the same joints and parents and the same rest
    offsets up to scale (every offset over the skeleton height within ``tolerance``).
    A real rig with the same joint names (LaFAN1 and ``biped22``) has other rest
    offsets, so the generator's joint angles would not play on it.

    Args:
        skeleton: A character's skeleton.
        tolerance: Largest difference of an offset coordinate, in skeleton heights.

    Returns:
        The kind, or None.
    """
    from skelagnostic import procedural

    height = max(skeleton.height(), 1e-9)
    for kind in procedural.KINDS:
        ref = procedural.skeleton(kind)
        if list(ref.joint_names) != list(skeleton.joint_names) or list(ref.parents) != list(
            skeleton.parents
        ):
            continue
        diff = ref.offsets.double() / ref.height() - skeleton.offsets.double() / height
        if float(diff.abs().max()) <= tolerance:
            return kind
    return None


def _first_unseen_seed(datamodule: Any) -> int:
    """A seed above every seed the run's procedural training sources used."""
    from skelagnostic.data import ProceduralSource

    first = PROCEDURAL_SEED
    for source in getattr(datamodule, "sources", None) or []:
        if isinstance(source, ProceduralSource):
            first = max(first, source.seed + len(source.clips()))
    return first


def procedural_gaits(aligner: Any, held: HeldOut, seeds_per_gait: int = 2) -> dict[str, Any]:
    """Phase linearity and frequency error on held-out procedural gaits, per character.

    For every character whose rig is a procedural kind (:func:`procedural_kind`),
    ``seeds_per_gait`` clips of each of its morphology's gaits except ``idle``,
    :data:`PROCEDURAL_SECONDS` long at the character's frame rate, with seeds from
    :data:`PROCEDURAL_SEED` upwards, above every seed a procedural training source of
    the run used (a seed sets the body size, stride frequency and turning, so these
    clips were never seen). The model sees them in metres, as it saw its training
    clips (:meth:`VqpaeModel.encode`). Per clip, on the
    frames whose window lies inside the clip: the median of the frequency head
    against the generator's stride frequency, the rate at which the phase advances
    (slope of :func:`phase_line`) against the same, and the phase's R^2.

    Args:
        aligner: A trained aligner.
        held: The run's held-out clips (for its data module's training sources).
        seeds_per_gait: Clips per gait and character; 0: none.

    Returns:
        ``characters`` (name -> kind or None), ``seeds``, ``seconds``, ``clips``
        (rows with ``character``, ``kind``, ``gait``, ``seed``, ``true_hz``,
        ``predicted_hz``, ``frequency_error_pct``, ``phase_hz``,
        ``phase_rate_error_pct``, ``phase_r2``), ``mean`` (of the numeric row
        figures) and ``note`` (why characters have no clip, or None).
    """
    from skelagnostic import procedural

    specs = aligner.hparams["datasets"] or {}
    kinds: dict[str, str | None] = {}
    for name in aligner.dataset_names:
        sk = (specs.get(name) or {}).get("skeleton")
        kinds[name] = procedural_kind(Skeleton.from_dict(sk)) if sk else None
    seed = _first_unseen_seed(held.datamodule) if seeds_per_gait > 0 else PROCEDURAL_SEED
    rows: list[dict[str, Any]] = []
    for name, kind in kinds.items():
        if kind is None or seeds_per_gait <= 0:
            continue
        spec = specs[name]
        fps, half = float(spec["fps"]), int(spec["window"]) // 2
        morphology = "quadruped" if kind == "quadruped" else "biped"
        for gait in procedural.GAITS[morphology]:
            if gait == "idle":
                continue
            for _ in range(seeds_per_gait):
                motion, info = procedural.generate(
                    kind, gait, seconds=PROCEDURAL_SECONDS, fps=fps, seed=seed
                )
                emb = embed_clip(aligner, motion)
                inner = slice(half, max(len(emb) - half, half + 2))
                truth = float(info["frequency"])
                predicted = float(emb.frequency[inner].median())
                r2, slope = phase_line(emb.phase[inner])
                phase_hz = abs(slope) * emb.fps
                rows.append(
                    {
                        "clip": str(motion.name),
                        "character": name,
                        "kind": kind,
                        "gait": gait,
                        "seed": seed,
                        "true_hz": truth,
                        "predicted_hz": predicted,
                        "frequency_error_pct": 100 * abs(predicted - truth) / truth,
                        "phase_hz": phase_hz,
                        "phase_rate_error_pct": 100 * abs(phase_hz - truth) / truth,
                        "phase_r2": r2,
                    }
                )
                seed += 1
    figures = ("frequency_error_pct", "phase_rate_error_pct", "phase_r2")
    absent = [n for n, k in kinds.items() if k is None]
    note = None
    if absent and seeds_per_gait > 0:
        note = (
            f"no procedural gaits for {', '.join(absent)}: their rigs are not a procedural "
            "kind's (skelagnostic.procedural animates only its own skeletons), so no clip of "
            "known gait frequency exists on them; phase linearity on held-out procedural gaits "
            "needs a model trained on procedural characters"
        )
    return {
        "characters": kinds,
        "seeds": sorted({r["seed"] for r in rows}),
        "seconds": PROCEDURAL_SECONDS,
        "clips": rows,
        "mean": {f: float(np.mean([r[f] for r in rows])) for f in figures} if rows else {},
        "note": note,
    }
