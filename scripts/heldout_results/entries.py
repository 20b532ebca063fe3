"""Held-out entries: read and check ``run.yaml`` + ``evaluation.json`` of each entry.

The keys of ``run.yaml`` are described in ``scripts/results.py``; every problem is a
:class:`ResultsError` naming the file and the key.
"""

from __future__ import annotations

import datetime
import json
import math
import operator
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

#: The methods of the page, in order, with their section titles.
METHODS = {
    "vqpae": "VQ-PAE (WalkTheDog)",
    "humot": "HuMoT",
    "pcmrl": "PC-MRL stage 1 (retargeting)",
    "pcmrl_interp": "PC-MRL stage 2 (interpolation)",
}
#: The method name of the evaluated model in ``evaluation.json``.
MODEL = "model"
#: The layout of ``evaluation.json`` this script reads.
SCHEMA = 1

_OPS: dict[str, Callable[[float, float], bool]] = {
    "<=": operator.le,
    ">=": operator.ge,
    "<": operator.lt,
    ">": operator.gt,
}
_TARGET = re.compile(r"^\s*(?P<metric>[^\s<>=]+)\s*(?P<op><=|>=|<|>)\s*(?P<rhs>.+?)\s*$")
_SCALED = re.compile(r"^(?P<factor>[-+0-9.eE]+)\s*[*x×]\s*(?P<method>\S+)$")
_ENTRY_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")
_RUN_KEYS = {
    "method": True,
    "title": True,
    "date": True,
    "machine": True,
    "budget": True,
    "commands": True,
    "quote": True,
    "paper": True,
    "targets": True,
    "references": False,
    "notes": False,
}
_MACHINE_KEYS = {"cores": True, "load": True, "cpu": False}
_BUDGET_KEYS = {"steps": True, "cpu_time": True, "wall_time": False}
_COMMAND_KEYS = {"fit": True, "evaluate": True}


class ResultsError(Exception):
    """A committed entry that cannot be published; the message names the file and key."""


@dataclass(frozen=True)
class Target:
    """One target of a quoted figure: ``metric op factor [* reference]``.

    Attributes:
        metric: The quoted figure (an item of ``quote``).
        op: ``<``, ``<=``, ``>`` or ``>=``.
        factor: The bound, or its factor when ``reference`` is set.
        reference: A baseline of the same run whose figure is the bound (times
            ``factor``), or None for a fixed bound.
    """

    metric: str
    op: str
    factor: float
    reference: str | None

    @property
    def rhs(self) -> str:
        """The right-hand side as written in a table (``0.98``, ``0.5 × mean_pose``)."""
        if self.reference is None:
            return format_value(self.factor)
        return (
            self.reference
            if self.factor == 1
            else f"{format_value(self.factor)} × {self.reference}"
        )

    def bound(self, figure: Mapping[str, float]) -> float | None:
        """The bound, given the figure's ``method -> value``; None when the reference has none."""
        if self.reference is None:
            return self.factor
        value = figure.get(self.reference)
        return None if value is None else self.factor * float(value)

    def met(self, figure: Mapping[str, float]) -> bool | None:
        """Whether the model's value meets the target; None when a value is missing."""
        value, bound = figure.get(MODEL), self.bound(figure)
        if value is None or bound is None or not math.isfinite(float(value) + bound):
            return None
        return _OPS[self.op](float(value), bound)


@dataclass(frozen=True)
class Entry:
    """A committed held-out result: ``run.yaml`` validated against its ``evaluation.json``.

    Attributes:
        name: The entry's directory name.
        run: The validated ``run.yaml`` (``date`` as ``YYYY-MM-DD``, commands as lists).
        report: The ``evaluation.json``.
        figures: Each quoted figure's ``method -> value`` (:func:`quoted_figure`).
        targets: The parsed targets, in the file's order.
        curves: The evaluation's ``extra.curves`` (:func:`load_curves`; may be empty).
    """

    name: str
    run: dict[str, Any]
    report: dict[str, Any]
    figures: dict[str, dict[str, float]]
    targets: list[Target]
    curves: dict[str, dict[str, dict[str, list]]] = field(default_factory=dict)

    @property
    def methods(self) -> list[str]:
        """The methods of the quoted figures: the evaluation's, then any other of ``extra``."""
        names = dict.fromkeys(self.report["methods"])
        names.update(dict.fromkeys(m for figure in self.figures.values() for m in figure))
        return list(names)

    def description(self, quoted: str) -> str:
        """What a quoted figure is: its metric's description, or where in ``extra`` it is."""
        if quoted in self.report["metrics"]:
            return self.report["metrics"][quoted]
        metric = next((m for m in self.report["metrics"] if quoted.endswith("." + m)), None)
        where = "corpus-level figure from the evaluation's `extra`"
        return f"{self.report['metrics'][metric]} ({where})" if metric else where

    @property
    def anchor(self) -> str:
        """The HTML id of the entry's per-clip tables."""
        return "per-clip-" + re.sub(r"[^a-z0-9-]+", "-", self.name.lower())


