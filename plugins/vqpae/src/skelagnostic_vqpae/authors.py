"""Runs of the WalkTheDog authors' trainer, loaded into skelagnostic's own VQ-PAE network.

The authors' ``train_vq.py`` (github PeizhuoLi/walk-the-dog) writes into its
``--save`` directory:

* ``args.txt``: one line of ``--key=value`` options;
* per epoch ``E`` and dataset ``i`` (in ``--load`` order), ``{E}_{i}_{C}Channels.pt``:
  the state dict of that dataset's ``VQAE`` (``C`` = ``--phase_channels``);
* per epoch, ``{E}_{C}Channels_VQ.pt``: the state dict of the shared
  ``ResidualVectorQuantizer``;
* per epoch, the phase decoders (``{name}_{E-1:04d}_Channels.pt`` and ONNX
  files), which predict the authors' Unity features and are not loaded here.

:func:`load_run` reads the latest complete epoch into a
:class:`~skelagnostic_vqpae.aligner.VqpaeAligner` configured to compute what
their network computes: zero "same" padding, the timing convolution with the
encoder's kernel, the raw power spectrum into a frequency MLP of
``n_layers_fft`` layers with ELU after every layer, temporal centering after
the first decoder convolution, and their time grid
(``linspace(-window/2, window/2, T)``). The weights are mapped key by key
(:func:`vqae_key_map`). One layout differs: their quantised state interleaves
``(cos, sin)`` coefficient pairs per latent channel, ours holds the sine
coefficients then the cosine ones, so the amplitude MLP's last layer and the
codebook columns are permuted on loading (:func:`authors_state_order`;
:func:`to_authors_state` converts an amplitude back).

Inputs are windows normalised as the authors' data loader does (their
dataset's mean and standard deviation, which live with the dataset, not the
run), so the loaded aligner has identity input statistics.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch
from torch import Tensor

from skelagnostic.errors import SkelagnosticError
from skelagnostic_vqpae.aligner import VqpaeAligner

__all__ = [
    "authors_state_order",
    "load_run",
    "read_args",
    "to_authors_state",
    "vqae_key_map",
]

_ARG = re.compile(r"--([A-Za-z_][A-Za-z0-9_]*)=(.*?)(?=\s+--[A-Za-z_][A-Za-z0-9_]*=|\s*$)")
_NETWORK = re.compile(r"^(\d+)_(\d+)_(\d+)Channels\.pt$")


def read_args(path: str | Path) -> dict[str, str]:
    """The options of an authors' ``args.txt`` (``--key=value ...`` on one line), as strings.

    Args:
        path: The ``args.txt`` file.

    Returns:
        Option name -> value text.

    Raises:
        SkelagnosticError: The file is missing or holds no ``--key=value`` option.

    Example:
        >>> import tempfile, pathlib
        >>> f = pathlib.Path(tempfile.mkdtemp()) / "args.txt"
        >>> _ = f.write_text("--window=1.0 --load=Datasets/human,Datasets/dog ")
        >>> read_args(f)
        {'window': '1.0', 'load': 'Datasets/human,Datasets/dog'}
    """
    path = Path(path)
    if not path.is_file():
        raise SkelagnosticError(f"authors' run: {path} not found (train_vq.py writes it)")
    args = dict(_ARG.findall(path.read_text().strip()))
    if not args:
        raise SkelagnosticError(f"authors' run: {path} holds no --key=value option")
    return args


def _option(args: Mapping[str, str], key: str, kind: type, path: Path, default: Any = None) -> Any:
    if key not in args:
        if default is None:
            raise SkelagnosticError(f"authors' run: {path} has no --{key}")
        return default
    try:
        return kind(float(args[key])) if kind is int else kind(args[key])
    except ValueError as err:
        raise SkelagnosticError(
            f"authors' run: {path}: --{key}={args[key]!r} is not a {kind.__name__}"
        ) from err


def authors_state_order(latent: int) -> Tensor:
    """Index ``o`` with ``ours = theirs[..., o]`` for a ``[..., 2d]`` amplitude (state).

    Theirs: ``state[2j]`` multiplies ``cos``, ``state[2j + 1]`` multiplies ``sin``
    for latent channel ``j``. Ours (:func:`~skelagnostic_vqpae.model.phase_manifold`):
    ``A[j]`` multiplies ``sin``, ``A[d + j]`` multiplies ``cos``.

    Example:
        >>> authors_state_order(3).tolist()
        [1, 3, 5, 0, 2, 4]
    """
    j = torch.arange(latent)
    return torch.cat([2 * j + 1, 2 * j])


def to_authors_state(amplitude: Tensor) -> Tensor:
    """Our ``[..., 2d]`` amplitude in the authors' layout (interleaved ``(cos, sin)`` pairs)."""
    order = authors_state_order(amplitude.shape[-1] // 2).to(amplitude.device)
    return amplitude[..., torch.argsort(order)]


def vqae_key_map(n_layers_fft: int, n_layers_state: int) -> dict[str, str]:
    """Authors' ``VQAE`` state-dict key -> key in :class:`~skelagnostic_vqpae.model.VQPAE`.

    For two encoder/decoder convolutions (their ``--n_layers=2``). Their ``tpi``
    and ``args`` entries are constants checked and used by :func:`load_run`.
    """
    pairs = {
        "convs.0": "encoder.0",
        "convs.3": "encoder.3",
        "phase_conv.0": "phase_conv",
        "deconvs.0": "decoder.0",
        "deconvs.3": "decoder.3",
    }
    # their MLP: Linear, LeakyReLU, ELU per hidden layer (indices 3i); ours with freq_hidden_elu
    pairs.update({f"freq_fc.layers.{3 * i}": f"freq_mlp.{3 * i}" for i in range(n_layers_fft)})
    pairs.update({f"state_fc.layers.{2 * i}": f"amp_mlp.{2 * i}" for i in range(n_layers_state)})
    return {f"{a}.{p}": f"{b}.{p}" for a, b in pairs.items() for p in ("weight", "bias")}


def _latest_epoch(run: Path, datasets: int, phases: int) -> int:
    epochs: dict[int, set[int]] = {}
    for f in run.iterdir():
        m = _NETWORK.match(f.name)
        if m and int(m.group(3)) == phases:
            epochs.setdefault(int(m.group(1)), set()).add(int(m.group(2)))
    complete = [
        e
        for e, found in epochs.items()
        if found >= set(range(datasets)) and (run / f"{e}_{phases}Channels_VQ.pt").is_file()
    ]
    if not complete:
        raise SkelagnosticError(
            f"authors' run: {run} has no complete epoch: expected {{E}}_{{i}}_{phases}Channels.pt "
            f"for i = 0..{datasets - 1} and {{E}}_{phases}Channels_VQ.pt"
        )
    return max(complete)


def _load(path: Path) -> dict[str, Tensor]:
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as err:  # torch raises several types for a bad file
        raise SkelagnosticError(f"authors' run: cannot read {path}: {err}") from err
    if not isinstance(state, Mapping):
        raise SkelagnosticError(f"authors' run: {path} is not a state dict")
    return dict(state)


def _tensor(state: Mapping[str, Tensor], key: str, path: Path) -> Tensor:
    if key not in state:
        raise SkelagnosticError(f"authors' run: {path} has no key {key!r}")
    return state[key]


def _dataset_names(load: str) -> list[str]:
    names: list[str] = []
    for i, part in enumerate(load.split(",")):
        name = Path(part.strip().rstrip("/")).name or f"dataset{i}"
        names.append(name if name not in names else f"{name}_{i}")
    return names


def _check_options(args: Mapping[str, str], path: Path) -> None:
    for key, wanted in (("phase_channels", 1), ("use_vq", 1), ("n_layers", 2)):
        value = _option(args, key, int, path, default=wanted)
        if value != wanted:
            raise SkelagnosticError(
                f"authors' run: {path}: --{key}={value} is not supported (only {wanted}: one "
                "phase channel, one quantisation step, two convolutions each way)"
            )
    distance = args.get("vq_distance", "l2")
    if distance != "l2":
        raise SkelagnosticError(
            f"authors' run: {path}: --vq_distance={distance} is not supported (only l2)"
        )


def load_run(run_dir: str | Path, epoch: int | None = None) -> VqpaeAligner:
    """Load an authors' ``train_vq.py`` run into a :class:`VqpaeAligner` (eval mode, CPU).

    Args:
        run_dir: The run's ``--save`` directory.
        epoch: Epoch to load (default: the latest with every dataset's network and the VQ).

    Returns:
        The aligner, one character per ``--load`` dataset, named after the
        dataset directory (``Datasets/human`` -> ``human``). It has no skeletons
        (the run does not store them) and no average-pose MLP.

    Raises:
        SkelagnosticError: A file is missing or unreadable, an option is not
            supported, or a weight is missing, unexpected or of the wrong shape
            (the message names the file and the key).
    """
    run = Path(run_dir)
    if not run.is_dir():
        raise SkelagnosticError(f"authors' run: {run} is not a directory")
    args_path = run / "args.txt"
    args = read_args(args_path)
    _check_options(args, args_path)
    names = _dataset_names(_option(args, "load", str, args_path))
    phases = _option(args, "phase_channels", int, args_path, default=1)
    if epoch is None:
        epoch = _latest_epoch(run, len(names), phases)
    latent = _option(args, "n_latent_channel", int, args_path)
    n_fft = _option(args, "n_layers_fft", int, args_path)
    n_state = _option(args, "n_layers_state", int, args_path)
    key_map = vqae_key_map(n_fft, n_state)

    states, specs = [], {}
    for i, name in enumerate(names):
        path = run / f"{epoch}_{i}_{phases}Channels.pt"
        if not path.is_file():
            raise SkelagnosticError(f"authors' run: {path} not found (dataset {i}, {name!r})")
        state = _load(path)
        tpi = float(_tensor(state, "tpi", path))
        if not math.isclose(tpi, 2 * math.pi, rel_tol=1e-6):
            raise SkelagnosticError(f"authors' run: {path}: 'tpi' is {tpi}, not 2 pi")
        grid = _tensor(state, "args", path).float()
        if grid.dim() != 1 or grid.numel() < 3 or grid.numel() % 2 == 0:
            raise SkelagnosticError(
                f"authors' run: {path}: 'args' (the time grid) must be an odd-length vector, "
                f"got shape {list(grid.shape)}"
            )
        conv = _tensor(state, "convs.0.weight", path)
        span = float(grid[-1] - grid[0])
        if not span > 0:
            raise SkelagnosticError(
                f"authors' run: {path}: 'args' (the time grid) must increase, got {grid.tolist()}"
            )
        specs[name] = {
            "channels": int(conv.shape[1]),
            "window": grid.numel(),
            "fps": (grid.numel() - 1) / span,
        }
        states.append((path, state, grid))

    book_path = run / f"{epoch}_{phases}Channels_VQ.pt"
    if not book_path.is_file():
        raise SkelagnosticError(f"authors' run: {book_path} not found")
    book_state = _load(book_path)
    embedding = _tensor(book_state, "vqs.0.embedding.weight", book_path)
    first = states[0][1]
    kernel = int(_tensor(first, "convs.0.weight", states[0][0]).shape[-1])
    phase_kernel = int(_tensor(first, "phase_conv.0.weight", states[0][0]).shape[-1])
    model = VqpaeAligner(
        latent=latent,
        num_codes=int(embedding.shape[0]),
        kernel_size=kernel,
        freq_layers=n_fft,
        amp_layers=n_state,
        decoder_centering=True,
        spectrum="power",
        padding_mode="zeros",
        frequency_head="mlp",
        phase_kernel=phase_kernel,
        freq_hidden_elu=True,
        center_windows=False,
        beta=_option(args, "beta", float, args_path, default=0.25),
        lambda_vq=_option(args, "lambda_vq", float, args_path, default=1.0),
        lambda_phase_rate=0.0,
        reinit_squared_distance=True,
        lr=_option(args, "learning_rate", float, args_path, default=1e-4),
        weight_decay=_option(args, "weight_decay", float, args_path, default=1e-4),
        restart_period=_option(args, "restart_period", int, args_path, default=10),
        restart_mult=_option(args, "restart_mult", int, args_path, default=2),
        pose_mlp="none",
        datasets=specs,
    )
    order = authors_state_order(latent)
    for (path, state, grid), char in zip(states, model.characters, strict=True):
        _copy_network(state, char.pae, key_map, order, n_state, path)
        char.pae.times.copy_(grid)
    _copy_codebook(book_state, model, order, book_path)
    return model.eval()


def _copy_network(
    state: Mapping[str, Tensor],
    pae: torch.nn.Module,
    key_map: Mapping[str, str],
    order: Tensor,
    n_state: int,
    path: Path,
) -> None:
    ours = pae.state_dict()
    unexpected = sorted(set(state) - set(key_map) - {"tpi", "args"})
    if unexpected:
        raise SkelagnosticError(
            f"authors' run: {path} has unexpected keys {unexpected} "
            "(a network option this loader does not know)"
        )
    last = f"amp_mlp.{2 * (n_state - 1)}"
    new = {}
    for theirs, key in key_map.items():
        value = _tensor(state, theirs, path)
        if key not in ours:
            raise SkelagnosticError(
                f"authors' run: {path}: {theirs!r} maps to {key!r}, which "
                "skelagnostic's network lacks"
            )
        if key.startswith(last):  # the state's layout: interleaved (cos, sin) -> (sin..., cos...)
            value = value[order]
        if value.shape != ours[key].shape:
            raise SkelagnosticError(
                f"authors' run: {path}: {theirs!r} has shape {list(value.shape)}, skelagnostic's "
                f"{key!r} has {list(ours[key].shape)}"
            )
        new[key] = value
    missing = sorted(set(ours) - set(new))
    if missing:
        raise SkelagnosticError(
            f"authors' run: {path} leaves {missing} of skelagnostic's network unset"
        )
    pae.load_state_dict(new)


def _copy_codebook(
    state: Mapping[str, Tensor], model: VqpaeAligner, order: Tensor, path: Path
) -> None:
    book = model.codebook
    assert book is not None  # built from datasets=
    weight = _tensor(state, "vqs.0.embedding.weight", path)
    if weight.shape != book.weight.shape:
        raise SkelagnosticError(
            f"authors' run: {path}: 'vqs.0.embedding.weight' has shape {list(weight.shape)}, "
            f"expected {list(book.weight.shape)} (--num_embed_vq x 2 --n_latent_channel)"
        )
    known = {"vqs.0.embedding.weight"}
    with torch.no_grad():
        book.weight.copy_(weight[:, order])
        for k in range(book.num_datasets):  # usage EMA; one shared updater: same key for all
            key = next(
                (
                    f"vqs.0.updater.{j}.embed_prob"
                    for j in (k, 0)
                    if f"vqs.0.updater.{j}.embed_prob" in state
                ),
                None,
            )
            if key is not None:
                book.usage[k].copy_(state[key])
                known.add(key)
    unexpected = sorted(
        k for k in set(state) - known if not re.fullmatch(r"vqs\.0\.updater\.\d+\.embed_prob", k)
    )
    if unexpected:
        raise SkelagnosticError(f"authors' run: {path} has unexpected keys {unexpected}")
