"""Hostile names in the Markdown reports (``evaluation.md``, ``summary.md``) show literally.

Clip, method, metric, dataset and checkpoint names holding ``|``, backticks,
HTML (``<img onerror=...>``), Markdown links and images, or line ends must not
split a table cell, end a table, or become an element when the report is
rendered. Each report is rendered with two Markdown engines (CommonMark with
tables, as GitHub; Python-Markdown, as MkDocs) and read back cell by cell.
"""

from __future__ import annotations

from html.parser import HTMLParser
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from markdown_it import MarkdownIt

from skelagnostic.callbacks import FitSummary
from skelagnostic.errors import printable
from skelagnostic.evaluation import markdown
from skelagnostic.io.markdown import markdown_cell

HOSTILE = (
    "a|b",
    "`tick` ``two``",
    "<img src=x onerror=alert(1)>",
    "</td></tr></table><script>alert(1)</script>",
    "<!-- comment",
    "[link](javascript:alert(1)) ![img](http://example.com/t.png)",
    "*em* _under_ **strong** mpjpe_cm",
    "back\\slash\\",
    "line\nbreak\r\nand\u2028more",
    "&amp; &lt; &#124;",
    "RTL \u05e2\u05d1\u05e8\u05d9\u05ea \U0001f9b4",
)


class _Tables(HTMLParser):
    """Rows of cell texts of every table, the tags met and the text of an HTML fragment."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.rows: list[list[str]] = []
        self.tags: set[str] = set()
        self.text = ""
        self._cell: str | None = None

    def handle_starttag(self, tag: str, attrs: Any) -> None:
        self.tags.add(tag)
        if tag == "tr":
            self.rows.append([])
        elif tag in ("td", "th"):
            self._cell = ""

    def handle_endtag(self, tag: str) -> None:
        if tag in ("td", "th") and self._cell is not None:
            self.rows[-1].append(self._cell)
            self._cell = None

    def handle_data(self, data: str) -> None:
        self.text += data
        if self._cell is not None:
            self._cell += data


def _render_commonmark(text: str) -> str:
    return MarkdownIt("commonmark").enable("table").render(text)


def _render_python_markdown(text: str) -> str:
    markdown_module = pytest.importorskip("markdown")
    return markdown_module.markdown(text, extensions=["tables"])


RENDERERS = [_render_commonmark, _render_python_markdown]


def _tables(page: str, render: Any) -> _Tables:
    parsed = _Tables()
    parsed.feed(render(page))
    # nothing but tables, their cells, headings, lists, paragraphs and code
    allowed = {"table", "thead", "tbody", "tr", "th", "td", "h1", "h2", "p", "ul", "li", "code"}
    assert parsed.tags <= allowed, parsed.tags - allowed
    return parsed


def _shown(name: str) -> str:
    """What a cell shows for ``name``: control characters escaped, outer spaces trimmed."""
    return printable(name).strip()


@pytest.mark.parametrize("name", HOSTILE)
@pytest.mark.parametrize("code", [False, True])
@pytest.mark.parametrize("render", RENDERERS)
def test_markdown_cell_shows_the_name_literally(name: str, code: bool, render: Any) -> None:
    page = f"| name | n |\n|---|---|\n| {markdown_cell(name, code=code)} | 1 |\n"
    parsed = _tables(page, render)
    assert parsed.rows[1:] == [[_shown(name), "1"]]
    assert ("code" in parsed.tags) == code
    assert "\n" not in markdown_cell(name, code=code)


@pytest.mark.parametrize("render", RENDERERS)
def test_evaluation_md_tables_hold_hostile_names(render: Any) -> None:
    clips, methods = HOSTILE[:4], ["model", *HOSTILE[4:7]]
    metrics = {"mpjpe_cm": "mean error | per joint (cm)", HOSTILE[7]: HOSTILE[8]}
    values = {m: {k: 1.5 for k in metrics} for m in methods}
    report = {
        "protocol": HOSTILE[9],
        "description": "",
        "model": HOSTILE[1],
        "checkpoint": "/runs/`x`|y/<b>.ckpt",
        "data": {"source": HOSTILE[2], "split_name": "test split", "clips": list(clips)},
        "methods": methods,
        "metrics": metrics,
        "mean": values,
        "per_clip": [{"clip": clip, "values": values} for clip in clips],
    }
    parsed = _tables(markdown(report), render)
    mean, per_clip = parsed.rows[: len(metrics) + 1], parsed.rows[len(metrics) + 1 :]
    assert mean[0] == ["metric", *map(_shown, methods)]
    assert [row[0] for row in mean[1:]] == [_shown(f"{k} ({t})") for k, t in metrics.items()]
    assert per_clip[0] == ["clip", "method", *map(_shown, metrics)]
    assert [row[:2] for row in per_clip[1:]] == [
        [_shown(clip), _shown(method)] for clip in clips for method in methods
    ]
    assert {len(row) for row in mean} == {len(methods) + 1}
    assert {len(row) for row in per_clip} == {len(metrics) + 2}
    assert f"model: {HOSTILE[1]}, checkpoint {report['checkpoint']}\n" in parsed.text
    assert f"data: {HOSTILE[2]}, test split (4 clips)" in parsed.text
    assert parsed.text.startswith(f"Evaluation: {HOSTILE[9]}\n")


@pytest.mark.parametrize("render", RENDERERS)
def test_summary_md_tables_hold_hostile_names(render: Any, tmp_path: Path) -> None:
    trainer = SimpleNamespace(current_epoch=1, global_step=5)
    logged = {f"train/{name}": 0.25 for name in HOSTILE}
    content = {"metrics": {name: name for name in HOSTILE}}
    text = FitSummary(name=HOSTILE[2])._markdown(
        trainer, logged, content, tmp_path / "m_metrics.json", []
    )
    parsed = _tables(text, render)
    assert parsed.rows == [
        ["metric", "value"],
        *([_shown(key), "0.25"] for key in sorted(logged)),
        ["figure", "value"],
        *([_shown(name), _shown(name)] for name in HOSTILE),
    ]
    assert text.startswith(f"# Fit summary: {markdown_cell(HOSTILE[2])}\n")


def test_pcmrl_tables_hold_hostile_model_names() -> None:
    evaluation = pytest.importorskip("skelagnostic_pcmrl.evaluation")
    interp_eval = pytest.importorskip("skelagnostic_pcmrl.interp.evaluation")
    rows = {name: {"knn@0.1": 1.0, "l_end": 2.0} for name in HOSTILE}
    parsed = _tables(evaluation.format_table({"rows": rows}), _render_commonmark)
    assert [row[0] for row in parsed.rows[1:]] == list(map(_shown, HOSTILE))
    assert all(len(row) == 3 for row in parsed.rows)
    gap = {f"{m}": 1.0 for m in ("l2p", "l2q", "npss")}
    report = {"protocol": {"gaps": [5]}, "results": {name: {"5": gap} for name in HOSTILE}}
    parsed = _tables(interp_eval.format_table(report), _render_commonmark)
    assert [row[0] for row in parsed.rows[1:]] == list(map(_shown, HOSTILE))
    assert all(len(row) == 4 for row in parsed.rows)