def format_value(value: Any) -> str:
    """A figure as in ``evaluation.md`` (4 significant digits), ``-`` when absent."""
    if value is None:
        return "-"
    return f"{float(value):.4g}"


def _keys(where: str, data: Any, keys: Mapping[str, bool]) -> dict[str, Any]:
    """``data`` as a mapping with every required key of ``keys`` and no other key."""
    if not isinstance(data, Mapping):
        raise ResultsError(f"{where}: expected a mapping, got {type(data).__name__}")
    required = [k for k, needed in keys.items() if needed]
    missing = [k for k in required if k not in data]
    if missing:
        raise ResultsError(f"{_at(where, missing[0])}: missing (required: {', '.join(required)})")
    unknown = sorted(str(k) for k in set(data) - set(keys))
    if unknown:
        raise ResultsError(f"{_at(where, unknown[0])}: unknown key (known: {', '.join(keys)})")
    return dict(data)


def _at(where: str, key: str) -> str:
    """``where`` (``"<file>:"`` or ``"<file>: key"``) followed by ``key``."""
    return f"{where} {key}" if where.endswith(":") else f"{where}.{key}"


def _text(where: str, value: Any) -> str:
    if not isinstance(value, str) or not value.strip():
        raise ResultsError(f"{where}: expected a non-empty string, got {value!r}")
    return value.strip()


def _scalar_text(where: str, value: Any) -> str:
    if isinstance(value, bool) or not isinstance(value, (str, int, float)) or value == "":
        raise ResultsError(f"{where}: expected a string or a number, got {value!r}")
    return str(value)


def _lines(where: str, value: Any) -> list[str]:
    items = [value] if isinstance(value, str) else value
    if not isinstance(items, list) or not items:
        raise ResultsError(f"{where}: expected a string or a non-empty list of strings")
    return [_text(f"{where}[{i}]", item) for i, item in enumerate(items)]


def _date(where: str, value: Any) -> str:
    if isinstance(value, datetime.date):
        return value.isoformat()
    if isinstance(value, str):
        try:
            return datetime.date.fromisoformat(value).isoformat()
        except ValueError:
            pass
    raise ResultsError(f"{where}: expected a date YYYY-MM-DD, got {value!r}")


