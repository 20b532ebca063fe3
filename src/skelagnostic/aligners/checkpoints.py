"""Reading aligner checkpoints safely, with one-line errors.

Every place that loads a checkpoint (``skelagnostic fit|validate|test|predict
ckpt_path=...``, ``skelagnostic retarget|interpolate|transfer ckpt=...``,
:func:`skelagnostic.plugins.load_aligner`, ``skelagnostic evaluate``)
goes through :func:`read_checkpoint`, which loads the file with
``torch.load(weights_only=True)`` (never unpickling code) and turns every way a
file can be wrong into a :class:`CheckpointError` naming the file and the
cause: missing, not a readable checkpoint (truncated or corrupt), holding
Python objects a safe load refuses, written by another model, holding non-finite
weights (a diverged run), or (once the weights are loaded,
:func:`architecture_mismatch`) of a different architecture.
"""

from __future__ import annotations

import contextlib
import inspect
import io
import pickle
import re
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import torch

from skelagnostic.aligners.checkpoint_errors import CheckpointError, CheckpointNotFoundError
from skelagnostic.aligners.weights import (
    is_weights,
    named_tensor_mismatch,
    read_weights,
    weights_file,
)
from skelagnostic.core.finite import first_non_finite

if TYPE_CHECKING:
    import lightning as L

__all__ = [
    "CheckpointError",
    "CheckpointNotFoundError",
    "architecture_mismatch",
    "check_architecture",
    "load_checkpoint",
    "read_checkpoint",
]

ModuleT = TypeVar("ModuleT", bound="L.LightningModule")

#: What :meth:`torch.nn.Module.load_state_dict` says when the weights do not fit.
_STATE_DICT_ERROR = "Error(s) in loading state_dict"


def read_checkpoint(
    path: str | Path,
    model: str | type | None = None,
    *,
    option: str = "checkpoint",
    aligners: Mapping[str, type] | None = None,
) -> dict[str, Any]:
    """Load a Lightning checkpoint with ``weights_only=True`` and check whose it is.

    A safetensors weights file (``skelagnostic export format=safetensors``) is read
    too, as the checkpoint it stands for (:func:`~skelagnostic.aligners.weights.read_weights`).

    Args:
        path: The checkpoint file, a ``.safetensors`` weights file or a directory
            holding ``model.safetensors``.
        model: The aligner that will load it: a registered name or a class;
            ``None`` skips the check of the model that wrote it.
        option: How the user named the file, for the message (``ckpt_path``).
        aligners: The registered aligners (name -> class, e.g.
            ``PluginManager.aligner_classes()``) among which the one that wrote
            the checkpoint is looked up, to name it when it is not ``model``.
            ``None``: a ``model`` given by name is not checked, and a class is
            checked only against its own options.

    Returns:
        The checkpoint (``state_dict``, ``hyper_parameters``, loop states, ...).

    Raises:
        CheckpointNotFoundError: The file does not exist.
        CheckpointError: The file is not a readable checkpoint
            (empty, truncated, corrupt, not a torch file), holds Python objects a
            safe load refuses (such as an ``os.system`` call), is not a Lightning
            checkpoint, was written by another model, or holds a NaN or infinite
            floating-point value in its ``state_dict`` (the error names the first).
    """
    file = Path(path)
    if is_weights(file):
        checkpoint = read_weights(file, option)
        file = weights_file(file) or file
        _check_weights_model(file, checkpoint["skelagnostic_model"], model, option, aligners)
    else:
        checkpoint = _load_lightning(file, option)
    if model is not None:
        _check_model(file, checkpoint, model, option, aligners or {})
    bad = first_non_finite(checkpoint["state_dict"].items())
    if bad is not None:
        raise CheckpointError(
            file,
            f"{str(file)!r} holds non-finite weights ({bad} has NaN or infinite values): the "
            "run that wrote it diverged; use an earlier checkpoint of that run, or train again "
            "(e.g. with a lower learning rate)",
            option,
        )
    return checkpoint


