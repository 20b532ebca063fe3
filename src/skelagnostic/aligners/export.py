"""Export an aligner's networks for engines (ONNX, TorchScript, JSON sidecars) or its weights.

An aligner says what a runtime needs through
:meth:`skelagnostic.aligners.Aligner.export_graphs`: a list of
:class:`ExportGraph`, each a plain :class:`torch.nn.Module` whose ``forward``
takes and returns tensors only, with example inputs, input and output names,
the axes that may change size at run time and metadata for the sidecar
(normalisation statistics, the skeleton, fixed sizes). :func:`export_aligner`
writes, for every graph, ``<name>.onnx`` (or ``<name>.pt``, TorchScript) and
``<name>.json``. ``format="safetensors"`` writes the aligner's weights instead,
``model.safetensors`` with the model config in its metadata
(:func:`skelagnostic.aligners.weights.save_weights`), which ``ckpt=`` loads back.

ONNX files come from the dynamo-based exporter
(``torch.onnx.export(..., dynamo=True)``) with ``dynamic_shapes`` built from
the declared axes (one :class:`torch.export.Dim` per axis label, so axes
sharing a label must have equal sizes). TorchScript files come from
:func:`torch.jit.trace`; the graphs are written so that tracing records sizes
as graph values, not constants.
"""

from __future__ import annotations

import contextlib
import inspect
import json
import logging
import re
import warnings
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import torch
from torch import Tensor, nn

from skelagnostic.errors import SkelagnosticError
from skelagnostic.io.outputs import OutputError, output_path

if TYPE_CHECKING:
    from skelagnostic.aligners.base import Aligner

__all__ = [
    "FORMATS",
    "GRAPH_FORMATS",
    "ExportError",
    "ExportGraph",
    "Method",
    "export_aligner",
    "export_graph",
    "sidecar",
]

#: Formats :func:`export_aligner` writes, and the suffix of their files.
FORMATS: dict[str, str] = {"onnx": ".onnx", "torchscript": ".pt", "safetensors": ".safetensors"}
#: The formats of networks (graphs); the others hold weights.
GRAPH_FORMATS = ("onnx", "torchscript")
#: ONNX opset of the exported files.
OPSET = 18
#: Version of the sidecar layout (bumped when a key changes meaning).
SIDECAR_VERSION = 1


class ExportError(SkelagnosticError):
    """An aligner cannot be exported (nothing to export, unknown format, missing package)."""


@dataclass
class ExportGraph:
    """One network an engine runs, as :meth:`Aligner.export_graphs` declares it.

    Attributes:
        name: File stem (``[A-Za-z0-9_.-]``), unique among the aligner's graphs.
        module: Module whose ``forward(*inputs)`` returns a tensor or a tuple of
            tensors, one per ``output_names`` entry. No Python control flow may
            depend on tensor values or on the sizes of the ``dynamic_axes``.
        example_inputs: One example tensor per ``input_names`` entry. Give each
            dynamic axis a size of at least 2 that differs from the other axes'
            sizes, so the exporters do not mistake it for a constant.
        input_names: Names of the inputs, in ``forward`` order.
        output_names: Names of the outputs, in ``forward`` order.
        dynamic_axes: Input or output name -> ``{axis: label}`` for the axes whose
            size may change at run time (``"batch"``, ``"time"``, ``"joints"``);
            axes with the same label must have the same size.
        description: What the graph computes (one or two sentences).
        fixed_axes: Label -> why the architecture fixes that size, for axes a
            reader might expect to be dynamic (for example a window length).
        metadata: Anything else the runtime needs (JSON-serialisable after
            tensors become lists): normalisation statistics, the skeleton,
            units, frame rate, pre- and post-processing notes.
    """

    name: str
    module: nn.Module
    example_inputs: tuple[Tensor, ...]
    input_names: Sequence[str]
    output_names: Sequence[str]
    dynamic_axes: Mapping[str, Mapping[int, str]] = field(default_factory=dict)
    description: str = ""
    fixed_axes: Mapping[str, str] = field(default_factory=dict)
    metadata: Mapping[str, Any] = field(default_factory=dict)

    def check(self) -> None:
        """Raise :class:`ExportError` if the declaration is inconsistent."""
        if not self.name or any(not (c.isalnum() or c in "_.-") for c in self.name):
            raise ExportError(f"export graph name {self.name!r}: use letters, digits, _ . -")
        if len(self.example_inputs) != len(self.input_names):
            raise ExportError(
                f"export graph {self.name!r}: {len(self.example_inputs)} example "
                f"inputs for {len(self.input_names)} input names"
            )
        known = {*self.input_names, *self.output_names}
        unknown = sorted(set(self.dynamic_axes) - known)
        if unknown:
            raise ExportError(
                f"export graph {self.name!r}: dynamic_axes names {unknown[0]!r}, "
                "which is neither an input nor an output"
            )


