"""An aligner's weights as a ``model.safetensors`` file that carries its config.

:func:`save_weights` writes the aligner's ``state_dict`` with
`safetensors <https://huggingface.co/docs/safetensors>`_ (no pickled code, so
the file is safe to load from anywhere) and puts in the file's metadata what
rebuilding the aligner needs: the registered model name, the resolved model
config (its hyperparameters) and the entries the aligner's
``on_save_checkpoint`` adds to a checkpoint (PC-MRL's target skeleton, for
example). :func:`read_weights` turns such a file back into the dictionary a
Lightning checkpoint holds, so
:func:`~skelagnostic.aligners.checkpoints.read_checkpoint` and
:func:`~skelagnostic.aligners.checkpoints.load_checkpoint` (and with them
``ckpt=`` of the inference verbs, ``evaluate`` and
:func:`skelagnostic.load_aligner`) accept the file, or a directory holding
``model.safetensors``, wherever they accept a checkpoint.

Metadata fields (all strings, as safetensors stores them): ``format``
(``skelagnostic.weights``), ``format_version``, ``model``, ``model_config``
(JSON), ``checkpoint_entries`` (JSON), ``skelagnostic_version``.
"""

from __future__ import annotations

import contextlib
import json
import re
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import torch

from skelagnostic.aligners.checkpoint_errors import CheckpointError, CheckpointNotFoundError
from skelagnostic.errors import SkelagnosticError
from skelagnostic.filenames import WEIGHTS_FILE

if TYPE_CHECKING:
    import lightning as L

__all__ = [
    "FORMAT",
    "WEIGHTS_FILE",
    "is_weights",
    "named_tensor_mismatch",
    "read_weights",
    "save_weights",
    "weights_file",
    "weights_model",
]

#: Value of the ``format`` metadata field.
FORMAT = "skelagnostic.weights"
#: Version of the metadata layout (bumped when a field changes meaning).
FORMAT_VERSION = "1"
#: Entries of a Lightning checkpoint that are not the aligner's own.
_TRAINING_STATE = (
    "state_dict",
    "hyper_parameters",
    "hparams_name",
    "optimizer_states",
    "lr_schedulers",
    "loops",
    "callbacks",
    "epoch",
    "global_step",
    "pytorch-lightning_version",
)


def _import_safetensors() -> Any:
    try:
        import safetensors.torch
    except ImportError:
        raise SkelagnosticError(
            "safetensors files need the safetensors package: pip install 'skelagnostic[export]'"
        ) from None
    return safetensors.torch


def weights_file(path: str | Path) -> Path | None:
    """The weights file ``path`` names: itself (``*.safetensors``) or ``<dir>/model.safetensors``.

    Returns:
        The file (which may not exist for a ``*.safetensors`` name), or ``None``
        when ``path`` is neither (a Lightning checkpoint, a run directory, ...).

    Example:
        >>> weights_file("exported/model.safetensors").name
        'model.safetensors'
        >>> weights_file("runs/fit/last.ckpt") is None
        True
    """
    path = Path(path)
    if path.suffix == ".safetensors":
        return path
    if path.is_dir() and (path / WEIGHTS_FILE).is_file():
        return path / WEIGHTS_FILE
    return None


def is_weights(path: str | Path) -> bool:
    """Whether ``path`` names a safetensors weights file (see :func:`weights_file`)."""
    return weights_file(path) is not None


def _json(value: Any, where: str) -> str:
    """``value`` as JSON text (tuples become lists); anything JSON cannot hold raises."""
    try:
        return json.dumps(value)
    except (TypeError, ValueError) as error:
        raise SkelagnosticError(
            f"{where} cannot be stored in a safetensors file's metadata (JSON only): {error}"
        ) from None


def save_weights(aligner: L.LightningModule, path: str | Path, model: str) -> Path:
    """Write ``aligner``'s weights and config to ``path`` (a ``.safetensors`` file).

    Args:
        aligner: The aligner (its ``hparams`` are the model config).
        path: The file to write (atomically; the folder is created).
        model: The aligner's registered name (``model=<name>`` on load).

    Returns:
        ``path``.

    Raises:
        SkelagnosticError: ``model`` is empty, the package is missing, or the
            config or a checkpoint entry is not JSON data.
    """
    from skelagnostic import __version__
    from skelagnostic.io.outputs import output_path

    st = _import_safetensors()
    if not model:
        raise SkelagnosticError("safetensors weights need the aligner's registered name (model=)")
    checkpoint: dict[str, Any] = {"hyper_parameters": dict(aligner.hparams)}
    aligner.on_save_checkpoint(checkpoint)
    entries = {k: v for k, v in checkpoint.items() if k not in _TRAINING_STATE}
    # clone: safetensors refuses tensors that share memory (tied weights)
    tensors = {k: v.detach().cpu().contiguous().clone() for k, v in aligner.state_dict().items()}
    metadata = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "model": model,
        "model_config": _json(checkpoint["hyper_parameters"], "model config"),
        "checkpoint_entries": _json(entries, "checkpoint entries"),
        "skelagnostic_version": __version__,
    }
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    with output_path(target) as tmp:
        st.save_file(tensors, str(tmp), metadata=metadata)
    return target


