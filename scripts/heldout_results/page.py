"""The Markdown of ``docs/results.md`` from the loaded held-out entries."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from heldout_results.entries import METHODS, MODEL, Entry, Target, format_value


def _title(method: str) -> str:
    return METHODS.get(method, method)


def _paper_cell(figure: Mapping[str, Any]) -> str:
    if figure["value"] is None:
        return f"not comparable: {figure['why']}"
    return f"{format_value(figure['value'])} ({figure['source']})"


def _target_cell(entry: Entry, metric: str) -> str:
    cells = []
    figure = entry.figures[metric]
    for target in (t for t in entry.targets if t.metric == metric):
        bound = target.bound(figure)
        text = f"{target.op} {target.rhs}"
        if target.reference is not None:
            text += f" (= {format_value(bound)})"
        met = target.met(figure)
        verdict = "no value" if met is None else ("**met**" if met else "**not met**")
        cells.append(f"{text}: {verdict}")
    return "; ".join(cells) or "-"


def _table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|---" * len(header) + "|"]
    return lines + ["| " + " | ".join(c.replace("|", "\\|") for c in row) + " |" for row in rows]


def _quoted_table(entry: Entry) -> list[str]:
    methods = entry.methods
    rows = [
        [
            f"`{metric}`",
            *(format_value(entry.figures[metric].get(m)) for m in methods),
            _paper_cell(entry.run["paper"][metric]),
            _target_cell(entry, metric),
        ]
        for metric in entry.run["quote"]
    ]
    return _table(["metric", *methods, "paper", "target"], rows)


def _per_clip_table(entry: Entry) -> list[str]:
    report = entry.report
    metrics = list(report["metrics"])
    character = any("character" in row for row in report["per_clip"])
    rows = []
    for row in report["per_clip"]:
        for method in report["methods"]:
            if method not in row["values"]:
                continue
            values = row["values"][method]
            first = [f"`{row['clip']}`", *([str(row.get("character", "-"))] if character else [])]
            rows.append([*first, method, *(format_value(values.get(k)) for k in metrics)])
    header = ["clip", *(["character"] if character else []), "method", *metrics]
    return _table(header, rows)


def _curve_tables(entry: Entry) -> list[str]:
    """One table per curve of ``extra.curves``: a row per series and point of its curve."""
    curves = entry.curves
    lines: list[str] = []
    for kind in dict.fromkeys(k for c in curves.values() for k in c):
        columns = list(dict.fromkeys(col for c in curves.values() for col in c.get(kind, {})))
        rows = []
        for clip, mine in curves.items():
            curve = mine.get(kind, {})
            for i in range(len(next(iter(curve.values()), []))):
                cells = [format_value(curve[c][i]) if c in curve else "-" for c in columns]
                rows.append([f"`{clip}`", *cells])
        lines += [
            f"Curve `{kind}` (the evaluation's `extra.curves`: each series, e.g. a group of "
            "clips, point by point):",
            "",
            *_table(["series", *columns], rows),
            "",
        ]
    return lines


def _budget(run: Mapping[str, Any]) -> str:
    budget = run["budget"]
    text = f"{budget['steps']:,} steps, {budget['cpu_time']} CPU time"
    return text + (f", {budget['wall_time']} wall time" if "wall_time" in budget else "")


def _machine(run: Mapping[str, Any]) -> str:
    machine = run["machine"]
    text = f"{machine['cores']} cores, load {machine['load']}"
    return text + (f" ({machine['cpu']})" if "cpu" in machine else "")


def _entry_section(entry: Entry) -> list[str]:
    report, run = entry.report, entry.run
    data = report["data"]
    clips = ", ".join(f"`{c}`" for c in data["clips"])
    training = data.get("split") == "train"  # evaluate split=train: never called held out
    clips_kind = "training clips (not held out)" if training else "held-out clips"
    evaluated = "Evaluated on (not held out)" if training else "Held out"
    kinds = dict.fromkeys(k for c in entry.curves.values() for k in c)
    curve_names = f", and the curves {', '.join(f'`{k}`' for k in kinds)}" if kinds else ""
    lines = [
        f"### {run['title']}",
        "",
        f"Entry `{entry.name}`: protocol `{report['protocol']}`, measured {run['date']}. "
        f"Mean over the {clips_kind}, the model beside the baselines of the same run:",
        "",
        *_quoted_table(entry),
        "",
        *(f"- `{m}`: {entry.description(m)}" for m in run["quote"]),
        "",
        f"- {evaluated}: the {data['split_name']} of `{data['source']}`, "
        f"{len(data['clips'])} clips: {clips}",
        f"- Budget: {_budget(run)}",
        f"- Machine: {_machine(run)}",
        f"- Date: {run['date']}",
        *(f"- Reference, not a baseline: `{m}`, {why}" for m, why in run["references"].items()),
        *(f"- Note: {n}" for n in run["notes"]),
        *(f"- Protocol note: {n}" for n in report.get("notes", [])),
        f"- Every metric of every clip{curve_names}: [per-clip tables](#{entry.anchor})",
        "",
        "Reproduce:",
        "",
        "```console",
        *(f"$ {c}" for c in run["commands"]["fit"]),
        *(f"$ {c}" for c in run["commands"]["evaluate"]),
        "```",
        "",
    ]
    return lines


def render_page(entries: Sequence[Entry], methods: Sequence[str] = tuple(METHODS)) -> str:
    """The text of ``docs/results.md``."""
    lines = [
        "# Held-out results",
        "",
        "<!-- Generated by scripts/results.py from benchmarks/results/heldout/; do not edit. -->",
        "",
        "Every figure on this page was measured by `skelagnostic evaluate` on clips the run "
        "never trained on (its test split, else its validation split, or both where an entry "
        "says so: `evaluate split=heldout`; each entry lists its clips), "
        "beside the non-learned [baselines](baselines.md) computed on the same clips in the same "
        "command. The page is generated by `python scripts/results.py` from the files committed "
        "under `benchmarks/results/heldout/<entry>/`: `evaluation.json`, copied from the "
        "evaluate run directory, and `run.yaml`, with the commands, budget, machine, the "
        "paper's figures and the targets (see "
        "[Publishing results](evaluate.md#publishing-results)). "
        "`python scripts/results.py --check` fails when the page is stale.",
        "",
        "To reproduce an entry, run its commands: the fit, then the evaluation of the run "
        "directory the fit wrote, on the corpora of the [data](data.md) page. Budgets are CPU "
        "budgets on the machine each entry names; a busier machine trains fewer steps in the "
        "same time.",
        "",
    ]
    if entries:
        rows = [
            [
                _title(e.run["method"]),
                f"`{e.name}`",
                f"`{e.report['protocol']}`",
                e.run["date"],
                _budget(e.run),
                _machine(e.run),
            ]
            for e in entries
        ]
        lines += [
            *_table(["method", "entry", "protocol", "date", "budget", "machine"], rows),
            "",
            "## Targets at a glance",
            "",
            "Each target, with every entry (run) that measures it; a bound named after a "
            "baseline is that baseline's figure in the same run. No target here is met by a "
            "non-learned baseline of its run: the generator refuses such a target (a method "
            "that is not a baseline, such as the input itself, is listed as a reference). "
            "The README links this table.",
            "",
            *_status_table(entries, methods),
            "",
        ]
    for method in methods:
        mine = [e for e in entries if e.run["method"] == method]
        lines += [f"## {_title(method)}", ""]
        if not mine:
            lines += ["No held-out result committed yet.", ""]
        for entry in mine:
            lines += _entry_section(entry)
    if entries:
        lines += ["## Per-clip tables", ""]
        for entry in entries:
            lines += [
                f'<a id="{entry.anchor}"></a>',
                "",
                f"### {entry.run['title']} (`{entry.name}`, per clip)",
                "",
                *_per_clip_table(entry),
                "",
                *(f"- `{k}`: {v}" for k, v in entry.report["metrics"].items()),
                "",
                *_curve_tables(entry),
            ]
    return "\n".join(lines).rstrip("\n") + "\n"


def _target_runs(entries: Sequence[Entry], method: str) -> list[list[tuple[Entry, Target]]]:
    """The targets of a method's entries, each as every ``(entry, target)`` that sets it.

    Entries share a target when they set the same metric, operator and bound (a fixed
    bound, or the same factor of the same baseline, whose value is each run's own) on
    the same kind of held-out clips (the evaluation's ``data.split``).
    """
    groups: dict[tuple[str, str, float, str | None, str], list[tuple[Entry, Target]]] = {}
    for entry in (e for e in entries if e.run["method"] == method):
        for target in entry.targets:
            split = str(entry.report["data"]["split"])
            key = (target.metric, target.op, target.factor, target.reference, split)
            groups.setdefault(key, []).append((entry, target))
    return list(groups.values())


def _run_cell(entry: Entry, target: Target) -> str:
    figure = entry.figures[target.metric]
    text = f"`{entry.name}` {format_value(figure.get(MODEL))}"
    if target.reference is not None:
        text += f" ({target.reference} {format_value(figure.get(target.reference))})"
    met = target.met(figure)
    return text + (": no value" if met is None else (": met" if met else ": **not met**"))


def _status_table(entries: Sequence[Entry], methods: Sequence[str]) -> list[str]:
    """One row per target of each method: every run's value and how many runs meet it."""
    rows = []
    for method in methods:
        groups = _target_runs(entries, method)
        if not any(e.run["method"] == method for e in entries):
            rows.append([_title(method), "no held-out result committed yet", *["-"] * 5])
        elif not groups:
            rows.append([_title(method), "no target set", *["-"] * 5])
        for runs in groups:
            target = runs[0][1]
            met = sum(t.met(e.figures[t.metric]) is True for e, t in runs)
            papers = {
                _paper_cell(p)
                for p in (e.run["paper"][t.metric] for e, t in runs)
                if p["value"] is not None
            }
            rows.append(
                [
                    _title(method),
                    f"`{target.metric}`",
                    runs[0][0].report["data"]["split_name"],
                    f"{target.op} {target.rhs}",
                    "; ".join(_run_cell(e, t) for e, t in runs),
                    f"{met} of {len(runs)}",
                    "; ".join(sorted(papers)) or "-",
                ]
            )
    header = [
        "method",
        "held-out figure",
        "clips",
        "target",
        "runs (entry: model)",
        "met by",
        "paper's",
    ]
    return _table(header, rows)
