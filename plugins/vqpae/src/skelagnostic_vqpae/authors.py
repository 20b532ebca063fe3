"""Runs of the WalkTheDog authors' trainer, loaded into skelagnostic's own VQ-PAE network.

The authors' ``train_vq.py`` (github PeizhuoLi/walk-the-dog) writes into its
``--save`` directory:

* ``args.txt``: one line of ``--key=value`` options;
* per epoch ``E`` and dataset ``i`` (in ``--load`` order), ``{E}_{i}_{C}Channels.pt``:
  the state dict of that dataset's ``VQAE`` (``C`` = ``--phase_channels``);
* per epoch, ``{E}_{C}Channels_VQ.pt``: the state dict of the shared
  ``ResidualVectorQuantizer``;
* per epoch and dataset, with ``--train_phase_decoder=1`` (their default), the
  phase decoder (``{name}_{E-1:04d}_Channels.pt``, ``name`` their dataset name,
  which their trainer takes from the ``--load`` path, and an ONNX export):
  a ``NormalizedMLP`` from a manifold point to the dataset's
  ``--needed_channel_names_phase_decoder`` features (default
  ``Velocities,Positions,Rotations`` of their Unity exporter), trained jointly
  with the VQ-PAE. It is the paper's average-pose MLP (Sec. 5.2): the same
  layers (``--n_layers_phase_decoder`` linear layers, LeakyReLU 0.2) as
  :class:`~skelagnostic_vqpae.model.AveragePoseMLP`, so it loads into the
  dataset's ``pose`` MLP, its output statistics into ``pose_mean``/``pose_std``
  (its input statistics, ones and zeros in their trainer, are folded into the
  first layer). Its outputs are their features, not skelagnostic's root-local
  positions: :meth:`VqpaeAligner.average_pose` runs it, ``decode`` refuses it.

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
run), so the loaded aligner has identity input statistics, and no skeleton:
:meth:`VqpaeAligner.embed_windows` takes such windows. To run it on motions
(``skelagnostic transfer ... ckpt=authors:<dir>``, ``evaluate``), put two files
per dataset ``name`` into the run directory:

* ``<name>.bvh``: a BVH file of that character whose joints, in file order, are
  the joints of the network's input channels (three per joint); its hierarchy
  becomes the dataset's skeleton (the motion in it is not used);
* ``<name>_normalization.npz``: arrays ``mean`` and ``std`` (one value per input
  channel) that normalise the features, ``(x - mean) / std``.

The windows are then skelagnostic's :class:`~skelagnostic.representations.RootLocalVelocities`
of the clips; they are what the authors' network saw only if their exporter's
``Velocities`` are the same quantity in the same frame and units, which this
loader cannot check.
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
from skelagnostic_vqpae.options import AUTHORS_OPTIMIZER, AUTHORS_SCHEDULER

__all__ = [
    "authors_state_order",
    "load_run",
    "phase_decoder_files",
    "read_args",
    "to_authors_state",
    "vqae_key_map",
]

_ARG = re.compile(r"--([A-Za-z_][A-Za-z0-9_]*)=(.*?)(?=\s+--[A-Za-z_][A-Za-z0-9_]*=|\s*$)")
_NETWORK = re.compile(r"^(\d+)_(\d+)_(\d+)Channels\.pt$")
_DECODER = re.compile(r"^(.+)_(\d{4})_Channels\.pt$")


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


def phase_decoder_files(run_dir: str | Path, epoch: int) -> dict[str, Path]:
    """The phase decoders of network epoch ``epoch`` in a run: load path -> file.

    Their trainer writes the decoder of epoch ``E`` (1-based, as the networks'
    files) as ``{name}_{E-1:04d}_Channels.pt``, ``name`` derived from the
    dataset's ``--load`` path. A file belongs to the dataset whose lower-cased
    load path contains its ``name`` (the longest such name when several do).

    Args:
        run_dir: The run's ``--save`` directory (its ``args.txt`` gives ``--load``).
        epoch: The networks' epoch ``E``.

    Returns:
        ``--load`` entry -> decoder file, for the datasets that have one.

    Raises:
        SkelagnosticError: ``args.txt`` is missing or has no ``--load``.
    """
    run = Path(run_dir)
    loads = [
        part.strip()
        for part in _option(read_args(run / "args.txt"), "load", str, run / "args.txt").split(",")
    ]
    found: dict[str, tuple[int, Path]] = {}
    for f in sorted(run.iterdir()):
        m = _DECODER.match(f.name)
        if not m or int(m.group(2)) != epoch - 1:
            continue
        owners = [load for load in loads if m.group(1).lower() in load.lower()]
        for load in owners:
            if len(m.group(1)) > found.get(load, (-1, f))[0]:
                found[load] = (len(m.group(1)), f)
    return {load: path for load, (_, path) in found.items()}


def load_run(run_dir: str | Path, epoch: int | None = None) -> VqpaeAligner:
    """Load an authors' ``train_vq.py`` run into a :class:`VqpaeAligner` (eval mode, CPU).

    Args:
        run_dir: The run's ``--save`` directory.
        epoch: Epoch to load (default: the latest with every dataset's network and the VQ).

    Returns:
        The aligner, one character per ``--load`` dataset, named after the
        dataset directory (``Datasets/human`` -> ``human``), with the phase decoders
        of that epoch when the run has them (see the module docstring). Without
        ``<name>.bvh`` and ``<name>_normalization.npz`` files in the run directory
        a dataset has no skeleton and identity input statistics.

    Raises:
        SkelagnosticError: A file is missing or unreadable, an option is not
            supported, or a weight is missing, unexpected or of the wrong shape
            (the message names the file and the key); a skeleton's joints do not
            match the channels, or its normalisation file is missing or malformed.
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

    states, specs = _network_states(run, epoch, names, phases)
    decoders = _phase_decoders(run, epoch, names, args, args_path, specs)
    pose_layers = _option(args, "n_layers_phase_decoder", int, args_path, default=8)
    normalization = {}
    for name in names:
        skeleton, stats = _character_files(run, name, int(specs[name]["channels"]))
        if skeleton is not None:
            specs[name]["skeleton"] = skeleton
            normalization[name] = stats

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
        optimizer={
            **AUTHORS_OPTIMIZER,
            "lr": _option(args, "learning_rate", float, args_path, default=1e-4),
            "weight_decay": _option(args, "weight_decay", float, args_path, default=1e-4),
        },
        scheduler={
            **AUTHORS_SCHEDULER,
            "period": _option(args, "restart_period", int, args_path, default=10),
            "mult": _option(args, "restart_mult", int, args_path, default=2),
        },
        pose_mlp="joint" if decoders else "none",
        pose_layers=pose_layers,
        pose_lr=_option(args, "lr_phase_decoder", float, args_path, default=1e-3),
        datasets=specs,
    )
    order = authors_state_order(latent)
    for (path, state, grid), char in zip(states, model.characters, strict=True):
        _copy_network(state, char.pae, key_map, order, n_state, path)
        char.pae.times.copy_(grid)
    for name, char in zip(names, model.characters, strict=True):
        if name in decoders:
            _copy_decoder(*decoders[name], char, pose_layers)
        if name in normalization:
            char.input_mean.copy_(normalization[name][0])
            char.input_std.copy_(normalization[name][1])
    _copy_codebook(book_state, model, order, book_path)
    return model.eval()


