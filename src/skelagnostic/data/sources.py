"""Clip sources: where motion clips come from (BVH directories, presets, the procedural generator).

A :class:`ClipSource` lists its clips cheaply (:meth:`ClipSource.clips`, with a
content key per clip used by the window cache) and loads one on demand
(:meth:`ClipSource.load`). Sources are small picklable objects, safe to send to
DDP ranks and data-loader workers. Motions with known units are converted to
metres (:meth:`Motion.to_metres <skelagnostic.core.motion.Motion.to_metres>`).

Two sources wrap others: :class:`MultiSource` bundles several sources under
one argument (a data module makes one dataset per part) and
:class:`MetresSource` brings every clip to metres, guessing the unit of clips
that do not know theirs.
"""

from __future__ import annotations

import hashlib
import os
import re
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from skelagnostic.core.axes import AxesError, axes_matrix, parse_axis, to_canonical
from skelagnostic.core.motion import UNITS, Motion, reroot
from skelagnostic.core.paths import expand_path
from skelagnostic.errors import SkelagnosticError

__all__ = [
    "DATA_ROOT_ENV",
    "MANN_DOG_TEST",
    "PRESETS",
    "Archive",
    "BVHSource",
    "ClipRef",
    "ClipSource",
    "DatasetPreset",
    "MetresSource",
    "MultiSource",
    "ProceduralSource",
    "bvh_sources",
    "dataset_root",
    "flatten_sources",
    "preset_source",
]


@dataclass(frozen=True)
class ClipRef:
    """One clip of a source.

    Attributes:
        id: Identifier, unique and stable within the source (e.g. a relative path).
        key: Hash of the clip's content; cached windows are keyed by it.
        split: ``"test"`` to force the clip into the test split, else ``None``.
    """

    id: str
    key: str
    split: str | None = None


class ClipSource(ABC):
    """A collection of motion clips.

    Attributes:
        name: Label of the source; data-module dataset names start with it.
    """

    name: str

    @abstractmethod
    def clips(self) -> list[ClipRef]:
        """The clips, in a deterministic order."""

    @abstractmethod
    def load(self, clip: ClipRef) -> Motion:
        """Read one clip."""

    def loading(self) -> dict[str, Any]:
        """The options that change what :meth:`load` returns for the same file.

        They are part of the window cache's key, so changing them (the units
        of ``data=bvh``, a re-rooting) never reuses windows built with other
        values. The default: none.
        """
        return {}

    def axes(self, clip: ClipRef) -> dict[str, Any] | None:
        """The file axes the last :meth:`load` of ``clip`` found, for the dataset's log line.

        ``{"up": ..., "forward": ..., "detected": [...]}`` (the names of the axes
        that ``"auto"`` detected), or ``None`` (the default: a source without file
        axes, such as the procedural generator).
        """
        return None


def _to_metres(motion: Motion, units: str | None) -> Motion:
    """``motion`` in metres when its unit is known (``units`` or ``motion.units``), else as is."""
    if (units or motion.units) is None:
        return motion
    return motion.to_metres(units)


