"""After Ctrl+C during ``fit``: where the newest checkpoint is and how to resume from it.

Lightning answers a ``KeyboardInterrupt`` (SIGINT, Ctrl+C) during training with
"Detected KeyboardInterrupt, attempting graceful shutdown ..." and exits; which
checkpoint survived, and how to continue, it does not say.
"""

from __future__ import annotations

import sys

import lightning as L

from skelagnostic.callbacks.checkpoint import newest_checkpoint

__all__ = ["ResumeHint"]


class ResumeHint(L.Callback):
    """On a ``KeyboardInterrupt``: one line on stderr naming the newest checkpoint and the resume.

    The line follows Lightning's own ("Detected KeyboardInterrupt ..."), on global
    rank 0 only, for example::

        skelagnostic fit: interrupted at step 7; the last checkpoint is
        runs/.../checkpoints/last.ckpt (step 4): resume with skelagnostic fit
        ckpt_path=runs/.../checkpoints/last.ckpt

    (one line). Without a checkpoint yet it says that there is nothing to resume.
    ``skelagnostic fit`` adds this callback to every run.

    Args:
        command: How the line starts and how the resume command is spelled.
    """

    def __init__(self, command: str = "skelagnostic fit") -> None:
        self.command = command
        #: The line printed after the latest interrupt (``None`` before one).
        self.message: str | None = None

    def on_exception(
        self, trainer: L.Trainer, pl_module: L.LightningModule, exception: BaseException
    ) -> None:
        """Print the line for a ``KeyboardInterrupt`` (other exceptions are reported elsewhere)."""
        if not isinstance(exception, KeyboardInterrupt) or not trainer.is_global_zero:
            return
        newest = newest_checkpoint(trainer)
        if newest is None:
            what = "no checkpoint was written yet, so there is nothing to resume"
        else:
            path, step = newest
            what = (
                f"the last checkpoint is {path} (step {step}): resume with "
                f"{self.command} ckpt_path={path}"
            )
        self.message = f"{self.command}: interrupted at step {trainer.global_step}; {what}"
        print(self.message, file=sys.stderr, flush=True)