class Method(nn.Module):
    """One method of a module as a module of its own, for :attr:`ExportGraph.module`.

    The owner becomes a submodule, so its weights go into the exported file.

    Args:
        owner: The module (usually the aligner itself).
        method: Name of the method ``forward`` calls with the graph's inputs.

    Example:
        >>> lin = nn.Linear(2, 3)
        >>> Method(lin, "forward")(torch.zeros(1, 2)).shape
        torch.Size([1, 3])
    """

    def __init__(self, owner: nn.Module, method: str) -> None:
        super().__init__()
        if not callable(getattr(owner, method, None)):
            raise ExportError(f"{type(owner).__name__} has no method {method!r}")
        self.owner = owner
        self.method = method

    def forward(self, *inputs: Tensor) -> Any:
        """``owner.<method>(*inputs)``."""
        return getattr(self.owner, self.method)(*inputs)


def _jsonable(value: Any) -> Any:
    """``value`` with tensors as (nested) lists and tuples as lists."""
    if isinstance(value, Tensor):
        return value.detach().cpu().tolist()
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, float) and value != value:  # NaN is not JSON
        return None
    return value


def _as_tuple(out: Any) -> tuple[Tensor, ...]:
    return tuple(out) if isinstance(out, (tuple, list)) else (out,)


def _tensor_entry(name: str, tensor: Tensor, axes: Mapping[int, str]) -> dict[str, Any]:
    shape: list[int | str] = list(tensor.shape)
    for axis, label in axes.items():
        shape[axis] = label
    return {"name": name, "dtype": str(tensor.dtype).removeprefix("torch."), "shape": shape}


def sidecar(graph: ExportGraph, fmt: str, file: str, aligner: str = "") -> dict[str, Any]:
    """The JSON sidecar of ``graph`` exported as ``fmt`` to ``file``.

    Keys: ``sidecar_version``, ``format``, ``file``, ``graph``, ``aligner``,
    ``description``, ``inputs`` and ``outputs`` (``name``, ``dtype``, ``shape``
    with the labels of dynamic axes in place of sizes), ``dynamic_axes``,
    ``fixed_axes``, ``metadata`` and ``skelagnostic_version`` (plus ``opset``
    for ONNX).
    """
    from skelagnostic import __version__

    with torch.no_grad():
        outputs = _as_tuple(graph.module(*graph.example_inputs))
    if len(outputs) != len(graph.output_names):
        raise ExportError(
            f"export graph {graph.name!r}: forward returned {len(outputs)} "
            f"tensors for {len(graph.output_names)} output names"
        )
    axes = {k: dict(v) for k, v in graph.dynamic_axes.items()}
    out: dict[str, Any] = {
        "sidecar_version": SIDECAR_VERSION,
        "format": fmt,
        "file": file,
        "graph": graph.name,
        "aligner": aligner,
        "description": graph.description,
        "inputs": [
            _tensor_entry(n, t, axes.get(n, {}))
            for n, t in zip(graph.input_names, graph.example_inputs, strict=True)
        ],
        "outputs": [
            _tensor_entry(n, t, axes.get(n, {}))
            for n, t in zip(graph.output_names, outputs, strict=True)
        ],
        "dynamic_axes": {k: {str(a): label for a, label in v.items()} for k, v in axes.items()},
        "fixed_axes": dict(graph.fixed_axes),
        "metadata": _jsonable(dict(graph.metadata)),
        "skelagnostic_version": __version__,
    }
    if fmt == "onnx":
        out["opset"] = OPSET
    return out