@dataclass
class MultiSource(ClipSource):
    """Several clip sources given as one, e.g. the human and dog parts of ``data.source=human_dog``.

    :class:`~skelagnostic.data.MotionDataModule` unpacks it: every part is a
    source of its own and names its datasets. Used directly, its clip ids are
    the part's ids prefixed by the part's name (``"dog:run1.bvh"``).

    Args:
        parts: The sources; their ``name`` labels the datasets.
        name: Label of the bundle.

    Raises:
        SkelagnosticError: ``parts`` is empty or two parts share a name.

    Example:
        >>> a = ProceduralSource(kinds=["biped22"], gaits=["walk"], clips_per_gait=1, name="a")
        >>> b = ProceduralSource(kinds=["quadruped"], gaits=["trot"], clips_per_gait=1, name="b")
        >>> print(*(clip.id for clip in MultiSource([a, b]).clips()))
        a:biped22_walk_0 b:quadruped_trot_0
    """

    parts: Sequence[ClipSource]
    name: str = "multi"

    def __post_init__(self) -> None:
        self.parts = list(self.parts)
        names = [p.name for p in self.parts]
        if not names:
            raise SkelagnosticError("MultiSource: parts must hold at least one source")
        if len(set(names)) != len(names):
            raise SkelagnosticError(f"MultiSource: part names must differ, got {names}")

    def clips(self) -> list[ClipRef]:
        """Clips of every part, ids prefixed by the part name."""
        return [ClipRef(f"{p.name}:{c.id}", c.key, c.split) for p in self.parts for c in p.clips()]

    def load(self, clip: ClipRef) -> Motion:
        """Load a clip from its part.

        Raises:
            SkelagnosticError: The id names no part.
        """
        part, _, inner = clip.id.partition(":")
        for source in self.parts:
            if source.name == part:
                return source.load(ClipRef(inner, clip.key, clip.split))
        raise SkelagnosticError(
            f"MultiSource {self.name!r}: clip {clip.id!r} names no part "
            f"(parts: {', '.join(p.name for p in self.parts)})"
        )

    def loading(self) -> dict[str, Any]:
        """The loading options of every part, by part name."""
        return {p.name: p.loading() for p in self.parts}

    def axes(self, clip: ClipRef) -> dict[str, Any] | None:
        """The file axes its part found for ``clip``."""
        part, _, inner = clip.id.partition(":")
        found = [p.axes(ClipRef(inner, clip.key, clip.split)) for p in self.parts if p.name == part]
        return found[0] if found else None


class MetresSource(ClipSource):
    """Wraps a clip source so that every clip comes in metres.

    Each clip goes through :meth:`Motion.to_metres
    <skelagnostic.core.motion.Motion.to_metres>`: clips that know their unit
    (``motion.units``) are converted from it, the others from ``units``, or
    from the unit guessed from their skeleton height when ``units`` is ``None``.

    Args:
        inner: The wrapped source (its ``name`` is kept).
        units: Unit of the clips that do not know theirs (``None``: guess).
    """

    def __init__(self, inner: ClipSource, units: str | None = None) -> None:
        self.inner = inner
        self.units = units
        self.name = inner.name

    def clips(self) -> list[ClipRef]:
        """The inner source's clips."""
        return self.inner.clips()

    def load(self, clip: ClipRef) -> Motion:
        """The clip in metres."""
        motion = self.inner.load(clip)
        return motion.to_metres(motion.units or self.units)

    def loading(self) -> dict[str, Any]:
        """The inner source's loading options plus the fallback unit."""
        return {**self.inner.loading(), "metres": True, "fallback_units": self.units}

    def axes(self, clip: ClipRef) -> dict[str, Any] | None:
        """The inner source's file axes of ``clip``."""
        return self.inner.axes(clip)


def flatten_sources(sources: ClipSource | Sequence[ClipSource] | None) -> list[ClipSource]:
    """``sources`` as a list, every :class:`MultiSource` replaced by its parts."""
    if sources is None:
        return []
    listed = [sources] if isinstance(sources, ClipSource) else list(sources)
    return [part for s in listed for part in (s.parts if isinstance(s, MultiSource) else [s])]


def file_sha256(path: Path, step: Callable[[int], None] | None = None) -> str:
    """Hex SHA-256 of the file at ``path``, read in blocks (``step`` gets the bytes of each)."""
    digest = hashlib.sha256()
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
            if step is not None:
                step(len(block))
    return digest.hexdigest()


