"""``skelagnostic.evaluation.track``: the protocols' progress bar."""

from __future__ import annotations

import io

from rich.console import Console

from skelagnostic.evaluation import track


def test_track_yields_every_item_and_draws_only_on_a_terminal() -> None:
    quiet = Console(file=io.StringIO(), force_terminal=False)
    assert list(track(iter([3, 1, 2]), "clips", total=3, console=quiet)) == [3, 1, 2]
    assert quiet.file.getvalue() == ""  # not a terminal: nothing drawn
    shown = Console(file=io.StringIO(), force_terminal=True, width=80)
    assert list(track(["a", "b"], "held-out clips", console=shown)) == ["a", "b"]
    drawn = shown.file.getvalue()
    assert "held-out clips" in drawn
    assert "100%" in drawn  # the total came from len(items): the bar completes
