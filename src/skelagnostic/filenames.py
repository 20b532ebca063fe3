"""Names of the files one part of skelagnostic writes and another reads back.

The writer (a Lightning callback, the weights exporter) and the readers (the
command line's run-directory handling) both import the name from here, so that a
reader does not import the writer's training stack to learn a file name.

This module imports nothing.
"""

__all__ = ["SPLIT_FILE", "WEIGHTS_FILE"]

#: The clip split a fit writes into its run directory
#: (:class:`~skelagnostic.callbacks.split.RecordSplit`).
SPLIT_FILE = "split.json"
#: Name of the weights file in a directory (``ckpt=<dir>`` looks for it;
#: :mod:`skelagnostic.aligners.weights`).
WEIGHTS_FILE = "model.safetensors"