@dataclass
class BVHSource(ClipSource):
    """BVH files from files or directories.

    Args:
        paths: Files or directories (searched with ``pattern``).
        pattern: Glob for directories, e.g. ``"**/*.bvh"``.
        test_pattern: Regular expression; clips whose path matches go to the test split.
        units: Length unit of the files (a key of :data:`~skelagnostic.core.UNITS`);
            the clips are converted to metres. ``None`` keeps the file's units.
        root_joint: Re-root every clip at this joint (see
            :func:`~skelagnostic.core.motion.reroot`). ``None``:
            a file whose root is a static trajectory carrier (detected by
            :func:`~skelagnostic.read_bvh`, see :attr:`Skeleton.body_root
            <skelagnostic.Skeleton.body_root>`) is re-rooted at its body root, any
            other file is kept as it is; give the file root's name to keep a carrier.
        name: Label of the source.
        up: The files' up axis (``x, y, z, -x, -y, -z``) or ``"auto"`` (detected per
            clip, see :mod:`skelagnostic.core.axes`); every clip is turned into the
            canonical frame (+Y up, facing +Z). ``None``: ``"y"``.
        forward: The files' forward axis, ``"auto"``, or ``None`` (the usual one
            for ``up``: ``"-y"`` for Blender's Z up).

    Raises:
        SkelagnosticError: A path does not exist, the units are unknown, an axis is
            not one, or no file matches.
    """

    paths: Sequence[str | Path]
    pattern: str = "**/*.bvh"
    test_pattern: str | None = None
    units: str | None = None
    root_joint: str | None = None
    name: str = "bvh"
    up: str | None = None
    forward: str | None = None
    _files: list[Path] = field(default_factory=list, init=False, repr=False)
    _axes: dict[str, dict[str, Any]] = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        if isinstance(self.paths, (str, Path)):
            self.paths = [self.paths]
        if self.up is not None:
            self.up = parse_axis(self.up, "data.up", auto=True)
        if self.forward is not None:
            self.forward = parse_axis(self.forward, "data.forward", auto=True)
        if self.up not in (None, "auto") and self.forward not in (None, "auto"):
            try:
                axes_matrix(self.up, self.forward)
            except AxesError as exc:
                raise AxesError(f"data.up, data.forward: {exc}") from None
        if self.units is not None and self.units not in UNITS:
            raise SkelagnosticError(
                f"data.units: unknown unit {self.units!r}; known: {', '.join(UNITS)}"
            )
        files: list[Path] = []
        for raw in self.paths:
            path = expand_path(raw)
            if path.is_file():
                files.append(path.resolve())
            elif path.is_dir():
                files.extend(sorted(p.resolve() for p in path.glob(self.pattern) if p.is_file()))
            else:
                raise SkelagnosticError(f"data.paths: {str(path)!r} does not exist")
        if not files:
            raise SkelagnosticError(
                f"data.paths: no file matches {self.pattern!r} in {[str(p) for p in self.paths]}"
            )
        self._files = list(dict.fromkeys(files))

    def clips(self) -> list[ClipRef]:
        """One clip per file, keyed by the file's SHA-256."""
        test = re.compile(self.test_pattern) if self.test_pattern else None
        return [
            ClipRef(
                str(path), file_sha256(path), "test" if test and test.search(str(path)) else None
            )
            for path in self._files
        ]

    def loading(self) -> dict[str, Any]:
        """``units``, ``root_joint``, the carrier rule and the axes: they change the motion."""
        options = {"units": self.units, "root_joint": self.root_joint, "carrier": "body_root"}
        if (self.up, self.forward) != (None, None):  # keeps the keys of earlier caches
            options.update(up=self.up, forward=self.forward)
        return options

    def load(self, clip: ClipRef) -> Motion:
        """Read the BVH file of ``clip`` in the canonical frame (re-rooted, see ``root_joint``)."""
        from skelagnostic.io.bvh import read_bvh

        motion, found = to_canonical(
            read_bvh(clip.id), self.up, self.forward, prefix="data.", where=clip.id
        )
        self._axes[clip.id] = {
            "up": found.up,
            "forward": found.forward,
            "detected": [name for name, how in found.how if how.startswith("detected")],
        }
        root = self.root_joint if self.root_joint is not None else motion.skeleton.body_root
        return _to_metres(reroot(motion, root), self.units)

    def axes(self, clip: ClipRef) -> dict[str, Any] | None:
        """The axes the last load of ``clip`` found (``None`` before one)."""
        return self._axes.get(clip.id)


#: Keys of a mapping entry of ``data.paths`` (besides ``path``/``paths``).
_ENTRY_KEYS = ("units", "name", "pattern", "test_pattern", "root_joint", "up", "forward")


