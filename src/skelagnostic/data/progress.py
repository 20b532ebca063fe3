"""A progress bar for long passes over a corpus's clips (building or reading the window cache).

The bar is Rich's, as the training progress bar (Lightning's ``RichProgressBar``)
and ``skelagnostic data prepare`` draw, on stderr. Like them it stays quiet when
stderr is not a terminal (logs and captured output stay clean), and like
Lightning's model summary it is not drawn for a pass that ends quickly: it
appears only once a pass has run for :data:`DELAY_S` seconds, so the usual
start of a run over a cached corpus prints nothing.
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Sequence
from typing import Any, TypeVar

__all__ = ["DELAY_S", "progress_console", "track_clips"]

T = TypeVar("T")

#: Seconds a pass runs before its bar appears.
DELAY_S = 1.0


def progress_console() -> Any:
    """The ``rich.console.Console`` the bars are drawn on: stderr."""
    from rich.console import Console

    return Console(stderr=True)


def track_clips(items: Sequence[T], description: str, show: bool = True) -> Iterator[T]:
    """Iterate ``items``; a Rich bar (done/total, time left) once the pass is slow.

    The bar is advanced after the caller is done with each item (when it asks
    for the next one). It is drawn on :func:`progress_console` only when that is
    a terminal, ``show`` is true and :data:`DELAY_S` seconds have passed, and
    not while another Rich live display (a caller's bar) is on screen; it is
    removed when the pass ends.

    Args:
        items: The clips (or anything) to go through.
        description: The bar's label, e.g. ``"data: caching windows"``.
        show: ``False`` never draws the bar (e.g. a DDP rank other than zero).

    Yields:
        The items, unchanged.
    """
    console = progress_console() if show and len(items) > 1 else None
    if console is None or not console.is_terminal:
        yield from items
        return
    from rich.errors import LiveError
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    progress = Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=console,
        transient=True,
    )
    task = progress.add_task(description, total=len(items))
    start, due, shown = time.monotonic(), True, False
    try:
        for item in items:
            yield item
            progress.advance(task)
            if due and time.monotonic() - start >= DELAY_S:
                due = False
                try:
                    progress.start()
                    shown = True
                except LiveError:  # the caller's own bar is on screen: no second one
                    pass
    finally:
        if shown:
            progress.stop()
