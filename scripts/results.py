r"""Write ``docs/results.md`` from the committed held-out entries.

An entry is a directory ``benchmarks/results/heldout/<entry>/`` with two files:

* ``evaluation.json``: copied unchanged from the run directory of a
  ``skelagnostic evaluate`` command (its layout: ``docs/evaluate.md``);
* ``run.yaml``: what the JSON does not hold::

    method: vqpae                  # vqpae, humot, pcmrl or pcmrl_interp (the JSON's model)
    title: VQ-PAE, LaFAN1 + MANN dog, K = 32
    date: 2026-12-03
    machine: {cores: 2, load: "about 2 (one other run)", cpu: "optional text"}
    budget: {steps: 15000, cpu_time: "2 h", wall_time: "optional text"}
    commands:
      fit: skelagnostic fit model=vqpae experiment=vqpae_cpu2h ...     # or a list
      evaluate: skelagnostic evaluate ckpt_path=runs/vqpae/fit/<stamp>  # or a list
    quote:                          # metrics of the JSON's mean table, or keys of its extra
      - shared_code_share
      - pose_mpjpe_cm
      - extra.table1.dog.pose_mpjpe_cm   # a number, or a mapping method -> number
      - extra.by_topology.seen.mpjpe_cm  # or the metric of a mapping method -> metric -> number
    paper:                          # one per quoted figure
      shared_code_share: {value: 0.98, source: "Table 2"}
      pose_mpjpe_cm: {value: null, why: "the paper reports it per character"}
      extra.table1.dog.pose_mpjpe_cm: {value: 1.41, source: "Table 1"}
    targets:                        # targets on quoted figures
      - shared_code_share >= 0.98
      - pose_mpjpe_cm < 0.9 * mean_pose     # a number, a baseline of the run, or k * baseline
    references:                     # optional: methods of the run that are not baselines
      original: "the source motion itself: the best reachable value, not a method"
    notes: ["optional sentences"]

A target must be one that no non-learned baseline of the same run meets (the
model beating a bound that a baseline also beats shows nothing): the script
refuses such an entry, naming the baseline. A method of the run that is not a
baseline (the input itself, an oracle that knows the answer) is listed under
``references`` with the reason, and is exempt.

The page opens with the status of every target (one row per target of a method,
listing each entry that measures it and how many meet it; the README links that
table and quotes one headline figure per method by hand), then lists, per method,
the quoted mean figures of the model beside every baseline of the same run, the
paper's figure and the target (met or not met), then the held-out clips, the
budget, the machine, the date and the commands, and the per-clip tables at the
end. A method without an entry is listed as having no held-out result yet.

Usage::

    python scripts/results.py            # rewrite docs/results.md
    python scripts/results.py --check    # exit 1 when it is stale

Only PyYAML is needed (no torch): the script reads the files and writes Markdown.
"""

from __future__ import annotations

import argparse
import difflib
import sys
from collections.abc import Sequence
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
#: Where the committed entries live.
HELDOUT = REPO / "benchmarks" / "results" / "heldout"
#: The generated page.
RESULTS_PAGE = REPO / "docs" / "results.md"

sys.path.insert(0, str(Path(__file__).resolve().parent))  # heldout_results, next to this script
from heldout_results.entries import (  # noqa: E402
    METHODS,
    ResultsError,
    Target,
    load_entries,
    parse_target,
    quoted_figure,
)
from heldout_results.page import render_page  # noqa: E402

__all__ = ["Target", "main", "parse_target", "quoted_figure", "render_page"]


def _diff(path: Path, old: str, new: str, limit: int = 40) -> str:
    lines = list(
        difflib.unified_diff(
            old.splitlines(), new.splitlines(), f"{path} (committed)", f"{path} (generated)", n=1
        )
    )
    more = f"\n... {len(lines) - limit} more diff lines" if len(lines) > limit else ""
    return "\n".join(lines[:limit]) + more


def main(argv: Sequence[str] | None = None) -> int:
    """Write (or with ``--check`` compare) the results page."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=HELDOUT, help="directory of the entries")
    parser.add_argument("--out", type=Path, default=RESULTS_PAGE, help="the page to write")
    parser.add_argument(
        "--methods",
        default=",".join(METHODS),
        help="comma-separated methods, one section each, in order (default: %(default)s)",
    )
    parser.add_argument(
        "--check", action="store_true", help="write nothing; exit 1 when a file is stale"
    )
    args = parser.parse_args(argv)
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    try:
        entries = load_entries(args.root, methods)
        outputs = {args.out: render_page(entries, methods)}
    except ResultsError as err:
        print(f"results: {err}", file=sys.stderr)
        return 2
    stale = []
    for path, text in outputs.items():
        old = path.read_text(encoding="utf-8") if path.is_file() else ""
        if old == text:
            continue
        if args.check:
            stale.append(_diff(path, old, text))
        else:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text, encoding="utf-8")
            print(f"results: wrote {path} ({len(entries)} entries)")
    if stale:
        command = "python scripts/results.py"
        print(
            f"results: stale, not what the committed entries give (run {command}):",
            *stale,
            sep="\n",
            file=sys.stderr,
        )
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