def bvh_sources(
    paths: Sequence[str | Path | Mapping[str, Any]],
    pattern: str = "**/*.bvh",
    test_pattern: str | None = None,
    units: str | None = None,
    root_joint: str | None = None,
    name: str = "bvh",
    up: str | None = None,
    forward: str | None = None,
) -> list[BVHSource]:
    """The sources of ``data=bvh``: plain paths share the options, mappings bring their own.

    A mapping entry such as ``{path: ~/mocap/dog, units: cm, name: dog}`` is a
    source of its own, so characters recorded in different units (and named
    apart in the logs and metrics) train together::

        data.paths=[{path: ~/cmu, units: cmu, name: human}, {path: ~/dog, units: cm, name: dog}]

    Its keys are ``path`` (or ``paths``, a list) and any of ``units``,
    ``name``, ``pattern``, ``test_pattern``, ``root_joint``, ``up``,
    ``forward`` (a Blender export among Y-up files: ``{path: ~/blender, up: z}``);
    what it leaves out comes from the top-level options. Plain entries form one source with the
    top-level options.

    Raises:
        SkelagnosticError: An entry without a path, with an unknown key, or any
            error of :class:`BVHSource` (the message names ``data.paths[i]``).
    """
    if isinstance(paths, (str, Path, Mapping)):
        paths = [paths]
    defaults = {
        "units": units,
        "name": name,
        "pattern": pattern,
        "test_pattern": test_pattern,
        "root_joint": root_joint,
        "up": up,
        "forward": forward,
    }
    plain = [p for p in paths if not isinstance(p, Mapping)]
    sources = [BVHSource(plain, **defaults)] if plain else []
    for i, entry in enumerate(paths):
        if not isinstance(entry, Mapping):
            continue
        where = f"data.paths[{i}]"
        unknown = sorted(set(entry) - {"path", "paths", *_ENTRY_KEYS})
        if unknown:
            raise SkelagnosticError(
                f"{where}.{unknown[0]} is not an option of a path entry; "
                f"accepted: path, paths, {', '.join(_ENTRY_KEYS)}"
            )
        entry_paths = entry.get("paths", entry.get("path"))
        if not entry_paths:
            raise SkelagnosticError(f"{where}: give the entry a 'path' (or 'paths')")
        options = {**defaults, **{k: entry[k] for k in _ENTRY_KEYS if k in entry}}
        if "name" not in entry:
            options["name"] = f"{name}{i}"
        try:
            sources.append(BVHSource(entry_paths, **options))
        except SkelagnosticError as exc:
            raise SkelagnosticError(f"{where}: {exc}") from exc
    return sources


@dataclass
class ProceduralSource(ClipSource):
    """Clips of :func:`skelagnostic.procedural.dataset` (no files needed).

    Args:
        kinds: Skeleton kinds (see ``skelagnostic.procedural.KINDS``).
        gaits: Gaits; ``None`` plays every gait of each kind except ``idle``.
        clips_per_gait: Clips per (kind, gait).
        seconds: Duration of each clip.
        seed: Base seed.
        name: Label of the source.
        test_clips_per_gait: Further clips per (kind, gait), with seeds of their own
            (after those of the other clips), marked as test clips: a test split that
            leaves the training and validation clips as they are.
    """

    kinds: Sequence[str] = ("biped22", "quadruped")
    gaits: Sequence[str] | None = None
    clips_per_gait: int = 2
    seconds: float = 4.0
    seed: int = 0
    name: str = "procedural"
    test_clips_per_gait: int = 0
    _motions: dict[str, Motion] = field(default_factory=dict, init=False, repr=False)
    _test_ids: set[str] = field(default_factory=set, init=False, repr=False)

    def __post_init__(self) -> None:
        if isinstance(self.test_clips_per_gait, bool) or self.test_clips_per_gait < 0:
            raise SkelagnosticError(
                f"data.test_clips_per_gait={self.test_clips_per_gait!r} must be 0 or more"
            )

    def _generate(self) -> dict[str, Motion]:
        from skelagnostic import procedural

        if not self._motions:
            gaits = self.gaits
            if gaits is None:
                gaits = sorted({g for table in procedural.GAITS.values() for g in table} - {"idle"})
            clips = procedural.dataset(
                tuple(self.kinds), tuple(gaits), self.clips_per_gait, self.seconds, seed=self.seed
            )
            if not clips:
                raise SkelagnosticError(
                    f"data: the procedural kinds {list(self.kinds)} have none of the gaits "
                    f"{list(gaits)}"
                )
            held_out = (
                procedural.dataset(
                    tuple(self.kinds),
                    tuple(gaits),
                    self.test_clips_per_gait,
                    self.seconds,
                    seed=self.seed + len(clips),  # seeds no other clip of the source has
                )
                if self.test_clips_per_gait
                else []
            )
            for (motion, info), test in [
                *((c, False) for c in clips),
                *((c, True) for c in held_out),
            ]:
                clip_id = f"{info['kind']}_{info['gait']}_{info['seed']}"
                self._motions[clip_id] = motion
                if test:
                    self._test_ids.add(clip_id)
        return self._motions

    def clips(self) -> list[ClipRef]:
        """The generated clips, keyed by a hash of their content (test clips marked)."""
        out = []
        for clip_id, motion in self._generate().items():
            digest = hashlib.sha256(clip_id.encode())
            for tensor in (motion.skeleton.offsets, motion.rotations, motion.root_positions):
                digest.update(tensor.detach().to(torch.float64).contiguous().numpy().tobytes())
            split = "test" if clip_id in self._test_ids else None
            out.append(ClipRef(clip_id, digest.hexdigest(), split))
        return out

    def load(self, clip: ClipRef) -> Motion:
        """The generated motion of ``clip``, in metres."""
        return _to_metres(self._generate()[clip.id], None)

    def __getstate__(self) -> dict[str, object]:
        state = dict(self.__dict__)
        state["_motions"] = {}  # regenerated on demand; keeps pickles small
        state["_test_ids"] = set()
        return state