def _load_lightning(file: Path, option: str) -> dict[str, Any]:
    """``torch.load(file, weights_only=True)``, checked to be a Lightning checkpoint."""
    shown = repr(str(file))
    if not file.is_file():
        raise CheckpointNotFoundError(file, f"no checkpoint file {shown}", option)
    if file.stat().st_size == 0:
        raise CheckpointError(file, f"{shown} is empty, not a checkpoint", option)
    try:
        checkpoint = torch.load(file, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as error:
        found = re.search(r"GLOBAL ([\w.]+)", str(error))
        if found:
            raise CheckpointError(
                file,
                f"{shown} holds a Python object ({found.group(1)}) that a safe load "
                "refuses; skelagnostic loads checkpoints with torch.load(weights_only=True), "
                "which allows tensors and plain data only",
                option,
            ) from None
        raise CheckpointError(
            file, f"{shown} is not a readable checkpoint (truncated or corrupt)", option
        ) from None
    except (
        EOFError,
        OSError,
        RuntimeError,
        ValueError,
        KeyError,
        IndexError,
        TypeError,
        AttributeError,
        UnicodeDecodeError,
    ):
        raise CheckpointError(
            file, f"{shown} is not a readable checkpoint (truncated or corrupt)", option
        ) from None
    if not isinstance(checkpoint, dict) or not isinstance(checkpoint.get("state_dict"), dict):
        raise CheckpointError(
            file,
            f"{shown} is a torch file but not a Lightning checkpoint (it has no state_dict)",
            option,
        )
    return checkpoint


def load_checkpoint(
    module: type[ModuleT],
    path: str | Path,
    *,
    option: str = "checkpoint",
    aligners: Mapping[str, type] | None = None,
    **overrides: Any,
) -> ModuleT:
    """``module.load_from_checkpoint`` (CPU, ``weights_only=True``) after :func:`read_checkpoint`.

    Args:
        module: The LightningModule class to build.
        path: The checkpoint file, or a safetensors weights file (or its directory).
        option: How the user named the file, for the messages.
        aligners: The registered aligners, to name the one that wrote the
            checkpoint (see :func:`read_checkpoint`).
        **overrides: Hyperparameters replacing the saved ones. Keys of the module's
            ``legacy_hparams`` that the checkpoint lacks get their legacy value (the
            behaviour the checkpoint was trained with) unless overridden here.

    Returns:
        The module with the checkpoint's weights.

    Raises:
        CheckpointError: See :func:`read_checkpoint`; also when the weights do
            not fit the module (a different architecture).
    """
    checkpoint = read_checkpoint(path, module, option=option, aligners=aligners)
    saved = dict(checkpoint.get("hyper_parameters") or {})
    legacy = getattr(module, "legacy_hparams", {})
    overrides = {**{k: v for k, v in legacy.items() if k not in saved}, **overrides}
    source: Path | io.BytesIO = Path(path)
    named: contextlib.AbstractContextManager[None] = contextlib.nullcontext()
    if is_weights(path):  # Lightning reads torch files: hand it the checkpoint in memory
        source = io.BytesIO()
        torch.save(checkpoint, source)
        source.seek(0)
        named = named_tensor_mismatch(path, option)
    with architecture_mismatch(path, saved, {**saved, **overrides}, option), named:
        return module.load_from_checkpoint(
            source, map_location="cpu", weights_only=True, **overrides
        )


@contextlib.contextmanager
def architecture_mismatch(
    path: str | Path,
    saved: Mapping[str, Any],
    used: Mapping[str, Any],
    option: str = "checkpoint",
    prefix: str = "model.",
) -> Iterator[None]:
    """Turn a ``load_state_dict`` failure inside the block into a :class:`CheckpointError`.

    The message lists the hyperparameters whose values differ between the
    checkpoint (``saved``) and the model that failed to load it (``used``);
    keys either side lacks, ``None`` (filled in from the data) and nested
    values are not compared. Without such a difference it counts the weights that do not fit.

    Args:
        path: The checkpoint file.
        saved: The checkpoint's ``hyper_parameters``.
        used: The hyperparameters of the model being loaded.
        option: How the user named the file.
        prefix: Config path of the hyperparameters, for the message.

    Raises:
        CheckpointError: The block raised the ``load_state_dict`` error.
    """
    try:
        yield
    except RuntimeError as error:
        text = str(error)
        if _STATE_DICT_ERROR not in text:
            raise
        counts = {"missing": 0, "unexpected": 0}
        for kind in counts:
            found = re.search(rf"{kind.capitalize()} key\(s\) in state_dict: (.*)", text)
            if found:
                counts[kind] = found.group(1).count(",") + 1
        raise _architecture_error(
            path,
            saved,
            used,
            option,
            prefix,
            missing=counts["missing"],
            unexpected=counts["unexpected"],
            shapes=len(re.findall(r"size mismatch for ", text)),
        ) from None


def check_architecture(
    path: str | Path,
    checkpoint: Mapping[str, Any],
    model: torch.nn.Module,
    option: str = "checkpoint",
    prefix: str = "model.",
) -> None:
    """Compare a checkpoint's weights with a built model before Lightning loads them.

    Weights of another shape, and weights of the model the checkpoint lacks,
    are a different architecture. Weights only the checkpoint has are not
    judged: aligners may build layers later (``configure_model``, ``setup``).
    Lightning's own check still runs when it loads the weights
    (:func:`architecture_mismatch`); this one fails before the run starts.

    Args:
        path: The checkpoint file.
        checkpoint: What :func:`read_checkpoint` returned.
        model: The module about to load it (its hyperparameters, if any, are
            compared for the message).
        option: How the user named the file.
        prefix: Config path of the hyperparameters, for the message.

    Raises:
        CheckpointError: The weights do not fit.
    """
    saved, own = checkpoint["state_dict"], model.state_dict()
    shapes = sum(
        1
        for key, value in own.items()
        if key in saved and tuple(getattr(saved[key], "shape", ())) != tuple(value.shape)
    )
    strict = getattr(model, "strict_loading", True)
    missing = sum(1 for key in own if key not in saved) if strict else 0
    if shapes or missing:
        raise _architecture_error(
            path,
            dict(checkpoint.get("hyper_parameters") or {}),
            dict(getattr(model, "hparams", {})),
            option,
            prefix,
            missing=missing,
            unexpected=0,
            shapes=shapes,
        )


def _architecture_error(
    path: str | Path,
    saved: Mapping[str, Any],
    used: Mapping[str, Any],
    option: str,
    prefix: str,
    missing: int,
    unexpected: int,
    shapes: int,
) -> CheckpointError:
    """The "different architecture" error: the hyperparameters that differ, else the counts."""
    differ = [
        f"{prefix}{key}={saved[key]!r} in the checkpoint, {used[key]!r} here"
        for key in saved
        if key in used and _plain(saved[key]) and _plain(used[key]) and saved[key] != used[key]
    ]
    if differ:
        what = "; ".join(differ)
    else:
        parts = [
            f"{n} {kind}"
            for n, kind in (
                (missing, "missing"),
                (unexpected, "unexpected"),
                (shapes, "of another shape"),
            )
            if n
        ]
        what = "its weights do not fit (" + ", ".join(parts or ["different keys"]) + ")"
    return CheckpointError(
        path, f"{str(Path(path))!r} is of a different architecture: {what}", option
    )


def _plain(value: Any) -> bool:
    """A short option value worth quoting (not ``None``, not a nested structure)."""
    return isinstance(value, (bool, int, float, str)) and len(repr(value)) <= 40


# ------------------------------------------------------------------ which model
def _check_weights_model(
    file: Path,
    stored: str,
    model: str | type | None,
    option: str,
    aligners: Mapping[str, type] | None,
) -> None:
    """Raise :class:`CheckpointError` if a weights file's ``model`` field names another aligner."""
    if model is None:
        return
    if isinstance(model, str):
        name = model
    else:
        name = next((n for n, c in (aligners or {}).items() if c is model), "")
    if name and stored != name:
        raise CheckpointError(
            file,
            f"{str(file)!r}: metadata field 'model' is {stored!r}, this is model={name}",
            option,
        )


def _accepted(cls: type) -> tuple[set[str], bool]:
    """The keyword arguments of ``cls.__init__`` and whether it takes ``**kwargs``."""
    params = inspect.signature(cls.__init__).parameters
    names = {
        name
        for name, p in params.items()
        if name != "self" and p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
    }
    return names, any(p.kind is p.VAR_KEYWORD for p in params.values())


def _fit(cls: type, keys: set[str]) -> int | None:
    """How many options of ``cls`` the checkpoint leaves unset (``None``: some key is not one)."""
    names, var_keyword = _accepted(cls)
    if keys <= names:
        return len(names - keys)
    return 10**6 if var_keyword else None


def _check_model(
    file: Path,
    checkpoint: dict[str, Any],
    model: str | type,
    option: str,
    aligners: Mapping[str, type],
) -> None:
    """Raise :class:`CheckpointError` if the hyperparameters belong to another aligner.

    Lightning does not store the class of the module in the checkpoint, but
    ``save_hyperparameters`` stores its constructor arguments: the writer is
    the registered aligner whose constructor takes every saved key and leaves
    the fewest of its own unset.
    """
    saved = checkpoint.get("hyper_parameters")
    if not isinstance(saved, Mapping) or not saved:
        return
    keys = {str(k) for k in saved}
    if isinstance(model, str):
        name, cls = model, aligners.get(model)
        if cls is None:
            return  # unknown names are reported by the plugin manager
    else:
        cls = model
        name = next((n for n, c in aligners.items() if c is cls), cls.__name__)
    own = _fit(cls, keys)
    fits = {n: f for n, c in aligners.items() if (f := _fit(c, keys)) is not None}
    best = min(fits.values(), default=None)
    if own is not None and (best is None or own <= best):
        return
    writers = sorted(n for n, f in fits.items() if f == best and n != name)
    shown = repr(str(file))
    if writers:
        raise CheckpointError(
            file, f"{shown} is a checkpoint of model={writers[0]}, this is model={name}", option
        )
    names, _ = _accepted(cls)
    foreign = sorted(keys - names)
    raise CheckpointError(
        file,
        f"{shown} is not a checkpoint of model={name}: its hyperparameters "
        f"{', '.join(foreign[:5])}{' ...' if len(foreign) > 5 else ''} are not options "
        f"of model={name}",
        option,
    )