def _network_states(
    run: Path, epoch: int, names: list[str], phases: int
) -> tuple[list[tuple[Path, dict[str, Tensor], Tensor]], dict[str, dict[str, Any]]]:
    """Each dataset's network state of ``epoch``, checked, and the spec it implies.

    Returns:
        ``([(path, state, time grid)], dataset name -> {"channels", "window", "fps"})``.
    """
    states: list[tuple[Path, dict[str, Tensor], Tensor]] = []
    specs: dict[str, dict[str, Any]] = {}
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
    return states, specs


def _phase_decoders(
    run: Path,
    epoch: int,
    names: list[str],
    args: Mapping[str, str],
    args_path: Path,
    specs: dict[str, dict[str, Any]],
) -> dict[str, tuple[Path, dict[str, Tensor]]]:
    """The phase decoders of ``epoch`` per dataset name.

    Their output size and feature names go into each dataset's ``specs`` entry.
    """
    loads = [part.strip() for part in _option(args, "load", str, args_path).split(",")]
    decoder_files = phase_decoder_files(run, epoch)
    decoders: dict[str, tuple[Path, dict[str, Tensor]]] = {}
    for name, load in zip(names, loads, strict=True):
        if load in decoder_files:
            path = decoder_files[load]
            decoders[name] = (path, _load(path))
    if decoders:
        activation = args.get("activation_phase_decoder", "LeakyReLU")
        if activation != "LeakyReLU":
            raise SkelagnosticError(
                f"authors' run: {args_path}: --activation_phase_decoder={activation} is not "
                "supported (only LeakyReLU, their default, as skelagnostic's average-pose MLP)"
            )
        features = args.get(
            "needed_channel_names_phase_decoder", "Velocities,Positions,Rotations"
        ).split(",")
        for name, (path, state) in decoders.items():
            out = _tensor(state, "std_out", path)
            specs[name]["pose_channels"] = int(out.numel())
            specs[name]["pose_features"] = [f.strip() for f in features]
    return decoders