#: Environment variable naming the folder that holds the dataset folders (``lafan1/``, ...).
DATA_ROOT_ENV = "SKELAGNOSTIC_DATA"


@dataclass(frozen=True)
class Archive:
    """A public archive of a dataset: where to download it and its checksum.

    ``skelagnostic data get`` downloads ``url`` and ``skelagnostic data prepare``
    refuses an archive whose SHA-256 is not ``sha256``.

    Attributes:
        url: Download address of the zip file.
        sha256: Hex SHA-256 of the whole file.
        size: Size in bytes (shown before a download; ``None``: unknown).
        source: Where the URL and checksum come from (a repository file, a page).
    """

    url: str
    sha256: str
    size: int | None = None
    source: str = ""

    def __post_init__(self) -> None:
        if not re.fullmatch(r"[0-9a-f]{64}", self.sha256):
            raise SkelagnosticError(
                f"archive {self.url}: sha256 must be 64 lowercase hex digits, got {self.sha256!r}"
            )


@dataclass(frozen=True)
class DatasetPreset:
    """Known layout of a public dataset: file pattern, units, test split, root fix.

    Attributes:
        name: Preset name (``data=<name>``).
        description: One line.
        units: Length unit of the files.
        pattern: Glob below the dataset root.
        test_pattern: Regular expression selecting the test clips by path, if the
            dataset defines a test split.
        test_clips: File names (without ``.bvh``) of a fixed held-out list; joined
            with ``test_pattern`` when both are given.
        root_joint: Joint to re-root at (rigs whose file root is a fixed helper).
        directory: Folder of the dataset below ``$SKELAGNOSTIC_DATA`` (default: ``name``).
        archive: The public archive ``skelagnostic data get`` downloads, if one with a
            fixed layout and a published checksum is known.
    """

    name: str
    description: str
    units: str
    pattern: str = "**/*.bvh"
    test_pattern: str | None = None
    test_clips: tuple[str, ...] = ()
    root_joint: str | None = None
    directory: str | None = None
    archive: Archive | None = None

    @property
    def folder(self) -> str:
        """The dataset's folder name below ``$SKELAGNOSTIC_DATA`` (``directory`` or ``name``)."""
        return self.directory or self.name

    @property
    def split_pattern(self) -> str | None:
        """The regular expression of the test split (``test_pattern`` or ``test_clips``)."""
        parts = [self.test_pattern] if self.test_pattern else []
        if self.test_clips:
            names = "|".join(re.escape(n) for n in self.test_clips)
            parts.append(rf"(^|[\\/])({names})\.bvh$")
        return "|".join(f"(?:{p})" for p in parts) if parts else None


