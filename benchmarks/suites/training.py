"""Suite ``training``: training throughput of every method at its paper's settings on CPU.

Runs each method's part in turn (each in a child process, as the parts do
themselves) and concatenates their results:

* ``benchmarks.suites.training_vqpae``: VQ-PAE windows/s with and without the
  average-pose MLPs, against the authors' ``train_vq.py`` run in the same suite
  when ``run.py --authors-repo walkthedog=DIR`` is given (absent otherwise);
* ``benchmarks.suites.training_humot``: HuMoT steps/s, windows/s and the
  data-loading share of the paper-size network;
* ``benchmarks.suites.training_pcmrl``: PC-MRL steps/s, windows/s and the
  data-loading share of both stages at the paper's sizes;
* ``benchmarks.suites.training_options``: each method's 2-CPU-hour preset under
  bf16 autocast, ``torch.compile``, twice the batch and two threads, against the
  preset as it runs.

Each part documents its settings, sizes and baselines in its own docstring.
"""

from __future__ import annotations

import importlib

from benchmarks.harness import Result

#: method -> module of its part (each has ``run(size) -> list[Result]``).
PARTS: dict[str, str] = {
    "vqpae": "benchmarks.suites.training_vqpae",
    "humot": "benchmarks.suites.training_humot",
    "pcmrl": "benchmarks.suites.training_pcmrl",
    "options": "benchmarks.suites.training_options",
}


def run(size: str) -> list[Result]:
    """Run every method's training-throughput part at ``size``."""
    results: list[Result] = []
    for module in PARTS.values():
        results.extend(importlib.import_module(module).run(size))
    return results
