"""Evaluation protocols: held-out clips in, every figure beside its baselines out.

A plugin registers protocols through the ``register_evaluations`` hook (see
:mod:`skelagnostic.plugins.hookspecs`); ``skelagnostic evaluate`` builds the
run's aligner and data, loads the checkpoint, collects the held-out clips
(:func:`held_out`), calls the protocol and writes its :class:`Evaluation` with
:func:`write_evaluation`:

* ``evaluation.json``: the protocol, the data (config, split, clip names), the
  checkpoint, the metric descriptions, per-clip rows and their mean for the
  model and every baseline computed in the same run;
* ``evaluation.md``: the same as Markdown tables;
* ``evaluation.png``: the mean figures, model beside baselines, plus the
  protocol's own plots.

A protocol is a plain function ``protocol(aligner, held_out, out_dir) -> Evaluation``,
so tests and benchmarks call it without the command line.

The framework lives in four modules: :mod:`~skelagnostic.evaluation.protocol`
(what a protocol receives and returns), :mod:`~skelagnostic.evaluation.reconstruction`
(the reconstruction rows a simple protocol reuses), :mod:`~skelagnostic.evaluation.feet`
(every method's foot skate on the ground truth's contacts) and
:mod:`~skelagnostic.evaluation.report` (the files above); this package re-exports
their public names, the import path plugins use::

    from skelagnostic.evaluation import MODEL, Evaluation, HeldOut, mean_rows
"""

from skelagnostic.evaluation.feet import (
    FOOT_SKATE_METRICS,
    GROUND_TRUTH,
    SKATE_THRESHOLD,
    foot_skate_figures,
    foot_skate_rows,
    own_foot_skate,
    skate_feet,
)
from skelagnostic.evaluation.protocol import (
    MODEL,
    SPLITS,
    Evaluation,
    EvaluationError,
    HeldOut,
    clips_of_split,
    held_out,
    mean_rows,
    track,
)
from skelagnostic.evaluation.reconstruction import RECONSTRUCTION_METRICS, reconstruction_rows
from skelagnostic.evaluation.report import markdown, portable_names, write_evaluation

__all__ = [
    "FOOT_SKATE_METRICS",
    "GROUND_TRUTH",
    "MODEL",
    "RECONSTRUCTION_METRICS",
    "SKATE_THRESHOLD",
    "SPLITS",
    "Evaluation",
    "EvaluationError",
    "HeldOut",
    "clips_of_split",
    "foot_skate_figures",
    "foot_skate_rows",
    "held_out",
    "markdown",
    "mean_rows",
    "own_foot_skate",
    "portable_names",
    "reconstruction_rows",
    "skate_feet",
    "track",
    "write_evaluation",
]