def _field(file: Path, metadata: dict[str, str], name: str, option: str) -> Any:
    """The metadata field ``name`` (JSON decoded for the JSON fields), or a CheckpointError."""
    shown = repr(str(file))
    if name not in metadata:
        raise CheckpointError(
            file,
            f"{shown} has no metadata field {name!r}: not written by skelagnostic export",
            option,
        )
    text = metadata[name]
    if name not in ("model_config", "checkpoint_entries"):
        return text
    try:
        value = json.loads(text)
    except ValueError:
        value = None
    if not isinstance(value, dict):
        raise CheckpointError(
            file, f"{shown}: metadata field {name!r} is not a JSON object", option
        )
    return value


def _open(
    file: Path, option: str, tensors: bool = True
) -> tuple[dict[str, torch.Tensor], dict[str, str]]:
    """The tensors (unless ``tensors=False``) and metadata of ``file``.

    Raises:
        CheckpointNotFoundError: The file does not exist.
        CheckpointError: It is not a readable safetensors file.
    """
    st = _import_safetensors()
    shown = repr(str(file))
    if not file.is_file():
        raise CheckpointNotFoundError(file, f"no weights file {shown}", option)
    try:
        from safetensors import safe_open

        with safe_open(str(file), framework="pt") as handle:
            metadata = dict(handle.metadata() or {})
        loaded = st.load_file(str(file)) if tensors else {}
    except Exception as error:  # safetensors' own error type: one line naming the file
        text = str(error).splitlines()[0] if str(error) else type(error).__name__
        raise CheckpointError(
            file,
            f"{shown} is not a readable safetensors file (truncated or corrupt): {text}",
            option,
        ) from None
    return loaded, metadata


def _model(file: Path, metadata: dict[str, str], option: str) -> str:
    """The ``model`` field, after checking the ``format`` field."""
    found = _field(file, metadata, "format", option)
    if found != FORMAT:
        raise CheckpointError(
            file, f"{str(file)!r}: metadata field 'format' is {found!r}, not {FORMAT!r}", option
        )
    model = _field(file, metadata, "model", option)
    if not model:
        raise CheckpointError(file, f"{str(file)!r}: metadata field 'model' is empty", option)
    return model


def read_weights(path: str | Path, option: str = "checkpoint") -> dict[str, Any]:
    """A safetensors weights file as the dictionary a Lightning checkpoint holds.

    Args:
        path: The ``.safetensors`` file, or a directory holding ``model.safetensors``.
        option: How the user named the file, for the messages.

    Returns:
        ``state_dict``, ``hyper_parameters`` (the model config), the aligner's
        own checkpoint entries, ``pytorch-lightning_version`` and
        ``skelagnostic_model`` (the registered name).

    Raises:
        CheckpointNotFoundError: The file does not exist.
        CheckpointError: The file is not a readable safetensors file, or a
            metadata field is missing or malformed (the message names the file
            and the field).
    """
    import lightning

    file = weights_file(path) or Path(path) / WEIGHTS_FILE
    tensors, metadata = _open(file, option)
    model = _model(file, metadata, option)
    return {
        **_field(file, metadata, "checkpoint_entries", option),
        "state_dict": tensors,
        "hyper_parameters": _field(file, metadata, "model_config", option),
        "pytorch-lightning_version": lightning.__version__,
        "skelagnostic_model": model,
    }


def weights_model(path: str | Path, option: str = "checkpoint") -> str:
    """The registered aligner name stored in a weights file (metadata field ``model``).

    Raises:
        CheckpointError: See :func:`read_weights` (only the metadata is read).
    """
    file = weights_file(path) or Path(path) / WEIGHTS_FILE
    _, metadata = _open(file, option, tensors=False)
    return _model(file, metadata, option)


#: One tensor of the state_dict error: "size mismatch for NAME: copying ... shape torch.Size([..])
#: from checkpoint, the shape in current model is torch.Size([..])".
_SIZE = re.compile(
    r"size mismatch for ([\w.]+): copying a param with shape torch\.Size\((\[[^\]]*\])\) from "
    r"checkpoint, the shape in current model is torch\.Size\((\[[^\]]*\])\)"
)
_KEYS = re.compile(r"(Missing|Unexpected) key\(s\) in state_dict: \"([^\"]+)\"")


@contextlib.contextmanager
def named_tensor_mismatch(path: str | Path, option: str = "checkpoint") -> Iterator[None]:
    """Turn a ``load_state_dict`` failure in the block into an error naming the first tensor.

    Raises:
        CheckpointError: ``'<file>': tensor 'NAME' has shape [..] in the file, the
            model expects [..]`` (or is missing from the file, or is not the model's).
    """
    try:
        yield
    except RuntimeError as error:
        text = str(error)
        file = weights_file(path) or Path(path)
        shown = repr(str(file))
        size, keys = _SIZE.search(text), _KEYS.search(text)
        if size:
            reason = (
                f"tensor {size.group(1)!r} has shape {size.group(2)} in the file, "
                f"the model expects {size.group(3)}"
            )
        elif keys and keys.group(1) == "Missing":
            reason = f"the model's tensor {keys.group(2)!r} is missing from the file"
        elif keys:
            reason = f"tensor {keys.group(2)!r} of the file is not one of the model's"
        else:
            raise
        raise CheckpointError(file, f"{shown} does not fit the model: {reason}", option) from None
