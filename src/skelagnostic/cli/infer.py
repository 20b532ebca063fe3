"""``skelagnostic retarget|interpolate|transfer``: apply a trained aligner to motion files.

Inputs and ``out=`` are BVH (``.bvh``) or glTF 2.0 (``.glb``, ``.gltf``), chosen by
suffix (:mod:`skelagnostic.io.motion_files`). Usage::

    skelagnostic retarget SOURCE.bvh TARGET.bvh ckpt=PATH [model=NAME] out=OUT.bvh
    skelagnostic interpolate INPUT.bvh ckpt=PATH (every=N | keys=0,15,40) out=OUT.bvh
    skelagnostic transfer SOURCE.bvh TARGET.bvh|DIR [...] ckpt=PATH out=OUT.bvh

Every verb also takes ``render=OUT.gif`` (or ``.png``/``.mp4``/``.html``) to draw
the input next to the result, ``html=VIEW.html`` for the interactive 3D viewer
(keyframes / matching transitions marked on its timeline), plus the rendering
options of ``skelagnostic render``, and ``cleanup=footlock`` to pin the result's
planted feet (:func:`skelagnostic.cleanup.foot_lock`).

The aligner is built from a checkpoint written by ``skelagnostic fit``; its name
comes from ``model=`` or, when omitted, from the run's ``config.yaml`` next to
the checkpoint. Each verb calls one method of
:class:`~skelagnostic.aligners.Aligner` (``retarget``, ``interpolate``,
``transfer``), so it works with any plugin that declares the capability.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from skelagnostic.cli.render import (
    END_OF_OPTIONS_HELP,
    RENDER_OPTIONS,
    THREADS_HELP,
    apply_threads,
    check_render_outputs,
    parse_arguments,
    render_from_options,
    wants_help,
)
from skelagnostic.errors import SkelagnosticError, error_line, printable

if TYPE_CHECKING:
    from skelagnostic.aligners import Aligner
    from skelagnostic.core.motion import Motion

__all__ = ["interpolate", "keyframes_from_options", "load_from_checkpoint", "retarget", "transfer"]

_COMMON = {
    "ckpt": "checkpoint written by `skelagnostic fit`, or <scheme>:<path> read by a "
    "plugin's checkpoint reader (e.g. authors:<run dir>) (required)",
    "model": "registered aligner name; default: model.name of the run's config.yaml",
    "out": "output motion path (required): .bvh, or .glb/.gltf for glTF 2.0; written atomically",
    "render": "also draw input and result side by side (.gif, .mp4, .png or .html)",
    "cleanup": "footlock: pin the result's planted feet (contacts detected on the result; "
    "two-bone IK faded in and out with inertialization); none (default)",
    "units": "length unit of the input motion files (m, cm, mm, inch, ft, cmu); "
    "default: the aligner guesses",
    "threads": THREADS_HELP,
}

_USAGE = {
    "retarget": (
        "usage: skelagnostic retarget SOURCE.bvh TARGET.bvh ckpt=PATH out=OUT.bvh "
        "[key=value ...]\n\n"
        "Move the motion of SOURCE.bvh onto the skeleton of TARGET.bvh (only its\n"
        "hierarchy is used) with a trained aligner that declares 'retarget'.",
        {},
    ),
    "interpolate": (
        "usage: skelagnostic interpolate INPUT.bvh ckpt=PATH (every=N | keys=I,J,...) "
        "out=OUT.bvh [key=value ...]\n\n"
        "Keep the keyframes of INPUT.bvh and generate the frames between them with a\n"
        "trained aligner that declares 'interpolate'.",
        {
            "every": "a keyframe every N frames (the first and last frames are always keys)",
            "keys": "explicit comma-separated keyframe indices (0 and the last are added)",
        },
    ),
    "transfer": (
        "usage: skelagnostic transfer SOURCE.bvh TARGET.bvh|DIR [...] ckpt=PATH out=OUT.bvh "
        "[key=value ...]\n\n"
        "Re-enact SOURCE.bvh with the target character's clips (motion files or\n"
        "directories of them, one skeleton) with a trained aligner that declares\n"
        "'transfer' (for example VQ-PAE's frequency-scaled motion matching).",
        {},
    ),
}


def _usage(verb: str) -> str:
    head, extra = _USAGE[verb]
    options = {**_COMMON, **extra, **RENDER_OPTIONS}
    lines = [f"  {key:<11} {text}" for key, text in options.items()]
    return head + "\n\noptions:\n" + "\n".join(lines) + "\n\n" + END_OF_OPTIONS_HELP


def load_from_checkpoint(ckpt: str | Path, model: str | None = None) -> Aligner:
    """Build the aligner saved in a ``skelagnostic fit`` checkpoint, or read by a plugin.

    Args:
        ckpt: The checkpoint file, a weights file written by ``export
            format=safetensors`` (or its directory), or ``<scheme>:<path>`` for a
            checkpoint reader a plugin registered (``register_checkpoint_readers``;
            for example ``authors:<run dir>`` of the VQ-PAE plugin), which also
            names the model.
        model: Registered aligner name; ``None`` reads ``model.name`` from the
            ``config.yaml`` of the run directory holding the checkpoint
            (``<run>/checkpoints/<file>.ckpt`` or ``<run>/<file>.ckpt``), or the
            ``model`` field of a weights file.

    Returns:
        The aligner in eval mode.

    Raises:
        SkelagnosticError: The name cannot be found or is not registered.
        CheckpointError: The checkpoint is missing, not a readable checkpoint,
            refused by the safe loader (``weights_only=True``), written by another
            model or of a different architecture.
    """
    from skelagnostic.aligners.checkpoints import load_checkpoint, read_checkpoint
    from skelagnostic.aligners.weights import is_weights, weights_model
    from skelagnostic.plugins import get_plugin_manager

    pm = get_plugin_manager()
    external = pm.read_external_checkpoint(ckpt, model)
    if external is not None:
        return external
    path = Path(ckpt)
    weights = is_weights(path)  # export format=safetensors: the file names its model
    if not weights and not path.is_file():
        read_checkpoint(path, option="ckpt")  # raises the "no checkpoint file" error
    if model is None:
        model = weights_model(path, option="ckpt") if weights else _model_name_near(path)
    return load_checkpoint(
        pm.aligner(model).module, path, option="ckpt", aligners=pm.aligner_classes()
    ).eval()


def _model_name_near(ckpt: Path) -> str:
    from omegaconf import OmegaConf

    for run_dir in (ckpt.parent, ckpt.parent.parent):
        config = run_dir / "config.yaml"
        if config.is_file():
            name = OmegaConf.select(OmegaConf.load(config), "model.name")
            if isinstance(name, str) and name:
                return name
            raise SkelagnosticError(f"{config}: has no model.name; give model=NAME")
    raise SkelagnosticError(
        f"ckpt={str(ckpt)!r}: no config.yaml of a skelagnostic run next to it; give model=NAME"
    )


def keyframes_from_options(num_frames: int, every: str | None, keys: str | None) -> list[int]:
    """The keyframe indices asked for by ``every=`` or ``keys=``.

    The first and last frames are always keys.

    Args:
        num_frames: Length of the clip.
        every: ``every=`` value (a positive integer as text) or ``None``.
        keys: ``keys=`` value (comma-separated indices) or ``None``.

    Returns:
        Sorted, unique keyframe indices.

    Raises:
        SkelagnosticError: Neither or both given, a malformed value, or an index
            outside the clip.

    Examples:
        >>> keyframes_from_options(10, "4", None)
        [0, 4, 8, 9]
        >>> keyframes_from_options(10, None, "3,5")
        [0, 3, 5, 9]
    """
    if (every is None) == (keys is None):
        raise SkelagnosticError("give exactly one of every=N or keys=I,J,...")
    if num_frames < 2:
        raise SkelagnosticError(f"the clip has {num_frames} frame(s); need at least 2")
    if every is not None:
        try:
            step = int(every)
        except ValueError:
            step = 0
        if step < 1:
            raise SkelagnosticError(f"option every={every!r} is not a positive integer")
        chosen = set(range(0, num_frames, step))
    else:
        try:
            chosen = {int(k) for k in str(keys).split(",") if k.strip()}
        except ValueError:
            raise SkelagnosticError(f"option keys={keys!r} is not a list of integers") from None
        bad = sorted(k for k in chosen if not 0 <= k < num_frames)
        if bad:
            raise SkelagnosticError(
                f"option keys: frame(s) {bad} are outside the clip (0..{num_frames - 1})"
            )
    return sorted(chosen | {0, num_frames - 1})


def _read(path: Path, options: dict[str, str]) -> Motion:
    """``read_motion(path)`` without a trajectory carrier, with the ``units=`` option applied."""
    from skelagnostic.core.motion import UNITS, reroot
    from skelagnostic.io.motion_files import read_motion

    motion = read_motion(path, other="bvh")  # any name but .glb/.gltf is BVH, as before
    motion = reroot(motion, motion.skeleton.body_root)
    units = options.get("units")
    if units is not None:
        if units not in UNITS:
            raise SkelagnosticError(f"option units={units!r}: known units are {', '.join(UNITS)}")
        motion.units = units
    return motion


def _motion_paths(items: Sequence[str]) -> list[Path]:
    from skelagnostic.io.motion_files import MOTION_SUFFIXES

    paths: list[Path] = []
    for item in items:
        path = Path(item)
        if path.is_dir():
            found = sorted(p for p in path.rglob("*") if p.suffix.lower() in MOTION_SUFFIXES)
            if not found:
                raise SkelagnosticError(f"{path}: directory holds no .bvh, .glb or .gltf file")
            paths.extend(found)
        elif path.is_file():
            paths.append(path)
        else:
            raise SkelagnosticError(f"{path}: no such file or directory")
    return paths


#: What a verb does with a loaded aligner: ``(aligner) -> (input shown, result)``.
Apply = Callable[["Aligner"], tuple["Motion", "Motion"]]


def _run(
    verb: str,
    argv: list[str],
    positional: tuple[int, int | None],
    prepare: Callable[[list[Path], dict[str, str]], Apply],
    marks: dict[str, dict[int, list[int]]] | None = None,
) -> int:
    """Shared driver: parse, check options, read the inputs, load the aligner, apply, write.

    ``prepare`` reads and checks the inputs before the (slower) checkpoint is
    loaded, so bad input files fail fast; it returns what to do with the aligner.
    ``marks`` (filled by that) holds keyframes / transitions for the viewer.
    """
    if not argv or wants_help(argv):
        print(_usage(verb))
        return 0 if argv else 2
    try:
        from skelagnostic.io.motion_files import MOTION_SUFFIXES, write_motion
        from skelagnostic.io.outputs import check_output_file

        words, options = parse_arguments(argv)
        apply_threads(options)
        known = set(_COMMON) | set(_USAGE[verb][1]) | set(RENDER_OPTIONS)
        unknown = sorted(set(options) - known)
        if unknown:
            raise SkelagnosticError(
                f"unknown option(s) {', '.join(k + '=' for k in unknown)}; "
                f"see 'skelagnostic {verb} --help'"
            )
        cleanup = _cleanup(options.get("cleanup", "none"))
        low, high = positional
        if len(words) < low or (high is not None and len(words) > high):
            raise SkelagnosticError(
                f"expected {low if high == low else f'at least {low}'} input path(s), "
                f"got {len(words)}; see 'skelagnostic {verb} --help'"
            )
        for key in ("ckpt", "out"):
            if key not in options:
                raise SkelagnosticError(f"missing option {key}=")
        if Path(options["out"]).suffix.lower() not in MOTION_SUFFIXES:
            raise SkelagnosticError(
                f"option out={options['out']!r}: must be a .bvh, .glb or .gltf path"
            )
        # every output is checked before any is written (out= is written first)
        check_output_file(options["out"], "out")
        check_render_outputs(options, out_key="render")
        paths = [Path(w) for w in words]
        for path in paths[: 1 if verb == "transfer" else len(paths)]:
            if not path.is_file():
                raise SkelagnosticError(f"{path}: no such file")
        apply = prepare(paths, options)
        aligner = load_from_checkpoint(options["ckpt"], options.get("model"))
        source, result = apply(aligner)
        result = cleanup(result)
        rendered: list[Path] = []
        # the renders come first: a render option refused late (fps=1e9) leaves
        # the previous out= in place, never a result without its picture
        if "render" in options or "html" in options:
            labels = options.get("labels")
            render_options = {**options, "labels": labels or f"input,{verb}"}
            rendered = render_from_options(
                [source, result], render_options, out_key="render", **(marks or {})
            )
        Path(options["out"]).parent.mkdir(parents=True, exist_ok=True)
        write_motion(result, options["out"])  # atomic: replaces out= only when complete
        for path in [options["out"], *rendered]:
            print(printable(path))
    except SkelagnosticError as error:
        print(error_line(f"skelagnostic {verb}", error), file=sys.stderr)
        return 2
    return 0


def _cleanup(name: str) -> Callable[[Motion], Motion]:
    """The clean-up pass ``cleanup=`` names (checked before anything is read)."""
    if name == "none":
        return lambda motion: motion
    if name == "footlock":
        from skelagnostic.cleanup import foot_lock

        return foot_lock
    raise SkelagnosticError(f"option cleanup={name!r}: must be footlock or none")


def retarget(argv: list[str]) -> int:
    """Run ``skelagnostic retarget`` (``Aligner.retarget``)."""

    def prepare(paths: list[Path], options: dict[str, str]) -> Apply:
        source, target = _read(paths[0], options), _read(paths[1], options)

        def apply(aligner: Aligner) -> tuple[Motion, Motion]:
            aligner.require("retarget")
            return source, aligner.retarget(source, target.skeleton)

        return apply

    return _run("retarget", argv, (2, 2), prepare)


def interpolate(argv: list[str]) -> int:
    """Run ``skelagnostic interpolate`` (``Aligner.interpolate``)."""

    def prepare(paths: list[Path], options: dict[str, str]) -> Apply:
        motion = _read(paths[0], options)
        keys = keyframes_from_options(motion.num_frames, options.get("every"), options.get("keys"))

        def apply(aligner: Aligner) -> tuple[Motion, Motion]:
            aligner.require("interpolate")
            marks["keyframes"] = {0: keys, 1: keys}
            return motion, aligner.interpolate(motion, keys)

        return apply

    marks: dict[str, dict[int, list[int]]] = {}
    return _run("interpolate", argv, (1, 1), prepare, marks)


def transfer(argv: list[str]) -> int:
    """Run ``skelagnostic transfer`` (``Aligner.transfer``)."""

    def prepare(paths: list[Path], options: dict[str, str]) -> Apply:
        source = _read(paths[0], options)
        targets = [_read(p, options) for p in _motion_paths([str(p) for p in paths[1:]])]
        skeletons = {tuple(t.skeleton.joint_names) for t in targets}
        if len(skeletons) > 1:
            raise SkelagnosticError(
                "the target clips are on different skeletons; give clips of one character"
            )

        def apply(aligner: Aligner) -> tuple[Motion, Motion]:
            aligner.require("transfer")
            result = aligner.transfer(source, targets)
            switches = getattr(aligner, "last_transitions", None)
            if switches is not None:
                marks["transitions"] = {1: [int(f) for f in switches]}
            return source, result

        return apply

    marks: dict[str, dict[int, list[int]]] = {}
    return _run("transfer", argv, (2, None), prepare, marks)
