"""What a VQ-PAE fit leaves in its run directory (via ``FitSummary``).

:func:`fit_summary` embeds the validation (and training) clips, measures the
manifold overlap of their codes and the paper's Table 2 on the run
(:func:`table2_summary`: the share of the training frames on codes both characters
use, the shared codes, and whether the held-out source and target clips share a
code), and draws the phase manifold and the per-clip timing; the callback writes
them as ``vqpae_metrics.json``, ``vqpae_manifold.png`` and ``vqpae_timing.png``.
With two or more characters and held-out clips of the first,
:func:`transfer_summary` also re-enacts a few of those clips with the second
character (the ``vqpae.transfer`` evaluation on a subset): figures under
``"transfer"``, a table in ``summary.md``, the picture ``vqpae_transfer.png``
(:func:`~skelagnostic_vqpae.picture.plot_transfer`: poses at one scale and the
feet's touch-downs) and, in the full summary, the animation ``vqpae_transfer.gif``
(:func:`transfer_render_options`: large labelled panels, the target's at one scale).

How much is computed is the run's ``summary=`` (:data:`SUMMARY_PLANS`): ``full``
or ``quick`` (one clip, a shorter excerpt, a smaller database, no animation: a
smoke run's summary takes seconds); the stages are printed as they run.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import torch

from skelagnostic.errors import SkelagnosticError
from skelagnostic.evaluation import MODEL, clips_of_split, mean_rows
from skelagnostic.io.markdown import markdown_cell
from skelagnostic.metrics.functional import manifold_overlap
from skelagnostic_vqpae.embed import embed_datasets, plot_clip_timing, plot_manifold
from skelagnostic_vqpae.picture import plot_transfer
from skelagnostic_vqpae.protocols.procedural import procedural_kind
from skelagnostic_vqpae.protocols.tables import table2
from skelagnostic_vqpae.protocols.transfer import (
    OWN_RATE,
    UNSCALED,
    transfer_rows,
    transition_note,
)
from skelagnostic_vqpae.training import VqpaeModel
from skelagnostic_vqpae.transfer import FREQUENCY_TOLERANCE, HALFLIFE

if TYPE_CHECKING:
    import lightning as L

    from skelagnostic.callbacks import SummaryContent

__all__ = [
    "SUMMARY_PLANS",
    "SummaryPlan",
    "fit_summary",
    "overlap_figures",
    "shared_codes_sentence",
    "shared_manifold_headline",
    "table2_summary",
    "transfer_labels",
    "transfer_picture",
    "transfer_render_options",
    "transfer_summary",
]


@dataclass(frozen=True)
class SummaryPlan:
    """What one ``summary=`` mode computes.

    Attributes:
        transfer_clips: Held-out source clips re-enacted.
        transfer_seconds: Longest excerpt of each (the start of the clip), seconds.
        database_clips: Training clips of the target in the matching database (None: all).
        animation: Whether the transfer is rendered as a GIF too.
    """

    transfer_clips: int
    transfer_seconds: float
    database_clips: int | None
    animation: bool

    def describe(self) -> str:
        """One line: what this plan computes."""
        database = "all" if self.database_clips is None else f"at most {self.database_clips}"
        return (
            f"up to {self.transfer_clips} held-out clip(s) of at most {self.transfer_seconds:g} s "
            f"transferred onto {database} training clips of the target, "
            + ("picture and animation" if self.animation else "picture only (no animation)")
        )


#: The plans of ``summary=full`` and ``summary=quick``.
SUMMARY_PLANS = {
    "full": SummaryPlan(
        transfer_clips=3, transfer_seconds=10.0, database_clips=None, animation=True
    ),
    "quick": SummaryPlan(transfer_clips=1, transfer_seconds=4.0, database_clips=6, animation=False),
}
#: Held-out source clips re-enacted by the full summary.
SUMMARY_TRANSFER_CLIPS = SUMMARY_PLANS["full"].transfer_clips
#: Longest source excerpt transferred by the full summary (the start of each clip), seconds.
SUMMARY_TRANSFER_SECONDS = SUMMARY_PLANS["full"].transfer_seconds
#: Seconds of the transfer animation (the start of the clip).
RENDER_SECONDS = 3.0
#: Size ``(width, height)`` of one panel of the transfer animation, pixels.
RENDER_PANEL = (380, 420)
#: Frame rate of the transfer animation (fewer frames: a lighter file, a quicker render).
RENDER_FPS = 15.0


class _Stages:
    """Prints each stage of the summary as it starts (Rich, on stderr), then the total time."""

    def __init__(self, mode: str, names: list[str], console: Any = None) -> None:
        from rich.console import Console

        self.console = console or Console(stderr=True, highlight=False)
        self.mode, self.names, self.done = mode, names, 0
        self.start = time.perf_counter()

    def __call__(self, name: str) -> None:
        self.done += 1
        total = max(len(self.names), self.done)
        elapsed = time.perf_counter() - self.start
        self.console.print(
            f"[bold]fit summary ({self.mode})[/bold] {self.done}/{total}: {name} "
            f"[dim](after {elapsed:.0f} s)[/dim]"
        )

    def finish(self) -> None:
        elapsed = time.perf_counter() - self.start
        self.console.print(f"[bold]fit summary ({self.mode})[/bold] done in {elapsed:.0f} s")


def fit_summary(aligner: VqpaeModel, trainer: L.Trainer, mode: str = "full") -> SummaryContent:
    """The manifold figures and pictures of the fit summary (:meth:`VqpaeAligner.fit_summary`).

    * metrics (in ``vqpae_metrics.json``): the manifold overlap (usage,
      overlap, per-dataset share, codes used per dataset) of the per-frame
      codes of the validation clips (``"split": "val"``; the training clips
      without a validation split), and under ``"train"`` the same figures
      for the training clips; under ``"table2"`` the paper's Table 2 on the run
      (:func:`table2_summary`); under ``"transfer"`` :func:`transfer_summary`;
    * ``vqpae_manifold.png``: the phase manifold (PCA of the codebook
      ellipses, one panel per character, its frames' points; paper Fig. 1);
    * ``vqpae_timing.png``: phase, frequency and code over time for the
      first clip of every character;
    * ``vqpae_transfer.png`` (and ``.gif`` in the full summary): the transfer.

    Args:
        aligner: The trained aligner.
        trainer: Its trainer (the data module).
        mode: ``"full"`` or ``"quick"`` (:data:`SUMMARY_PLANS`).

    Raises:
        SkelagnosticError: An unknown mode.
    """
    if mode not in SUMMARY_PLANS:
        raise SkelagnosticError(
            f"summary: the VQ-PAE summary is one of {', '.join(SUMMARY_PLANS)}, got {mode!r}"
        )
    plan = SUMMARY_PLANS[mode]
    dm = trainer.datamodule
    if dm is None or aligner.codebook is None:
        return {}
    splits = [
        name for name in ("val", "train") if any(len(d) for d in dm.datasets.get(name, {}).values())
    ]
    if not splits:
        return {}
    stages = _Stages(
        mode,
        ["embed the clips", "Table 2", "transfer held-out clips", "picture"]
        + (["animation"] if plan.animation else [])
        + ["manifold plots"],
    )
    stages(f"embed the {' and '.join(splits)} clips")
    embeddings = {name: embed_datasets(aligner, dm.datasets[name], dm.fps) for name in splits}
    figures = {name: overlap_figures(aligner, embeddings[name]) for name in splits}
    metrics: dict[str, Any] = {
        "split": splits[0],
        **figures[splits[0]],
        **({"train": figures["train"]} if splits[0] != "train" else {}),
    }
    content: SummaryContent = {"metrics": metrics, "notes": []}
    stages("Table 2 (shared codes)")
    if "train" in embeddings and len(aligner.dataset_names) >= 2:
        held = embeddings.get("val", {})  # without a validation split: no held-out column
        table, note = table2_summary(aligner, held, embeddings["train"])
        metrics["table2"] = table
        content["notes"].append(note)
        content["headline"] = [shared_manifold_headline(table, list(aligner.dataset_names))]
    stages(f"transfer: {plan.describe()}")
    transferred = transfer_summary(
        aligner,
        dm,
        plan=plan,
        stages=stages,
        table=metrics.get("table2"),
        steps=trainer.global_step,
    )
    if transferred:
        metrics["transfer"] = transferred["metrics"]
        content["renders"] = transferred["renders"]
        content["render_options"] = transferred.get("render_options", {})
        content["figures"] = transferred.get("figures", {})
        content["notes"] += transferred["notes"]
    shown = {n: embs for n, embs in embeddings[splits[0]].items() if embs}
    if shown:
        stages("manifold and timing plots")
        content.setdefault("figures", {}).update(
            {
                "manifold": plot_manifold(aligner, shown),
                "timing": plot_clip_timing({n: embs[0] for n, embs in shown.items()}),
            }
        )
    stages.finish()
    return content


def _codes(embeddings: Mapping[str, list[Any]], names: list[str]) -> dict[str, torch.Tensor]:
    """``character -> [F]`` codes of every frame of its clips (empty without clips)."""
    return {
        n: torch.cat([e.code for e in embeddings.get(n, [])] or [torch.zeros(0, dtype=torch.long)])
        for n in names
    }


def table2_summary(
    aligner: VqpaeModel,
    held: Mapping[str, list[Any]],
    train: Mapping[str, list[Any]],
) -> tuple[dict[str, Any], str]:
    """The paper's Table 2 on the run, and whether held-out source and target share codes.

    WalkTheDog's Table 2 is the share of the training frames that lie on a code
    every character uses (over the training set, as the authors' ``test_vq.py``).
    Beside it: the share of the held-out frames on those training-shared codes, and
    the codes the held-out clips of the first two characters (the transfer's source
    and target) use, with a plain sentence when they share none.

    Args:
        aligner: The trained aligner.
        held: ``character -> clip embeddings`` of the held-out (validation) clips.
        train: The same for the training clips.

    Returns:
        ``(figures, markdown)``: ``codes_shared_training`` (codes every character
        uses on its training clips), ``shared_codes_training`` (their ids),
        ``frame_share_training`` (character -> share of its training frames on them:
        the paper's figure), ``frame_share_heldout_on_training_shared`` (character ->
        share of its held-out frames on them), ``codes_heldout`` (character -> the
        codes its held-out frames use), ``heldout_source_target_shared`` (the codes
        the held-out clips of the first two characters share) and ``num_codes``; and
        a ``## Table 2`` section for ``summary.md``.
    """
    names = list(aligner.dataset_names)
    num_codes = int(aligner._require_built().num_codes)
    trained = _codes(train, names)
    heldout = {n: c for n, c in _codes(held, names).items() if len(c)}
    used = {n: set(c.tolist()) for n, c in trained.items()}
    shared = sorted(set.intersection(*used.values())) if used else []
    share_train = {
        n: float(torch.isin(c, torch.tensor(shared, dtype=c.dtype)).float().mean())
        if len(c)
        else None
        for n, c in trained.items()
    }
    held_table = table2(heldout, trained) if heldout else {}
    codes_heldout = {n: sorted(set(c.tolist())) for n, c in heldout.items()}
    source, target = names[0], names[1]
    both = sorted(set(codes_heldout.get(source, [])) & set(codes_heldout.get(target, [])))
    figures = {
        "num_codes": num_codes,
        "codes_shared_training": len(shared),
        "shared_codes_training": shared,
        "frame_share_training": share_train,
        "frame_share_heldout_on_training_shared": held_table.get(
            "frame_share_heldout_on_training_shared", {}
        ),
        "codes_heldout": codes_heldout,
        "heldout_source_target_shared": both,
    }

    def pct(v: float | None) -> str:
        return "n/a" if v is None or math.isnan(v) else f"{100 * v:.1f} %"

    lines = [
        "## Table 2: frames on shared codes",
        "",
        f"WalkTheDog's Table 2 on this run: the share of each character's training frames "
        f"whose code every character uses on its training clips ({len(shared)} of {num_codes} "
        "codes are shared), and the same share of its held-out (validation) frames.",
        "",
        "| character | training frames on shared codes | held-out frames on them | "
        "codes used (training) | codes of the held-out clips |",
        "|---|---|---|---|---|",
    ]
    for n in names:
        lines.append(
            f"| `{n}` | {pct(share_train.get(n))} | "
            f"{pct(figures['frame_share_heldout_on_training_shared'].get(n))} | "
            f"{len(used.get(n, ()))} | {', '.join(map(str, codes_heldout.get(n, []))) or 'none'} |"
        )
    lines += ["", shared_codes_sentence(source, target, codes_heldout)]
    return figures, "\n".join(lines)


def shared_codes_sentence(source: str, target: str, codes: Mapping[str, list[int]]) -> str:
    """Whether the held-out clips of ``source`` and ``target`` sit on a common code, plainly.

    Example:
        >>> text = shared_codes_sentence("human", "dog", {"human": [4, 7, 9], "dog": [10]})
        >>> text.split(":")[0]
        'The held-out human clips sit on codes 4, 7, 9 and the dog clips on code 10'
    """
    a, b = codes.get(source, []), codes.get(target, [])
    if not a or not b:
        return f"No held-out clip of `{source}` or `{target}`: no shared code to report."

    def listed(c: list[int]) -> str:
        return ("code " if len(c) == 1 else "codes ") + ", ".join(map(str, c))

    both = sorted(set(a) & set(b))
    head = f"The held-out {source} clips sit on {listed(a)} and the {target} clips on {listed(b)}"
    if not both:
        return (
            f"{head}: they share no code, so this run does not show a shared manifold (the "
            "method's point): the transfer matches the source to the nearest target frames "
            "on other codes."
        )
    return f"{head}: they share {listed(both)}."


def shared_manifold_headline(table: Mapping[str, Any], names: list[str]) -> str:
    """One paragraph for the top of ``summary.md``: does this run show a shared manifold?

    Args:
        table: :func:`table2_summary`'s figures.
        names: The dataset names; the first two are the transfer's source and target.

    Returns:
        The codes both characters use on their training clips with the share of each
        character's training (and held-out) frames on them, and whether the held-out
        clips of the first two characters sit on a common code.

    Example:
        >>> table = {"num_codes": 16, "codes_shared_training": 0,
        ...          "frame_share_training": {"human": 0.0, "dog": 0.0},
        ...          "codes_heldout": {"human": [4], "dog": [10]}}
        >>> text = shared_manifold_headline(table, ["human", "dog"])
        >>> "0 of 16 codes are used by both" in text, "they share no code" in text
        (True, True)
    """

    def shares(figures: Mapping[str, Any]) -> str:
        def pct(v: float | None) -> str:
            return "n/a" if v is None or math.isnan(v) else f"{100 * v:.0f} %"

        return ", ".join(f"{n.rsplit('/', 1)[-1]} {pct(figures[n])}" for n in names if n in figures)

    held = table.get("frame_share_heldout_on_training_shared") or {}
    short = [n.rsplit("/", 1)[-1] for n in names[:2]]
    return (
        f"**Shared manifold (WalkTheDog's Table 2)**: {table.get('codes_shared_training')} of "
        f"{table.get('num_codes')} codes are used by both characters' training clips, with "
        f"{shares(table.get('frame_share_training', {}))} of the training frames"
        + (f" and {shares(held)} of the held-out frames on them" if held else " on them")
        + ". "
        + shared_codes_sentence(short[0], short[1], _short(table.get("codes_heldout", {})))
    )


def transfer_summary(
    aligner: VqpaeModel,
    datamodule: Any,
    max_clips: int | None = None,
    *,
    plan: SummaryPlan = SUMMARY_PLANS["full"],
    stages: Any = None,
    table: Mapping[str, Any] | None = None,
    steps: int | None = None,
) -> dict[str, Any]:
    """Held-out clips of the first character re-enacted by the second, model vs baseline.

    The first ``plan.transfer_clips`` validation (else test) clips of the first dataset
    (their first ``plan.transfer_seconds`` seconds: motion-capture clips can last
    minutes) go through :func:`skelagnostic_vqpae.protocols.transfer.transfer_rows` with the
    second dataset's training clips (the first ``plan.database_clips``) as the database.

    Args:
        aligner: The trained aligner.
        datamodule: Its set-up data module.
        max_clips: Source clips to transfer (default: the plan's).
        plan: What to compute (:data:`SUMMARY_PLANS`).
        stages: Called with the name of each stage as it starts (progress), optional.
        table: :func:`table2_summary`'s figures, for the picture's header (optional).
        steps: Optimiser steps of the run, for the picture's header (optional).

    Returns:
        ``{}`` without two characters, a held-out source clip or a database clip;
        else ``metrics`` (the split, the source and database clip ids, the excerpt
        length, per-clip rows and the per-method means), ``figures`` (``transfer``:
        :func:`~skelagnostic_vqpae.picture.plot_transfer` of the first clip),
        ``renders`` (``transfer``, with ``plan.animation``: the first clip, its transfer
        and the two baselines', in metres), ``render_options``
        (:func:`transfer_render_options`) and ``notes`` (a Markdown table). When the transfer
        cannot run (for example a model whose frequencies have periods longer than
        every database clip), ``metrics`` is ``{"skipped": reason}``, no picture, and
        the notes say why: the fit still succeeds.
    """
    stage = stages or (lambda name: None)
    clips = plan.transfer_clips if max_clips is None else max_clips
    found = _transfer_clips(aligner, datamodule, plan)
    if found is None:
        return {}
    split, sources, database = found
    seconds = plan.transfer_seconds
    excerpts = [c[: int(seconds * c.fps) + 1] for c in sources[:clips]]
    try:
        codes: dict[str, Any] = {}
        rows, outputs = transfer_rows(aligner, excerpts, database, codes=codes)
    except SkelagnosticError as error:  # e.g. frequencies whose periods no clip holds
        return {
            "metrics": {"skipped": str(error)},
            "renders": {},
            "notes": [f"## Transfer of held-out clips\n\nNot run: {error}\n"],
        }
    means = mean_rows(rows)
    source, target = aligner.dataset_names[0], aligner.dataset_names[1]
    first = next(iter(outputs))
    stage(f"picture of {first}")
    picture = transfer_picture(
        aligner, outputs[first], split=split, table=table, steps=steps, codes=codes.get(first)
    )
    notes = [
        _transfer_table(rows, means, split, source, target, seconds, len(database)),
        f"Picture `vqpae_transfer.png`: {first} (held-out, first {seconds:g} s) and the "
        f"`{target}` motions made from it at one scale, with the feet's touch-downs over time.",
    ]
    renders: dict[str, Any] = {}
    options: dict[str, Any] = {}
    if plan.animation:
        stage("animation")
        renders["transfer"] = [
            m[: int(RENDER_SECONDS * m.fps) + 1].to_metres() for m in outputs[first]
        ]
        options["transfer"] = transfer_render_options(aligner, outputs[first][0])
        width, height = RENDER_PANEL
        notes.append(
            f"Animation `vqpae_transfer.gif`: the first {RENDER_SECONDS:g} s of {first} at "
            f"{RENDER_FPS:g} fps, {len(renders['transfer'])} panels of {width}x{height} pixels "
            f"(the source, then the `{target}` motions made from it, named as in the picture), "
            f"a camera travelling with each character; the `{target}` panels share one scale, "
            "the source has its own."
        )
    return {
        "metrics": {
            "split": split,
            "source": source,
            "target": target,
            "excerpt_seconds": seconds,
            "database_clips": [str(c.name) for c in database],
            "halflife": HALFLIFE,
            "frequency_tolerance": FREQUENCY_TOLERANCE,
            "per_clip": rows,
            "mean": means,
        },
        "figures": {"transfer": picture},
        "renders": renders,
        "render_options": options,
        "notes": notes,
    }


def _transfer_clips(
    aligner: VqpaeModel, datamodule: Any, plan: SummaryPlan
) -> tuple[str, list[Any], list[Any]] | None:
    """``(split, held-out sources of the first character, database of the second)``, or None.

    None without two characters, a held-out (validation, else test) source clip or a
    training clip of the target.
    """
    if len(aligner.dataset_names) < 2 or not hasattr(datamodule, "sources"):
        return None
    for split in ("val", "test"):
        sources = [
            c for c in clips_of_split(datamodule, split) if aligner.dataset_of(c.skeleton) == 0
        ]
        if sources:
            break
    database = [
        c for c in clips_of_split(datamodule, "train") if aligner.dataset_of(c.skeleton) == 1
    ]
    if plan.database_clips is not None:
        database = database[: plan.database_clips]
    if not sources or not database:
        return None
    return split, sources, database


def _transfer_table(
    rows: list[dict[str, Any]],
    means: Mapping[str, Any],
    split: str,
    source: str,
    target: str,
    seconds: float,
    database: int,
) -> str:
    """The ``## Transfer of held-out clips`` section of ``summary.md``: per clip and mean."""
    lines = [
        "## Transfer of held-out clips",
        "",
        f"{len(rows)} held-out ({split}) clip(s) of `{source}` (at most their first "
        f"{seconds:g} s) re-enacted with {database} training clips of `{target}`, on the "
        "same manifold query: `model`, frequency-scaled motion matching (the paper); "
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
    return "\n".join(lines)


def transfer_labels(aligner: VqpaeModel, source: Any) -> list[str]:
    r"""The names of the source and its three transfers (the picture's and the animation's).

    Args:
        aligner: The trained aligner (its first two dataset names: source, target).
        source: The source clip (its name, if any, follows the character's).

    Returns:
        ``[source, model output, unscaled-matching output, own-rate output]`` labels,
        a newline before the method's kind.

    Example:
        >>> from types import SimpleNamespace
        >>> aligner = SimpleNamespace(dataset_names=["procedural/biped22", "dog"])
        >>> transfer_labels(aligner, SimpleNamespace(name="walk_1"))[:2]
        ['biped22: walk_1', 'dog: VQ-PAE\n(frequency-scaled matching)']
    """
    source_name, target_name = (n.rsplit("/", 1)[-1] for n in aligner.dataset_names[:2])
    clip = getattr(source, "name", None)
    return [
        f"{source_name}: {clip}" if clip else source_name,
        f"{target_name}: VQ-PAE\n(frequency-scaled matching)",
        f"{target_name}: unscaled matching\n(baseline)",
        f"{target_name}: best clip at its own rate\n(baseline)",
    ]


def transfer_render_options(aligner: VqpaeModel, source: Any) -> dict[str, Any]:
    """:func:`~skelagnostic.viz.render_motion`'s options for the transfer animation.

    Panels of :data:`RENDER_PANEL` pixels at :data:`RENDER_FPS`, a camera travelling
    with each character (the figures stay large while they walk), the labels of
    :func:`transfer_labels` (the source's says it has its own scale) and one scale
    for the three target panels (``same_scale``), as in the picture.

    Args:
        aligner: The trained aligner.
        source: The source clip.
    """
    labels = transfer_labels(aligner, source)
    labels[0] += "\n(source, its own scale)"
    return {
        "size": RENDER_PANEL,
        "fps": RENDER_FPS,
        "follow": True,
        "labels": labels,
        "same_scale": [1, 2, 3],
    }


def transfer_picture(
    aligner: VqpaeModel,
    motions: list[Any],
    split: str = "val",
    table: Mapping[str, Any] | None = None,
    steps: int | None = None,
    codes: Sequence[tuple[torch.Tensor, float]] | None = None,
) -> Any:
    """:func:`~skelagnostic_vqpae.picture.plot_transfer` of one transferred clip, titled.

    Args:
        aligner: The trained aligner.
        motions: ``[source, model output, unscaled-matching output, own-rate output]``
            (one value of :func:`~skelagnostic_vqpae.protocols.transfer.transfer_rows`' outputs).
        split: The source clip's split (held out from training).
        table: :func:`table2_summary`'s figures: the header states the shared codes.
        steps: Optimiser steps of the run, for the header (optional).
        codes: Per motion, its per-frame codes and their frame rate: the source's, then
            those of the target frames each output replays (``transfer_rows(codes=...)``);
            drawn as the picture's code strip (optional).

    Returns:
        The matplotlib figure.
    """
    source_name, target_name = aligner.dataset_names[0], aligner.dataset_names[1]
    short = source_name.rsplit("/", 1)[-1], target_name.rsplit("/", 1)[-1]
    source = motions[0]
    outputs = dict(zip(transfer_labels(aligner, source)[1:], motions[1:], strict=True))
    notes = []
    if table is not None:
        share = table.get("frame_share_training", {})
        figures = ", ".join(
            f"{n.rsplit('/', 1)[-1]} {100 * v:.0f} %"
            for n, v in share.items()
            if v is not None and not math.isnan(v)
        )
        run = f"After {steps} optimiser steps: " if steps is not None else ""
        notes.append(
            f"{run}{table.get('codes_shared_training')} of {table.get('num_codes')} codes are "
            f"shared by both characters' training clips (Table 2: training frames on them "
            f"{figures})."
        )
        notes.append(
            shared_codes_sentence(short[0], short[1], _short(table.get("codes_heldout", {})))
        )
    # the generator's feet touch down more than once per stride: mark their strides instead
    generated = any(procedural_kind(m.skeleton) is not None for m in motions)
    return plot_transfer(
        source,
        outputs,
        title=f"A held-out {short[0]} clip ({source.name}, {split} split, never trained on) "
        f"re-enacted by the {short[1]}",
        notes=notes,
        source_label=short[0],
        target_label=short[1],
        events="swing" if generated else "touchdown",
        codes=[(c.numpy(), fps) for c, fps in codes] if codes else None,
    )


def _short(codes: Mapping[str, Any]) -> dict[str, Any]:
    """``codes`` keyed by the last part of each dataset name (``procedural/biped22``: biped22)."""
    return {n.rsplit("/", 1)[-1]: v for n, v in codes.items()}


def overlap_figures(aligner: VqpaeModel, embeddings: Mapping[str, list[Any]]) -> dict[str, Any]:
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
