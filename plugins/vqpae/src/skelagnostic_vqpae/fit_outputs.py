"""What a VQ-PAE fit leaves in its run directory (via ``FitSummary``).

:func:`fit_summary` embeds the validation (and training) clips, measures the
manifold overlap of their codes (paper Table 2) and draws the phase manifold
and the per-clip timing; the callback writes them as ``vqpae_metrics.json``,
``vqpae_manifold.png`` and ``vqpae_timing.png``. With two or more characters and
held-out clips of the first, :func:`transfer_summary` also re-enacts a few of
those clips with the second character (the ``vqpae.transfer`` evaluation on a
subset): figures under ``"transfer"``, a table in ``summary.md`` and the render
``vqpae_transfer.gif`` / ``.png`` (source, VQ-PAE transfer, the two baselines).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import torch

from skelagnostic.errors import SkelagnosticError
from skelagnostic.io.markdown import markdown_cell
from skelagnostic.metrics.functional import manifold_overlap

if TYPE_CHECKING:
    import lightning as L

    from skelagnostic.callbacks import SummaryContent
    from skelagnostic_vqpae.aligner import VqpaeAligner

__all__ = ["fit_summary", "overlap_figures", "transfer_summary"]

#: Held-out source clips re-enacted at the end of ``fit`` (seconds each: a few).
SUMMARY_TRANSFER_CLIPS = 3
#: Longest source excerpt transferred at the end of ``fit`` (the start of each clip), seconds.
SUMMARY_TRANSFER_SECONDS = 10.0
#: Seconds of the transfer render (the start of the clip; a short path keeps the figures large).
RENDER_SECONDS = 3.0


def fit_summary(aligner: VqpaeAligner, trainer: L.Trainer) -> SummaryContent:
    """The manifold figures and pictures of the fit summary (:meth:`VqpaeAligner.fit_summary`).

    * metrics (in ``vqpae_metrics.json``): the manifold overlap (usage,
      overlap, per-dataset share, codes used per dataset) of the per-frame
      codes of the validation clips (``"split": "val"``; the training clips
      without a validation split), and under ``"train"`` the same figures
      for the training clips (the paper's Table 2 measures the training data);
    * ``vqpae_manifold.png``: the phase manifold (PCA of the codebook
      ellipses, one panel per character, its frames' points; paper Fig. 1);
    * ``vqpae_timing.png``: phase, frequency and code over time for the
      first clip of every character.
    """
    dm = trainer.datamodule
    if dm is None or aligner.codebook is None:
        return {}
    splits = [
        name for name in ("val", "train") if any(len(d) for d in dm.datasets.get(name, {}).values())
    ]
    if not splits:
        return {}
    embeddings = {name: aligner.embed_datasets(dm.datasets[name], dm.fps) for name in splits}
    figures = {name: overlap_figures(aligner, embeddings[name]) for name in splits}
    metrics = {
        "split": splits[0],
        **figures[splits[0]],
        **({"train": figures["train"]} if splits[0] != "train" else {}),
    }
    content: SummaryContent = {"metrics": metrics}
    transferred = transfer_summary(aligner, dm)
    if transferred:
        metrics["transfer"] = transferred["metrics"]
        content["renders"] = transferred["renders"]
        content["notes"] = transferred["notes"]
    shown = {n: embs for n, embs in embeddings[splits[0]].items() if embs}
    if not shown:
        return content
    from skelagnostic_vqpae.embed import plot_clip_timing, plot_manifold

    content["figures"] = {
        "manifold": plot_manifold(aligner, shown),
        "timing": plot_clip_timing({n: embs[0] for n, embs in shown.items()}),
    }
    return content


def transfer_summary(
    aligner: VqpaeAligner, datamodule: Any, max_clips: int = SUMMARY_TRANSFER_CLIPS
) -> dict[str, Any]:
    """Held-out clips of the first character re-enacted by the second, model vs baseline.

    The first ``max_clips`` validation (else test) clips of the first dataset (their
    first :data:`SUMMARY_TRANSFER_SECONDS` seconds: motion-capture clips can last
    minutes) go through :func:`skelagnostic_vqpae.evaluation.transfer_rows` with the second
    dataset's training clips as the database.

    Args:
        aligner: The trained aligner.
        datamodule: Its set-up data module.
        max_clips: Source clips to transfer.

    Returns:
        ``{}`` without two characters, a held-out source clip or a database clip;
        else ``metrics`` (the split, the source and database clip ids, per-clip
        rows and the per-method means), ``renders`` (``transfer``: the first clip,
        its transfer and the two baselines') and ``notes`` (a Markdown table).
        When the transfer cannot run (for example a model whose frequencies have
        periods longer than every database clip), ``metrics`` is ``{"skipped":
        reason}``, no render, and the notes say why: the fit still succeeds.
    """
    from skelagnostic.evaluation import MODEL, clips_of_split, mean_rows
    from skelagnostic_vqpae.evaluation import OWN_RATE, UNSCALED, transfer_rows, transition_note
    from skelagnostic_vqpae.transfer import FREQUENCY_TOLERANCE, HALFLIFE

    if len(aligner.dataset_names) < 2 or not hasattr(datamodule, "sources"):
        return {}
    for split in ("val", "test"):
        sources = [
            c for c in clips_of_split(datamodule, split) if aligner.dataset_of(c.skeleton) == 0
        ]
        if sources:
            break
    database = [
        c for c in clips_of_split(datamodule, "train") if aligner.dataset_of(c.skeleton) == 1
    ]
    if not sources or not database:
        return {}
    excerpts = [c[: int(SUMMARY_TRANSFER_SECONDS * c.fps) + 1] for c in sources[:max_clips]]
    try:
        rows, outputs = transfer_rows(aligner, excerpts, database)
    except SkelagnosticError as error:  # e.g. frequencies whose periods no clip holds
        return {
            "metrics": {"skipped": str(error)},
            "renders": {},
            "notes": f"## Transfer of held-out clips\n\nNot run: {error}\n",
        }
    means = mean_rows(rows)
    source, target = aligner.dataset_names[0], aligner.dataset_names[1]
    lines = [
        "## Transfer of held-out clips",
        "",
        f"{len(rows)} held-out ({split}) clips of `{source}` (at most their first "
        f"{SUMMARY_TRANSFER_SECONDS:g} s) re-enacted with the "
        f"{len(database)} training clips of `{target}`, on the same manifold query: "
        "`model`, frequency-scaled motion matching (the paper); "
        f"`{UNSCALED}`, classical motion matching (1 s replays, no time warping: the target "
        f"at its own rate, re-matched every second); `{OWN_RATE}`, the best-matching target "
        "stretch as long as the source, at its own rate. Gait frequencies are counted from "
        "the feet's forward swings of each motion, independently of the model; acceleration "
        "(mean and worst frame, over the skeleton height, 1/s^2) measures smoothness, lower "
        f"is smoother. Transitions: {transition_note(HALFLIFE, FREQUENCY_TOLERANCE)}.",
        "",
        "| clip | source Hz | method | output Hz | frequency error % | mean accel | max accel |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        for method in (MODEL, UNSCALED, OWN_RATE):
            v = row["values"][method]
            lines.append(
                f"| {markdown_cell(row['clip'])} | {row['source_hz']:.3f} | `{method}` | "
                f"{v['output_hz']:.3f} | "
                f"{v['frequency_error_pct']:.1f} | {v['accel_height_per_s2']:.2f} | "
                f"{v['accel_max_height_per_s2']:.1f} |"
            )
    for method in (MODEL, UNSCALED, OWN_RATE):
        v = means.get(method, {})
        lines.append(
            f"| **mean** | | `{method}` | | **{v.get('frequency_error_pct', math.nan):.1f}** | "
            f"{v.get('accel_height_per_s2', math.nan):.2f} | "
            f"{v.get('accel_max_height_per_s2', math.nan):.1f} |"
        )
    first = next(iter(outputs))
    return {
        "metrics": {
            "split": split,
            "source": source,
            "target": target,
            "database_clips": [str(c.name) for c in database],
            "halflife": HALFLIFE,
            "frequency_tolerance": FREQUENCY_TOLERANCE,
            "per_clip": rows,
            "mean": means,
        },
        "renders": {"transfer": [m[: int(RENDER_SECONDS * m.fps) + 1] for m in outputs[first]]},
        "notes": [
            "\n".join(lines),
            f"Render `vqpae_transfer`: the first {RENDER_SECONDS:g} s of {first} (source, "
            "model, the two baselines).",
        ],
    }


def overlap_figures(aligner: VqpaeAligner, embeddings: Mapping[str, list[Any]]) -> dict[str, Any]:
    """Manifold overlap (Table 2) of per-clip embeddings of every dataset."""
    codes = [
        torch.cat([e.code for e in embeddings.get(n, [])] or [torch.zeros(0, dtype=torch.long)])
        for n in aligner.dataset_names
    ]
    overlap = manifold_overlap(codes, aligner._require_built().num_codes)
    single = len(aligner.dataset_names) < 2  # overlap is not applicable: None, not a number
    return {
        "usage": overlap["usage"],
        "overlap": None if single else overlap["overlap"],
        "per_dataset": {
            n: None if single or math.isnan(v) else v
            for n, v in zip(aligner.dataset_names, overlap["per_dataset"], strict=True)
        },
        "codes_used": {
            n: int(c.unique().numel()) for n, c in zip(aligner.dataset_names, codes, strict=True)
        },
    }
