r"""Count the words of the docs pages by section of the mkdocs nav.

A reader of the site meets the nav's first two levels without unfolding
anything: the top-level pages and sections, and the pages directly in a
section. This script counts the words of those pages' Markdown (snippets
included with ``--8<--`` are counted where they are included), grouped by their
top-level section, and the share of them that guides and reference pages hold:
every section but the lab record (results, reports, changelog). Pages deeper in
the nav (the reports, under "Lab record" -> "Reports") are listed apart.

The API reference that mkdocstrings renders from ``::: name`` lines counts as
one word per line here, so the guides' share is a lower bound.

Usage::

    python scripts/docs_words.py          # a table by section, then the share

Only PyYAML is needed.
"""

from __future__ import annotations

import re
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

REPO = Path(__file__).resolve().parents[1]
#: The top-level nav sections that are not guides or reference.
RECORD_SECTIONS = ("Lab record",)
#: A ``pymdownx.snippets`` include line.
SNIPPET = re.compile(r'^--8<-- "([^"]+)"\s*$', re.MULTILINE)


@dataclass(frozen=True)
class Page:
    """A page of the nav: its file, top-level section and depth (1: top level)."""

    path: str
    section: str
    depth: int


class _Loader(yaml.SafeLoader):
    """A safe loader that reads mkdocs' ``!!python/name:`` tags as plain strings."""


_Loader.add_multi_constructor("tag:yaml.org,2002:python/", lambda loader, suffix, node: None)


def nav_pages(config: Path) -> list[Page]:
    """Every page of the nav of ``config`` (``mkdocs.yml``), in nav order."""
    nav = yaml.load(config.read_text(encoding="utf-8"), Loader=_Loader)["nav"]

    def walk(items: list[Any], section: str | None, depth: int) -> Iterator[Page]:
        for item in items:
            ((title, value),) = item.items()
            if isinstance(value, str):
                yield Page(value, section or title, depth)
            else:
                yield from walk(value, section or title, depth + 1)

    return list(walk(nav, None, 1))


def words(page: Path, base: Path) -> int:
    """The words of a Markdown page, with its ``--8<--`` snippets included.

    Args:
        page: The page's file.
        base: The directory snippet paths are relative to (mkdocs' ``base_path``).
    """
    text = page.read_text(encoding="utf-8")
    text = SNIPPET.sub(lambda m: (base / m[1]).read_text(encoding="utf-8"), text)
    return len(text.split())


def by_section(config: Path, max_depth: int = 2) -> dict[str, int]:
    """Words of the pages at most ``max_depth`` deep in the nav, per top-level section."""
    docs = config.parent / "docs"
    counts: dict[str, int] = {}
    for page in nav_pages(config):
        if page.depth <= max_depth:
            counts[page.section] = counts.get(page.section, 0) + words(
                docs / page.path, config.parent
            )
    return counts


def guide_share(counts: dict[str, int]) -> float:
    """The share of the words that lie outside :data:`RECORD_SECTIONS`."""
    total = sum(counts.values())
    guides = sum(n for s, n in counts.items() if s not in RECORD_SECTIONS)
    return guides / total if total else 0.0


def main() -> int:
    """Print the words per section of the nav's first two levels and the guides' share."""
    config = REPO / "mkdocs.yml"
    counts = by_section(config)
    deeper = by_section(config, max_depth=99)
    print("| section | words (levels 1-2) | words (all levels) |")
    print("|---|---|---|")
    for section, n in deeper.items():
        print(f"| {section} | {counts.get(section, 0):,} | {n:,} |")
    print(
        f"\nguides + reference: {guide_share(counts):.1%} of the words in the nav's first two "
        f"levels, {guide_share(deeper):.1%} of all nav pages"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