#: MANN dog clips held out of training (``data=mann_dog``'s test split). Chosen once by
#: the median root speed of each clip (``../shared/datasets/README.md``) to cover the
#: dog's gaits: idle, a slow mixed clip, walk, trot and canter (docs/data.md).
MANN_DOG_TEST = (
    "D1_004_KAN01_001",  # idle, 0.01 m/s
    "D1_053_KAN01_002",  # slow, mixed standing and walking, 0.30 m/s
    "D1_008_KAN01_001",  # walk, 0.84 m/s
    "D1_ex04_KAN02_002",  # trot, 1.31 m/s
    "D1_010_KAN01_003",  # canter, 3.13 m/s
)

#: LaFAN1's public archive: ``lafan1/lafan1.zip`` of ubisoft/ubisoft-laforge-animation-dataset,
#: stored with Git LFS; the checksum and size are those of the file's LFS pointer (commit
#: 610f0658, unchanged on the default branch since). The BVH files sit at the top of the zip.
LAFAN1_ARCHIVE = Archive(
    url="https://media.githubusercontent.com/media/ubisoft/ubisoft-laforge-animation-dataset/"
    "610f0658a561c7ef208c396f5d3439844bd3459b/lafan1/lafan1.zip",
    sha256="ea918082b500a5d158e9d3aa39039df04cd42e25f5c02fe8f7e88e8e9365a977",
    size=144051503,
    source="Git LFS pointer of lafan1/lafan1.zip in ubisoft/ubisoft-laforge-animation-dataset",
)

#: Presets of the datasets users have (see METHODS.md "Datasets").
PRESETS: dict[str, DatasetPreset] = {
    p.name: p
    for p in (
        DatasetPreset(
            "lafan1",
            "Ubisoft LaFAN1: 22 joints, 30 fps, cm; subject 5 is the test set",
            "cm",
            test_pattern=r"_subject5\.bvh$",
            archive=LAFAN1_ARCHIVE,
        ),
        DatasetPreset("cmu", "CMU mocap (BVH conversions): 31 joints, 120 fps, CMU units", "cmu"),
        DatasetPreset(
            "mann_dog",
            "MANN dog: 21 joints, 60 fps, cm, human-style joint names; 5 fixed test clips "
            "(idle to canter)",
            "cm",
            test_clips=MANN_DOG_TEST,
        ),
        DatasetPreset(
            "bandai",
            "Bandai-Namco: joint_Root fixed at the origin, Hips carry the "
            "translation (re-rooted at Hips)",
            "cm",
            root_joint="Hips",
        ),
    )
}


def dataset_root(preset: str, root: str | Path | None = None) -> Path:
    """The folder of a dataset preset: ``root``, else ``$SKELAGNOSTIC_DATA/<directory>``.

    Raises:
        SkelagnosticError: ``root`` is ``None`` and ``$SKELAGNOSTIC_DATA`` is not set.
    """
    if root is not None and str(root) not in ("", "???"):
        return expand_path(root)
    directory = PRESETS[preset].folder if preset in PRESETS else preset
    base = os.environ.get(DATA_ROOT_ENV)
    if not base:
        raise SkelagnosticError(
            f"data.root is not set for the {preset!r} files: pass data.root=DIR, or set "
            f"{DATA_ROOT_ENV}=DIR to a folder holding {directory}/ (docs/data.md)"
        )
    return expand_path(base) / directory


def preset_source(
    preset: str,
    root: str | Path | None = None,
    up: str | None = None,
    forward: str | None = None,
) -> BVHSource:
    """The :class:`BVHSource` of a dataset preset below ``root``.

    Args:
        preset: A key of :data:`PRESETS`.
        root: Folder of the files; ``None``: ``$SKELAGNOSTIC_DATA/<preset>``.
        up: The files' up axis or ``"auto"`` (``None``: ``"y"``, as every preset's).
        forward: The files' forward axis or ``"auto"`` (``None``: the usual one).

    Raises:
        SkelagnosticError: Unknown preset, no root, or ``root`` missing or without
            matching files.
    """
    if preset not in PRESETS:
        raise SkelagnosticError(f"unknown dataset preset {preset!r}; known: {', '.join(PRESETS)}")
    p = PRESETS[preset]
    return BVHSource(
        [dataset_root(preset, root)],
        p.pattern,
        p.split_pattern,
        p.units,
        p.root_joint,
        name=p.name,
        up=up,
        forward=forward,
    )