def _character_files(
    run: Path, name: str, channels: int
) -> tuple[dict[str, Any] | None, tuple[Tensor, Tensor] | None]:
    """The skeleton (``to_dict``) and input statistics of ``<name>.bvh`` and its ``.npz``."""
    bvh = run / f"{name}.bvh"
    if not bvh.is_file():
        return None, None
    from skelagnostic.io.bvh import read_bvh

    skeleton = read_bvh(bvh).skeleton
    if 3 * skeleton.num_joints != channels:
        raise SkelagnosticError(
            f"authors' run: {bvh} has {skeleton.num_joints} joints, but the network of "
            f"dataset {name!r} takes {channels} channels ({channels / 3:g} joints x 3)"
        )
    stats_path = run / f"{name}_normalization.npz"
    if not stats_path.is_file():
        raise SkelagnosticError(
            f"authors' run: {bvh} gives dataset {name!r} a skeleton, but {stats_path} is "
            f"missing: save the input statistics there as arrays 'mean' and 'std' of "
            f"{channels} values (numpy.savez)"
        )
    import numpy as np

    with np.load(stats_path) as stats:
        values = []
        for key in ("mean", "std"):
            if key not in stats.files or stats[key].size != channels:
                raise SkelagnosticError(
                    f"authors' run: {stats_path} needs an array {key!r} of {channels} values"
                )
            values.append(torch.as_tensor(stats[key], dtype=torch.float32).reshape(-1))
    if not bool((values[1] > 0).all()):
        raise SkelagnosticError(f"authors' run: {stats_path}: 'std' must be positive")
    return skeleton.to_dict(), (values[0], values[1])


def _copy_decoder(path: Path, state: Mapping[str, Tensor], char: Any, layers: int) -> None:
    """An authors' phase decoder into ``char.pose`` and its output statistics."""
    mlp = char.pose.net
    linear = [i for i, m in enumerate(mlp) if isinstance(m, torch.nn.Linear)]
    keys = {f"layers.{2 * j}.{p}" for j in range(layers) for p in ("weight", "bias")}
    stats = {"std_in", "mean_in", "std_out", "mean_out"}
    unexpected = sorted(set(state) - keys - stats)
    missing = sorted(keys - set(state))
    if unexpected or missing or len(linear) != layers:
        raise SkelagnosticError(
            f"authors' run: {path} is not a {layers}-layer phase decoder "
            f"(--n_layers_phase_decoder): missing {missing}, unexpected {unexpected}"
        )
    new = {}
    for j, index in enumerate(linear):
        for p in ("weight", "bias"):
            value = _tensor(state, f"layers.{2 * j}.{p}", path).float()
            if value.shape != getattr(mlp[index], p).shape:
                raise SkelagnosticError(
                    f"authors' run: {path}: 'layers.{2 * j}.{p}' has shape {list(value.shape)}, "
                    f"skelagnostic's average-pose MLP has {list(getattr(mlp[index], p).shape)}"
                )
            new[f"{index}.{p}"] = value
    # their eval-mode input normalisation (x - mean_in) / std_in, folded into the first layer
    std_in = _tensor(state, "std_in", path).float()
    mean_in = _tensor(state, "mean_in", path).float()
    first = f"{linear[0]}"
    weight = new[f"{first}.weight"] / std_in
    new[f"{first}.bias"] = new[f"{first}.bias"] - weight @ mean_in
    new[f"{first}.weight"] = weight
    mlp.load_state_dict(new)
    with torch.no_grad():
        char.pose_mean.copy_(_tensor(state, "mean_out", path).float().reshape(-1))
        char.pose_std.copy_(_tensor(state, "std_out", path).float().reshape(-1))
        char.pose_fitted.fill_(True)


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