def _dynamic_shapes(graph: ExportGraph) -> tuple[dict[int, Any] | None, ...]:
    """``dynamic_shapes`` for ``torch.onnx.export(dynamo=True)``: one ``Dim`` per label."""
    from torch.export import Dim

    dims: dict[str, Any] = {}
    shapes: list[dict[int, Any] | None] = []
    for name in graph.input_names:
        axes = graph.dynamic_axes.get(name)
        if not axes:
            shapes.append(None)
            continue
        shapes.append({axis: dims.setdefault(label, Dim(label)) for axis, label in axes.items()})
    params = inspect.signature(graph.module.forward).parameters.values()
    if any(p.kind is p.VAR_POSITIONAL for p in params):  # forward(*inputs): one argument
        return (tuple(shapes),)
    return tuple(shapes)


def _label_dynamic_outputs(path: Path, graph: ExportGraph) -> None:
    """Write the declared axis labels into the ONNX file's output shapes.

    The exporter infers output shapes itself and can leave a dynamic output axis
    at its example size (e.g. after a GRU), which only makes onnxruntime warn;
    the labels make the file's interface match the sidecar. The intermediate
    shape annotations are then dropped too (runtimes infer them again).
    """
    import onnx

    model = onnx.load(str(path))
    changed = False
    for value in model.graph.output:
        axes = graph.dynamic_axes.get(value.name, {})
        dims = value.type.tensor_type.shape.dim
        for axis, label in axes.items():
            if axis < len(dims) and dims[axis].dim_param != label:
                dims[axis].dim_param = label
                changed = True
    if changed:  # the intermediate shapes carry the same example size: let runtimes infer them
        del model.graph.value_info[:]
        onnx.save(model, str(path))


def _require_onnx() -> None:
    missing = []
    for package in ("onnx", "onnxscript"):
        try:
            __import__(package)
        except ImportError:
            missing.append(package)
    if missing:
        raise ExportError(
            f"format=onnx needs the {' and '.join(missing)} package(s): "
            "pip install 'skelagnostic[export]'"
        )


@contextlib.contextmanager
def _jit_scripting(module: nn.Module) -> Iterator[None]:
    """Tell the LightningModules inside ``module`` that they are being compiled.

    :func:`torch.jit.trace` probes every attribute of every submodule; a
    LightningModule's ``trainer`` property raises outside a Trainer unless its
    ``_jit_is_scripting`` flag is set (what ``LightningModule.to_torchscript`` does).
    """
    from lightning.pytorch import LightningModule

    flagged = [m for m in module.modules() if isinstance(m, LightningModule)]
    old = [m._jit_is_scripting for m in flagged]
    for m in flagged:
        m._jit_is_scripting = True
    try:
        yield
    finally:
        for m, value in zip(flagged, old, strict=True):
            m._jit_is_scripting = value


def _write_atomic(path: Path, write: Any) -> None:
    """Call ``write(tmp_path)`` and move the result to ``path`` (umask permissions).

    Raises:
        OutputError: The file cannot be written (full disk, ...); ``path`` is unchanged.
    """
    with output_path(path) as tmp:
        write(tmp)


#: Warnings of the ONNX exporter a user cannot act on (messages, as regular expressions).
_EXPORTER_NOISE = (
    r"`isinstance\(treespec, LeafSpec\)` is deprecated",
    r"# The axis name: .* will not be used, since it shares the same shape constraints",
)
#: Log records of the exporter a user cannot act on: (logger name, message start).
_EXPORTER_LOG_NOISE = (
    ("torch.onnx._internal.exporter._registration", "torchvision is not installed"),
)


class _DropRecords(logging.Filter):
    def __init__(self, start: str) -> None:
        super().__init__()
        self.start = start

    def filter(self, record: logging.LogRecord) -> bool:
        return not record.getMessage().startswith(self.start)


@contextlib.contextmanager
def _quiet_exporter() -> Iterator[None]:
    """Within the block: drop the exporter's warnings and log lines in :data:`_EXPORTER_NOISE`.

    ``torchvision is not installed. Skipping torchvision::nms`` (and three more, per
    graph), a deprecation inside Lightning's pytree helper and notes on dynamic axes
    that share a size: none of them says anything about the exported file.
    """
    filters = [
        (logging.getLogger(name), _DropRecords(start)) for name, start in _EXPORTER_LOG_NOISE
    ]
    for logger, drop in filters:
        logger.addFilter(drop)
    try:
        with warnings.catch_warnings():
            for pattern in _EXPORTER_NOISE:
                warnings.filterwarnings("ignore", message=f".*{pattern}")
            yield
    finally:
        for logger, drop in filters:
            logger.removeFilter(drop)


