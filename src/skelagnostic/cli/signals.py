"""SIGTERM outside Lightning's training loop: stop at once, clean up, one line.

Python's default answer to ``SIGTERM`` is to end the process on the spot: a file
being written through :func:`skelagnostic.io.atomic.atomic_write` (a window-cache
entry, ``retarget``'s output) leaves its temporary ``.tmp`` file behind, and the
command says nothing. While a verb runs, :func:`sigterm_raises` turns ``SIGTERM``
into the exception :class:`Terminated`, so ``finally`` blocks and the atomic
writer's clean-up run, and the CLI prints one line and exits with code 143.

During training Lightning installs its own handler, which ends the run at the
end of the current step (and calls the previous handler too): there this
module's handler does nothing, so Lightning's graceful stop (and its exact
resume) is unchanged.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from types import FrameType

__all__ = ["SIGTERM_EXIT_CODE", "Terminated", "sigterm_raises"]

#: Exit code of a command stopped by SIGTERM (128 + 15, as the shell reports it).
SIGTERM_EXIT_CODE = 143


class Terminated(BaseException):
    """``SIGTERM`` arrived. A ``BaseException``, so ``except Exception`` blocks let it pass."""


@contextlib.contextmanager
def sigterm_raises() -> Iterator[None]:
    """Within the block, ``SIGTERM`` raises :class:`Terminated` (in the main thread).

    Nothing changes when the block does not run in the main thread, or when a
    handler other than the default one is installed already (the process then
    chose what ``SIGTERM`` does). Once another handler replaces this one (as
    Lightning's does during training, calling this one as well), this one does
    nothing, so the other decides. The previous handler is restored on exit.
    """
    if threading.current_thread() is not threading.main_thread() or signal.getsignal(
        signal.SIGTERM
    ) not in (signal.SIG_DFL, None):
        yield
        return

    def handler(signum: int, frame: FrameType | None) -> None:
        if signal.getsignal(signal.SIGTERM) is handler:  # not called through Lightning's
            raise Terminated(signum)

    signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
