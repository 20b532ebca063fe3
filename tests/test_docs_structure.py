"""The README, the docs' nav and the changelog stay readable for a newcomer (issue 48, 1-3)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from script_loader import load_script

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
docs_words = load_script("scripts/docs_words.py", "docs_words")


def _readme_words() -> tuple[int, int]:
    """The README's words, and the words before its first command (its first shell block)."""
    text = README.read_text(encoding="utf-8")
    first = re.search(r"^```(bash|console|sh)$", text, re.MULTILINE)
    assert first, "the README has no shell block"
    return len(text.split()), len(text[: first.start()].split())


def test_readme_is_short_and_reaches_its_first_command_early() -> None:
    total, before = _readme_words()
    assert total < 1200, f"README.md has {total} words (limit 1,200)"
    assert before < 400, f"README.md's first command comes after {before} words (limit 400)"


def _status_rows() -> list[list[str]]:
    """The README status table's method rows (those naming a ``model=``), as cells."""
    text = README.read_text(encoding="utf-8")
    rows = [line.strip("|").split(" | ") for line in text.splitlines() if line.startswith("| ")]
    return [row for row in rows if "model=" in row[0]]


def test_readme_quotes_only_figures_of_the_results_page() -> None:
    """Every decimal figure of a method's status line is on docs/results.md (not invented)."""
    results = (REPO / "docs" / "results.md").read_text(encoding="utf-8")
    rows = _status_rows()
    assert len(rows) == 4, rows  # VQ-PAE, HuMoT, PC-MRL stage 1 and stage 2
    for row in rows:
        figures = re.findall(r"\d+\.\d+", row[1])
        assert len(figures) >= 2, f"no headline figure beside a baseline in {row[0]}"
        for figure in figures:
            assert re.search(rf"(?<![\d.]){re.escape(figure)}(?!\d)", results), (
                f"README's {row[0]} quotes {figure}, which docs/results.md does not hold"
            )
        assert "docs/results.md" in row[2] and "docs/methods/" in row[2]


def test_readme_links_its_local_pages() -> None:
    """Each relative Markdown link of the README names a file of the checkout.

    The main job's picture is made by the run and committed separately; it is the
    one image the README may name before it lands.
    """
    text = README.read_text(encoding="utf-8")
    for target in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", text):
        if target.startswith("http") or target == "docs/assets/vqpae_main_job.png":
            continue
        assert (REPO / target).exists(), f"README.md links {target}, which does not exist"


def test_guides_hold_most_of_the_words_of_the_navs_first_two_levels() -> None:
    config = REPO / "mkdocs.yml"
    counts = docs_words.by_section(config)
    assert "Lab record" in counts and "Getting started" in counts
    share = docs_words.guide_share(counts)
    assert share >= 0.5, f"guides + reference: {share:.1%} of the nav's first two levels"
    # the nav lists guides first: the lab record is the last top-level section
    assert list(counts)[-1] == "Lab record" and list(counts)[:2] == ["Home", "Getting started"]


def test_words_are_counted_by_section_and_depth(tmp_path: Path) -> None:
    (tmp_path / "docs" / "r").mkdir(parents=True)
    (tmp_path / "docs" / "a.md").write_text("one two three\n")
    (tmp_path / "docs" / "b.md").write_text('four\n--8<-- "NOTES.md"\n')
    (tmp_path / "NOTES.md").write_text("five six\n")
    (tmp_path / "docs" / "r" / "deep.md").write_text("x " * 100)
    (tmp_path / "mkdocs.yml").write_text(
        "site_name: t\n"
        "extra_javascript:\n  - !!python/name:tags.example\n"
        "nav:\n"
        "  - Home: a.md\n"
        "  - Lab record:\n"
        "      - Notes: b.md\n"
        "      - Reports:\n"
        "          - Deep: r/deep.md\n"
    )
    counts = docs_words.by_section(tmp_path / "mkdocs.yml")
    assert counts == {"Home": 3, "Lab record": 3}  # the snippet counted, the deep page not
    assert docs_words.guide_share(counts) == pytest.approx(0.5)
    deeper = docs_words.by_section(tmp_path / "mkdocs.yml", max_depth=99)
    assert deeper == {"Home": 3, "Lab record": 103}


REPORTS = sorted((REPO / "docs" / "reports").glob("*.md"))


@pytest.mark.parametrize("report", REPORTS, ids=lambda p: p.stem)
def test_each_report_opens_with_a_table_of_its_current_conclusions(report: Path) -> None:
    """The first section of a report is its summary table, ahead of the records."""
    text = report.read_text(encoding="utf-8")
    first = re.search(r"^## (.+)$", text, re.MULTILINE)
    assert first and first[1].startswith("Current conclusions"), (report.name, first)
    section = text[first.end() :].split("\n## ", 1)[0]
    assert re.search(r"^\|---", section, re.MULTILINE), f"{report.name}: no table"
    nav = (REPO / "mkdocs.yml").read_text(encoding="utf-8")
    assert f"reports/{report.name}" in nav


def test_performance_page_opens_with_its_goals() -> None:
    text = (REPO / "docs" / "performance.md").read_text(encoding="utf-8")
    first = re.search(r"^## (.+)$", text, re.MULTILINE)
    assert first and first[1] == "Goals at a glance"
    section = text[first.end() :].split("\n## ", 1)[0]
    assert "| goal | measured | status | details |" in section
    # the measurements live in the report, not on the guide
    assert "## Suite `" not in text and "<!-- benchmarks:start -->" not in text


KINDS = ("Added", "Changed", "Deprecated", "Removed", "Fixed", "Security")


def test_changelog_entries_are_one_short_line_each() -> None:
    """Keep a Changelog: versions, then kinds of change, then one-line entries of ~20 words."""
    text = (REPO / "CHANGELOG.md").read_text(encoding="utf-8")
    body = text.split("\n## [Unreleased]\n", 1)[1]
    kind = None
    entries = 0
    for line in body.splitlines():
        if line.startswith("## ["):
            kind = None  # a released version
        elif line.startswith("### "):
            kind = line[4:]
            assert kind in KINDS, f"CHANGELOG.md: unknown section {line!r}"
        elif line.startswith("- "):
            assert kind is not None, f"CHANGELOG.md: entry before a section: {line!r}"
            entries += 1
            assert len(line[2:].split()) <= 25, f"CHANGELOG.md: {len(line.split())} words: {line}"
        elif line.startswith(("  ", "#")) or (line and kind is not None):
            pytest.fail(f"CHANGELOG.md: line {line!r} is neither a heading nor a one-line entry")
    assert entries >= 50
    # the docs page includes the file
    assert '--8<-- "CHANGELOG.md"' in (REPO / "docs" / "changelog.md").read_text()