def export_graph(
    graph: ExportGraph, fmt: str, out_dir: str | Path, aligner: str = ""
) -> tuple[Path, Path]:
    """Write one graph as ``<out_dir>/<name><suffix>`` and its sidecar ``<name>.json``.

    Args:
        graph: The graph.
        fmt: ``"onnx"`` or ``"torchscript"``.
        out_dir: Output directory (created).
        aligner: Registered name of the aligner, for the sidecar.

    Returns:
        ``(model file, sidecar file)``.

    Raises:
        ExportError: Unknown format, a missing package, an inconsistent graph or
            an exporter failure (the message names the graph and the cause).
    """
    if fmt not in GRAPH_FORMATS:
        raise ExportError(f"format={fmt!r} is not one of {', '.join(GRAPH_FORMATS)}")
    graph.check()
    if fmt == "onnx":
        _require_onnx()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    model_path = out / f"{graph.name}{FORMATS[fmt]}"
    module = graph.module.eval()
    args = tuple(graph.example_inputs)
    meta = sidecar(graph, fmt, model_path.name, aligner)

    def write_onnx(path: Path) -> None:
        with _quiet_exporter():
            torch.onnx.export(
                module,
                args,
                str(path),
                dynamo=True,
                opset_version=OPSET,
                input_names=list(graph.input_names),
                output_names=list(graph.output_names),
                dynamic_shapes=_dynamic_shapes(graph),
                external_data=False,
                verbose=False,
            )
        _label_dynamic_outputs(path, graph)

    def write_torchscript(path: Path) -> None:
        with torch.no_grad(), _jit_scripting(module):
            traced = torch.jit.trace(module, args, check_trace=False)
        torch.jit.save(traced, str(path))

    try:
        _write_atomic(model_path, write_onnx if fmt == "onnx" else write_torchscript)
    except (ExportError, OutputError):
        raise
    except Exception as error:  # exporter internals: one line naming the graph and the cause
        root: BaseException = error
        while root.__cause__ is not None:
            root = root.__cause__
        text = re.sub(r"\x1b\[[0-9;]*m", "", str(root))
        first = next((ln.strip() for ln in text.splitlines() if ln.strip()), "")
        raise ExportError(
            f"export graph {graph.name!r} as {fmt} failed: {type(root).__name__}: {first}"
        ) from error
    side = out / f"{graph.name}.json"
    _write_atomic(side, lambda p: p.write_text(json.dumps(meta, indent=2) + "\n"))
    return model_path, side


def export_aligner(aligner: Aligner, fmt: str, out_dir: str | Path, name: str = "") -> list[Path]:
    """Export every graph of ``aligner.export_graphs()``.

    With ``fmt="safetensors"``, write the aligner's weights and model config as
    ``<out_dir>/model.safetensors`` instead (every aligner can).

    Args:
        aligner: A trained aligner (put in eval mode).
        fmt: ``"onnx"``, ``"torchscript"`` or ``"safetensors"``.
        out_dir: Output directory.
        name: Registered name of the aligner, for the sidecars (required for
            safetensors: loading the file back builds that aligner).

    Returns:
        The written files, model and sidecar per graph (the weights file for safetensors).

    Raises:
        ExportError: The aligner exports nothing, a safetensors export without
            ``name`` or the ``safetensors`` package, or see :func:`export_graph`.
    """
    if fmt not in FORMATS:
        raise ExportError(f"format={fmt!r} is not one of {', '.join(FORMATS)}")
    aligner.eval()
    if fmt == "safetensors":
        from skelagnostic.aligners.weights import WEIGHTS_FILE, save_weights

        try:
            return [save_weights(aligner, Path(out_dir) / WEIGHTS_FILE, name)]
        except OutputError:
            raise
        except SkelagnosticError as error:
            raise ExportError(str(error)) from error
    with torch.no_grad():
        graphs = list(aligner.export_graphs())
    if not graphs:
        raise ExportError(
            f"{type(aligner).__name__} exports no networks (Aligner.export_graphs returns none)"
        )
    names = [g.name for g in graphs]
    if len(set(names)) != len(names):
        raise ExportError(f"{type(aligner).__name__}.export_graphs: duplicate names {names}")
    written: list[Path] = []
    for graph in graphs:
        written.extend(export_graph(graph, fmt, out_dir, name))
    return written