def _read(path: Path, parse: Callable[[str], Any], hint: str) -> Any:
    """``parse`` of a file's text; errors name the file (``hint``: how to provide it)."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ResultsError(f"{path}: missing ({hint})") from None
    try:
        return parse(text)
    except (json.JSONDecodeError, yaml.YAMLError) as err:
        raise ResultsError(f"{path}: does not parse ({err})") from None


def load_report(path: Path) -> dict[str, Any]:
    """Read and check an ``evaluation.json`` (the keys this script uses).

    Raises:
        ResultsError: The file is missing, not JSON, of another schema or lacks a key.
    """
    report = _read(path, json.loads, "copy it from the evaluate run directory")
    if not isinstance(report, dict):
        raise ResultsError(f"{path}: expected a JSON object")
    if report.get("schema") != SCHEMA:
        raise ResultsError(f"{path}: schema: {report.get('schema')!r}, this script reads {SCHEMA}")
    for key in ("protocol", "model", "data", "methods", "metrics", "mean", "per_clip"):
        if key not in report:
            raise ResultsError(f"{path}: {key}: missing")
    for key in ("source", "split", "split_name", "clips"):
        if key not in report["data"]:
            raise ResultsError(f"{path}: data.{key}: missing")
    if MODEL not in report["mean"]:
        raise ResultsError(f"{path}: mean.{MODEL}: missing")
    return report


def parse_target(where: str, text: Any, figures: Mapping[str, Mapping[str, float]]) -> Target:
    """Parse ``"metric op bound"`` (bound: a number, a baseline of the run, or ``k * baseline``).

    Args:
        where: The file and key, for errors.
        text: The target as written.
        figures: The quoted figures, ``quote item -> method -> value``.

    Raises:
        ResultsError: The text does not parse, or names a figure that is not quoted or a
            baseline the figure lacks.
    """
    match = _TARGET.match(text) if isinstance(text, str) else None
    if match is None:
        raise ResultsError(
            f"{where}: {text!r} is not 'metric OP bound' (OP one of <, <=, >, >=; bound a "
            "number, a method of the run or 'FACTOR * method')"
        )
    metric, rhs = match["metric"], match["rhs"]
    if metric not in figures:
        raise ResultsError(f"{where}: {metric!r} is not quoted (quote: {', '.join(figures)})")
    try:
        return Target(metric, match["op"], float(rhs), None)
    except ValueError:
        pass
    scaled = _SCALED.match(rhs)
    factor, method = (scaled["factor"], scaled["method"]) if scaled else ("1", rhs)
    try:
        factor = float(factor)
    except ValueError:
        raise ResultsError(f"{where}: {factor!r} in {rhs!r} is not a number") from None
    baselines = [m for m in figures[metric] if m != MODEL]
    if method not in baselines:
        raise ResultsError(
            f"{where}: {rhs!r} is neither a number nor a baseline of the run with a value of "
            f"{metric!r} (its baselines: {', '.join(baselines) or 'none'})"
        )
    return Target(metric, match["op"], factor, method)


def _references(where: str, raw: Any, report: Mapping[str, Any]) -> dict[str, str]:
    """``references``: methods of the run that are not baselines, each with its reason."""
    if raw is None:
        return {}
    if not isinstance(raw, dict):
        raise ResultsError(f"{where}: expected a mapping method -> why it is not a baseline")
    methods = [m for m in report.get("methods", []) if m != MODEL]
    out = {}
    for method, why in raw.items():
        if method not in methods:
            raise ResultsError(
                f"{where}: {method!r} is not a method of the run (its methods: "
                f"{', '.join(methods) or 'none'})"
            )
        out[str(method)] = _text(f"{where}.{method}", why)
    return out


def refuse_trivial_target(
    where: str,
    target: Target,
    figure: Mapping[str, float],
    references: Mapping[str, str] | None = None,
) -> None:
    """Refuse a target that a non-learned baseline of the same run also meets.

    A target is there to show what the model learned: when a baseline's value
    (the same metric, the same clips, the same run) meets the bound too, the
    target says nothing about the model, whatever the model's value.

    Args:
        where: The file and key, for the message.
        target: The parsed target.
        figure: The quoted figure, ``method -> value`` (the model and its baselines).
        references: Methods of the run that are not baselines (exempt), with the reason.

    Raises:
        ResultsError: A baseline meets the target; the message names it and its value.
    """
    bound = target.bound(figure)
    if bound is None or not math.isfinite(bound):
        return
    for method, value in figure.items():
        if method == MODEL or method in (references or {}) or value is None:
            continue
        if not math.isfinite(float(value)):
            continue
        if _OPS[target.op](float(value), bound):
            raise ResultsError(
                f"{where}: {target.metric} {target.op} {target.rhs} is also met by the "
                f"baseline {method} ({format_value(value)}); a target must be one that no "
                "non-learned baseline of the run meets"
            )


def load_entry(directory: Path, methods: Sequence[str] = tuple(METHODS)) -> Entry:
    """Read and validate one entry directory.

    Args:
        directory: ``benchmarks/results/heldout/<entry>``.
        methods: The method names ``run.yaml`` may give.

    Returns:
        The entry.

    Raises:
        ResultsError: A file is missing or malformed; the message names the file and key.
    """
    if not _ENTRY_NAME.match(directory.name):
        raise ResultsError(f"{directory}: entry names are letters, digits, '_', '-' and '.'")
    report = load_report(directory / "evaluation.json")
    path = directory / "run.yaml"
    raw = _read(path, yaml.safe_load, "see scripts/results.py for its keys")
    run = _keys(f"{path}:", raw, _RUN_KEYS)
    where = f"{path}: "
    if run["method"] not in methods:
        raise ResultsError(f"{where}method: {run['method']!r} is not one of {', '.join(methods)}")
    if run["method"] != report["model"]:
        raise ResultsError(
            f"{where}method: {run['method']!r}, but evaluation.json evaluates "
            f"model={report['model']}"
        )
    run["title"] = _text(f"{where}title", run["title"])
    run["date"] = _date(f"{where}date", run["date"])
    machine = _keys(f"{where}machine", run["machine"], _MACHINE_KEYS)
    cores = machine["cores"]
    if isinstance(cores, bool) or not isinstance(cores, int) or cores < 1:
        raise ResultsError(f"{where}machine.cores: expected a positive integer, got {cores!r}")
    machine["load"] = _scalar_text(f"{where}machine.load", machine["load"])
    if "cpu" in machine:
        machine["cpu"] = _text(f"{where}machine.cpu", machine["cpu"])
    run["machine"] = machine
    budget = _keys(f"{where}budget", run["budget"], _BUDGET_KEYS)
    steps = budget["steps"]
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 0:
        raise ResultsError(f"{where}budget.steps: expected an integer >= 0, got {steps!r}")
    for key in ("cpu_time", "wall_time"):
        if key in budget:
            budget[key] = _scalar_text(f"{where}budget.{key}", budget[key])
    run["budget"] = budget
    commands = _keys(f"{where}commands", run["commands"], _COMMAND_KEYS)
    run["commands"] = {k: _lines(f"{where}commands.{k}", v) for k, v in commands.items()}
    quote = run["quote"]
    if not isinstance(quote, list) or not quote:
        raise ResultsError(f"{where}quote: expected a non-empty list of metrics")
    if len(set(map(str, quote))) != len(quote):
        raise ResultsError(f"{where}quote: a metric is listed twice")
    figures = {
        str(item): quoted_figure(f"{where}quote[{i}]", item, report) for i, item in enumerate(quote)
    }
    run["paper"] = _paper(f"{where}paper", run["paper"], quote)
    if not isinstance(run["targets"], list):
        raise ResultsError(f"{where}targets: expected a list of 'metric OP bound' (may be empty)")
    targets = [
        parse_target(f"{where}targets[{i}]", text, figures) for i, text in enumerate(run["targets"])
    ]
    run["references"] = _references(f"{where}references", run.get("references"), report)
    for i, target in enumerate(targets):
        refuse_trivial_target(
            f"{where}targets[{i}]", target, figures[target.metric], run["references"]
        )
    run["notes"] = _lines(f"{where}notes", run["notes"]) if run.get("notes") else []
    curves = load_curves(f"{directory / 'evaluation.json'}: ", report)
    return Entry(directory.name, run, report, figures, targets, curves)


def load_curves(where: str, report: Mapping[str, Any]) -> dict[str, dict[str, dict[str, list]]]:
    """The evaluation's ``extra.curves``: ``series -> curve -> column -> [values]`` (may be empty).

    HuMoT's reconstruction protocol writes its denoising (Fig. 8) and joint-upsampling
    (Fig. 9) curves there, one series per group of held-out clips of one topology; the
    page shows them as tables, one per curve.

    Raises:
        ResultsError: ``extra.curves`` is not that shape, or a curve's columns differ in
            length; the message names the key.
    """
    curves = report.get("extra", {}).get("curves", {}) if isinstance(report, Mapping) else {}
    if not isinstance(curves, Mapping):
        raise ResultsError(f"{where}extra.curves: expected a mapping clip -> curve -> columns")
    out: dict[str, dict[str, dict[str, list]]] = {}
    for clip, kinds in curves.items():
        if not isinstance(kinds, Mapping):
            raise ResultsError(f"{where}extra.curves.{clip}: expected a mapping curve -> columns")
        for kind, columns in kinds.items():
            at = f"{where}extra.curves.{clip}.{kind}"
            if not isinstance(columns, Mapping) or not columns:
                raise ResultsError(f"{at}: expected a mapping column -> list of numbers")
            bad = [
                k for k, v in columns.items() if not (isinstance(v, list) and all(map(_number, v)))
            ]
            if bad:
                raise ResultsError(f"{at}.{bad[0]}: expected a list of numbers")
            lengths = {len(v) for v in columns.values()}
            if len(lengths) != 1:
                raise ResultsError(f"{at}: its columns differ in length ({sorted(lengths)})")
            out.setdefault(str(clip), {})[str(kind)] = {str(k): v for k, v in columns.items()}
    return out


def quoted_figure(where: str, item: Any, report: Mapping[str, Any]) -> dict[str, float]:
    """``method -> value`` of a quoted figure.

    ``item`` is a metric of the mean table (every method's mean), or ``extra.<key>.<key>...``:
    a number of the evaluation's ``extra`` (the model's figure, e.g. a corpus-level count)
    or a mapping ``method -> number`` there (the model beside baselines, e.g. one
    character's means), or ``extra.<key>...<metric>`` of a method-major mapping
    ``method -> metric -> number`` (e.g. HuMoT's ``extra.by_topology.unseen.mpjpe_cm``).
    Keys may contain dots: the longest key that matches is taken.

    Raises:
        ResultsError: The item names no such metric or key, or the key holds something else.
    """
    if not isinstance(item, str):
        raise ResultsError(f"{where}: expected a metric name or 'extra.<key>...', got {item!r}")
    if not item.startswith("extra."):
        if item not in report["metrics"] or item not in report["mean"][MODEL]:
            raise ResultsError(
                f"{where}: {item!r} is not a metric with a mean value of the model in "
                f"evaluation.json (its metrics: {', '.join(report['metrics'])}; or 'extra.<key>')"
            )
        return {m: float(v[item]) for m, v in report["mean"].items() if v.get(item) is not None}
    node: Any = report.get("extra", {})
    path, rest = "extra", item[len("extra.") :]
    while rest:
        if not isinstance(node, Mapping):
            raise ResultsError(f"{where}: {item!r}: evaluation.json's {path} is not a mapping")
        keys = [k for k in node if rest == k or rest.startswith(f"{k}.")]
        per_method = node.get(MODEL)
        if not keys and isinstance(per_method, Mapping) and _number(per_method.get(rest)):
            # a method-major table (method -> metric -> number): the metric of every method
            return {
                str(m): float(v[rest])
                for m, v in node.items()
                if isinstance(v, Mapping) and _number(v.get(rest))
            }
        if not keys:
            raise ResultsError(
                f"{where}: {item!r}: evaluation.json's {path} has no key {rest.split('.')[0]!r} "
                f"(its keys: {', '.join(map(str, node)) or 'none'})"
            )
        key = max(keys, key=len)
        node, path, rest = node[key], f"{path}.{key}", rest[len(key) + 1 :]
    if _number(node):
        return {MODEL: float(node)}
    if isinstance(node, Mapping) and _number(node.get(MODEL)):
        return {str(m): float(v) for m, v in node.items() if _number(v)}
    raise ResultsError(
        f"{where}: {item!r} holds neither a number nor a mapping method -> number with a "
        f"{MODEL!r} value"
    )


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _paper(where: str, paper: Any, quote: Sequence[str]) -> dict[str, dict[str, Any]]:
    """Validate ``paper``: for each quoted metric a value with its source, or null with why."""
    keys = {metric: True for metric in quote}
    paper = _keys(where, paper, keys)
    out = {}
    for metric, figure in paper.items():
        item = f"{where}.{metric}"
        figure = _keys(item, figure, {"value": True, "source": False, "why": False})
        value = figure["value"]
        if value is None:
            if "why" not in figure:
                raise ResultsError(f"{item}.why: missing (say why the paper has no such figure)")
            out[metric] = {"value": None, "why": _text(f"{item}.why", figure["why"])}
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ResultsError(f"{item}.value: expected a number or null, got {value!r}")
        if "source" not in figure:
            raise ResultsError(f"{item}.source: missing (where the paper gives it, e.g. Table 2)")
        out[metric] = {"value": float(value), "source": _text(f"{item}.source", figure["source"])}
    return out


def load_entries(root: Path, methods: Sequence[str] = tuple(METHODS)) -> list[Entry]:
    """Every entry under ``root``, ordered by method, then date, then name.

    Raises:
        ResultsError: ``root`` is not a directory, or an entry is malformed.
    """
    if not root.is_dir():
        raise ResultsError(f"{root}: not a directory of held-out entries")
    entries = [load_entry(d, methods) for d in sorted(root.iterdir()) if d.is_dir()]
    order = list(methods)
    return sorted(entries, key=lambda e: (order.index(e.run["method"]), e.run["date"], e.name))


# --- rendering ------------------------------------------------------------------------------
