"""The :class:`Skeleton`: a joint hierarchy with rest offsets and body groups."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np
import torch

from skelagnostic.core.names import counterpart_names, infer_body_groups, is_effector_name
from skelagnostic.core.template import canonical_template
from skelagnostic.errors import SkeletonError

__all__ = ["BODY_GROUPS", "Skeleton"]

#: The body groups a joint can belong to.
BODY_GROUPS: tuple[str, ...] = (
    "spine",
    "left_arm",
    "right_arm",
    "left_leg",
    "right_leg",
    "tail",
    "other",
)

_AXES = {"x": 0, "y": 1, "z": 2}


def _check_hierarchy(names: list[str], parents: list[int]) -> dict[str, int]:
    """Check names and parents (unique names, root 0 only, parents first); name -> index."""
    if not names:
        raise SkeletonError("skeleton has no joints")
    if len(parents) != len(names):
        raise SkeletonError(f"parents has {len(parents)} entries for {len(names)} joint names")
    seen: dict[str, int] = {}
    for j, n in enumerate(names):
        if n in seen:
            raise SkeletonError(f"duplicate joint name {n!r} (joints {seen[n]} and {j})")
        seen[n] = j
    roots = [j for j, p in enumerate(parents) if p < 0]
    if roots != [0]:
        raise SkeletonError(f"the root must be joint 0 and unique; roots found at {roots}")
    for j, p in enumerate(parents):
        if p >= j:
            raise SkeletonError(
                f"joint {names[j]!r} has parent index {p}: parents must come before children"
            )
    return seen


def _as_offsets(
    offsets: torch.Tensor | np.ndarray | Sequence[Sequence[float]], names: list[str]
) -> torch.Tensor:
    """``[J, 3]`` floating-point, finite rest offsets as a tensor (float64 from non-tensors)."""
    off = torch.as_tensor(
        np.asarray(offsets, dtype=np.float64) if not isinstance(offsets, torch.Tensor) else offsets
    )
    if not off.is_floating_point():
        off = off.to(torch.float64)
    if off.shape != (len(names), 3):
        raise SkeletonError(f"offsets must have shape [{len(names)}, 3], got {list(off.shape)}")
    if not torch.isfinite(off).all():
        bad = int((~torch.isfinite(off)).any(-1).nonzero()[0, 0])
        raise SkeletonError(f"offset of joint {names[bad]!r} is not finite")
    return off


def _resolve_morphology(morphology: str | None, groups: Sequence[str]) -> str:
    """``morphology`` checked, or inferred: tail plus both arms and legs is a quadruped."""
    if morphology is None:
        has_all = {"left_arm", "right_arm", "left_leg", "right_leg"} <= set(groups)
        morphology = "quadruped" if has_all and "tail" in groups else "biped"
    if morphology not in {"biped", "quadruped"}:
        raise SkeletonError(f"morphology must be 'biped' or 'quadruped', got {morphology!r}")
    return morphology


class Skeleton:
    """A joint hierarchy with rest offsets.

    Joints are ordered so that every parent comes before its children; the root
    has parent ``-1``. Offsets are the rest-pose translation of each joint from
    its parent, in the parent's frame (the root's offset is its rest position).

    Args:
        joint_names: Unique joint names.
        parents: Parent index per joint.
        offsets: ``[J, 3]`` rest offsets (torch or numpy).
        end_sites: Optional mapping from joint index to the offsets of its BVH
            ``End Site`` children (a list of 3-vectors per joint).
        body_groups: Optional explicit group per joint (a sequence, or a mapping from
            joint name to group for a partial override); inferred otherwise.
        up_axis: ``"x"``, ``"y"`` or ``"z"``; the up direction of the data.
        name: Optional human-readable name (e.g. ``"lafan1"``).
        morphology: ``"biped"`` or ``"quadruped"``; decides the canonical :meth:`template`.
            Inferred when ``None``: a skeleton with a tail and both arms and legs is a
            quadruped.
        channels: Optional per-joint BVH channel names, kept so that
            :func:`~skelagnostic.write_bvh` can reproduce the file's layout. Not part of
            the topology (ignored by ``==`` and ``hash``).
        body_root: The joint (index or name) that is the body's root, when the file
            root is a static *trajectory carrier* above it (see :attr:`body_root`);
            ``None`` means the file root, joint 0.

    Raises:
        SkeletonError: On duplicate names, bad parents, wrong offset shape,
            non-finite offsets or an unknown ``body_root``.
    """

    def __init__(
        self,
        joint_names: Sequence[str],
        parents: Sequence[int],
        offsets: torch.Tensor | np.ndarray | Sequence[Sequence[float]],
        end_sites: Mapping[int, Sequence[Sequence[float]]] | None = None,
        body_groups: Sequence[str] | Mapping[str, str] | None = None,
        up_axis: str = "y",
        name: str | None = None,
        morphology: str | None = None,
        channels: Sequence[Sequence[str]] | None = None,
        body_root: int | str | None = None,
    ) -> None:
        names = [str(n) for n in joint_names]
        parents_l = [int(p) for p in parents]
        self._index = _check_hierarchy(names, parents_l)
        self._names = names
        self._parents = parents_l
        self._offsets = _as_offsets(offsets, names)
        if up_axis not in _AXES:
            raise SkeletonError(f"up_axis must be 'x', 'y' or 'z', got {up_axis!r}")
        self.up_axis = up_axis
        self.name = name
        self.end_sites: dict[int, list[list[float]]] = {
            int(k): [list(map(float, e)) for e in v] for k, v in (end_sites or {}).items()
        }
        self.channels = None if channels is None else [list(c) for c in channels]
        if self.channels is not None and len(self.channels) != len(names):
            raise SkeletonError(
                f"channels has {len(self.channels)} entries for {len(names)} joints"
            )
        self._body_root = 0 if body_root is None else self._body_root_index(body_root)
        self._groups = self._resolve_groups(body_groups)
        self.morphology = _resolve_morphology(morphology, self._groups)

    def _resolve_groups(self, given: Sequence[str] | Mapping[str, str] | None) -> list[str]:
        """The body groups: inferred, then overridden by ``given`` (all, or some by name)."""
        names = self._names
        if given is not None and not isinstance(given, Mapping):
            groups = list(given)  # all given: no inference (unpickling, from_dict)
            if len(groups) != len(names):
                raise SkeletonError(
                    f"body_groups has {len(groups)} entries for {len(names)} joints"
                )
        else:
            groups = list(
                infer_body_groups(
                    names, self._parents, self.rest_offsets(), lateral_axis=self._lateral_axis()
                )
            )
            for jn, g in (given or {}).items():
                groups[self.index(jn)] = g
        for jn, g in zip(names, groups, strict=True):
            if g not in BODY_GROUPS:
                raise SkeletonError(
                    f"body group {g!r} of joint {jn!r} is not one of {', '.join(BODY_GROUPS)}"
                )
        return groups

    # ------------------------------------------------------------------ basics
    @property
    def joint_names(self) -> list[str]:
        """Joint names, in joint order."""
        return list(self._names)

    @property
    def parents(self) -> list[int]:
        """Parent index of each joint (``-1`` for the root)."""
        return list(self._parents)

    @property
    def offsets(self) -> torch.Tensor:
        """``[J, 3]`` rest offsets (float64 unless constructed otherwise)."""
        return self._offsets

    @property
    def num_joints(self) -> int:
        """Number of joints (End Sites not counted)."""
        return len(self._names)

    @property
    def body_groups(self) -> list[str]:
        """Body group of every joint (see :data:`BODY_GROUPS`)."""
        return list(self._groups)

    @property
    def up_index(self) -> int:
        """Index (0, 1, 2) of the up axis."""
        return _AXES[self.up_axis]

    @property
    def body_root(self) -> int:
        """Index of the joint that is the body's root (0 unless the file root is a carrier).

        Some exports (the Bandai-Namco research motion dataset, MotionBuilder
        exports) put a static root node at the origin whose only child, the hips,
        carries the world trajectory in its position channels. That root is a
        *trajectory carrier*, not a body part: the link from it to its child is no
        bone (its OFFSET is wherever the hips stood when the file was exported).
        :func:`~skelagnostic.read_bvh` detects such files and sets ``body_root``
        to the child. Rest geometry (:meth:`rest_offsets`, :meth:`bone_lengths`,
        :meth:`rest_positions` and what derives from them: the template, the
        height, the unit guess) then gives the links from joint 0 down to the body
        root zero length; forward kinematics is unchanged (it uses
        :attr:`offsets`).
        """
        return self._body_root

    def carrier_joints(self) -> list[int]:
        """The trajectory-carrier joints above :attr:`body_root`, root first (else ``[]``).

        Example:
            >>> from skelagnostic import procedural
            >>> motion, _ = procedural.generate("biped22", "walk", 1.0, root_carrier="static")
            >>> motion.skeleton.body_root, motion.skeleton.carrier_joints()
            (1, [0])
        """
        path, j = [], self._body_root
        while self._parents[j] >= 0:
            j = self._parents[j]
            path.append(j)
        return path[::-1]

    def _body_root_index(self, joint: int | str) -> int:
        try:
            return self.index(joint)
        except SkeletonError as exc:
            raise SkeletonError(f"body_root: {exc}") from None

    def _lateral_axis(self) -> int:
        # Canonical BVH convention: Y up, facing +Z, left +X; for Z up, facing +Y... +X left.
        return 0 if self.up_axis in {"y", "z"} else 2

    def index(self, joint: str | int) -> int:
        """Index of a joint given by name (or index, checked).

        Raises:
            SkeletonError: If the joint is unknown; the message lists close names.
        """
        if isinstance(joint, int):
            if not 0 <= joint < self.num_joints:
                raise SkeletonError(f"joint index {joint} out of range [0, {self.num_joints})")
            return joint
        try:
            return self._index[joint]
        except KeyError:
            import difflib

            close = difflib.get_close_matches(joint, self._names, n=3)
            hint = f"; did you mean {', '.join(map(repr, close))}?" if close else ""
            raise SkeletonError(
                f"unknown joint {joint!r} in skeleton {self.name or ''}{hint}".replace(" ;", ";")
            ) from None

    def children(self, joint: str | int) -> list[int]:
        """Indices of the direct children of a joint."""
        j = self.index(joint)
        return [c for c, p in enumerate(self._parents) if p == j]

    def bones(self) -> list[tuple[int, int]]:
        """``(parent, child)`` index pairs, one per non-root joint."""
        return [(p, c) for c, p in enumerate(self._parents) if p >= 0]

    def rest_offsets(self) -> torch.Tensor:
        """``[J, 3]`` offsets of the rest geometry: :attr:`offsets` without the carrier links.

        Equal to :attr:`offsets` except on a skeleton whose :attr:`body_root` is not
        the file root: the offsets of the body root and of the carrier joints
        between it and joint 0 are zero there (the carrier's link to the body is
        the trajectory at export time, not a bone). Joint 0 keeps its offset.
        Joints with animated translations (BVH position channels) use their
        OFFSET here too: bone lengths are the rest pose's, never a frame's.
        """
        if self._body_root == 0:
            return self._offsets
        off = self._offsets.clone()
        off[[*self.carrier_joints()[1:], self._body_root]] = 0.0
        return off

    def limb_starts(self) -> dict[str, int]:
        """The first joint with a bone of every left/right body group (``left_leg`` -> hip).

        Example:
            >>> from skelagnostic import procedural
            >>> sk = procedural.skeleton("biped22")
            >>> sk.joint_names[sk.limb_starts()["left_leg"]]
            'LeftUpLeg'
        """
        lengths = self.bone_lengths()
        starts: dict[str, int] = {}
        for j, group in enumerate(self.body_groups):
            if group not in starts and group.startswith(("left_", "right_")) and lengths[j] > 0:
                starts[group] = j
        return starts

    def bone_lengths(self) -> torch.Tensor:
        """``[J]`` length of the bone ending at each joint in the rest geometry.

        0 for the root and, on a skeleton with a trajectory carrier, for the body
        root and the carrier joints (see :meth:`rest_offsets`).
        """
        lengths = self.rest_offsets().norm(dim=-1).clone()
        lengths[0] = 0.0
        return lengths

    def end_effectors(self) -> list[int]:
        """Joints that end limbs or the spine: hands, feet (toes), head, tail tip.

        A leaf joint (no joint children) of each group, preferring names with
        hand/foot/toe/head words.
        """
        leaves = [j for j in range(self.num_joints) if not self.children(j) and j != 0]
        result = []
        for group in ("spine", "left_arm", "right_arm", "left_leg", "right_leg", "tail"):
            cands = [j for j in leaves if self._groups[j] == group]
            if not cands:
                continue
            named = [j for j in cands if is_effector_name(self._names[j])]
            pick = named or cands
            # the deepest candidate ends the main chain
            result.append(max(pick, key=self.depth))
        return sorted(result)

    def depth(self, joint: str | int) -> int:
        """Number of bones between a joint and the root."""
        j, d = self.index(joint), 0
        while self._parents[j] >= 0:
            j, d = self._parents[j], d + 1
        return d

    def mirror_map(self) -> list[int]:
        """For every joint, the index of its left/right counterpart (itself if none).

        Counterparts are found by swapping side markers in names (``Left``/``Right``,
        ``L``/``R`` prefixes, ``_l``/``_r`` suffixes:
        :func:`~skelagnostic.core.names.counterpart_names`).
        """
        mapping = list(range(self.num_joints))
        for j, n in enumerate(self._names):
            if not self._groups[j].startswith(("left_", "right_")):
                continue
            for cand in counterpart_names(n):
                k = self._index.get(cand)
                if k is not None and k != j:
                    mapping[j] = k
                    break
        return mapping

    # ----------------------------------------------------------- derived forms
    def rest_positions(self) -> torch.Tensor:
        """``[J, 3]`` global joint positions of the file's rest pose (zero rotations).

        Built from :meth:`rest_offsets`: a trajectory carrier and the body root
        share joint 0's position.
        """
        offsets = self.rest_offsets()
        pos = torch.zeros_like(offsets)
        for j, p in enumerate(self._parents):
            pos[j] = offsets[j] if p < 0 else pos[p] + offsets[j]
        return pos

    def template(self) -> torch.Tensor:
        """``[J, 3]`` canonical neutral pose built from the file's own rest geometry.

        The canonical frame is Y up, facing +Z, left +X, root at the origin. Every
        bone keeps its length (:meth:`bone_lengths`); its direction comes from the
        rest offsets (see ``docs/skeleton.md``):

        1. The rest pose is turned into the canonical frame using the body itself:
           for bipeds up is pelvis to head, for quadrupeds forward is pelvis to the
           joint the front legs hang from; left is right hip to left hip (right to
           left upper arm without legs). A rotated rest pose (LaFAN1's, the MANN
           dog's) therefore gives the same template as an upright one.
        2. Torso, neck, head, clavicle and pelvis bones keep their rest directions.
        3. Each limb is rotated as a whole at its upper-arm or hip joint (the parent
           of the joint named as elbow or knee, twist joints skipped) so that the
           upper arm or thigh hangs straight down; the limb's own geometry is kept.
        4. Degenerate rest geometry falls back, per bone, to the length-only
           construction: a clavicle or pelvis bone lying along the body axis points
           sideways (a quadruped's shoulder blade steeply down, forward and
           outward); a toe bone hanging along the leg points forward; a quadruped's
           tail or hip bone pointing forward and up (towards the head) is turned
           half a turn about the lateral axis; a limb without a recognisable elbow
           or knee is rotated at the end of its first non-zero bone.

        Without a body frame (no head, no left/right hips or upper arms, or a
        collinear rest pose) the whole template is the length-only construction
        (:func:`~skelagnostic.core.template.template_from_lengths`). The geometry
        is in :mod:`skelagnostic.core.template`.
        """
        return canonical_template(self)

    def height(self) -> float:
        """Extent of :meth:`template` along the up axis (the character's standing height).

        For quadrupeds this is the shoulder/hip height plus the raised head.
        """
        t = self.template()
        return float(t[:, 1].max() - t[:, 1].min())

    def subset(self, joint_names: Iterable[str]) -> Skeleton:
        """A skeleton with only the given joints (the root must be kept).

        Removed joints are bridged: a kept joint is re-parented to its nearest kept
        ancestor and its offset becomes the sum of the offsets along the removed
        chain (exact when the removed joints have zero rest rotation, which is the
        BVH rest pose). The :attr:`body_root` stays if kept; otherwise the subset's
        body root is its root.

        Raises:
            SkeletonError: On unknown names or when the root is dropped.
        """
        keep = {self.index(n) for n in joint_names}
        if 0 not in keep:
            raise SkeletonError(f"subset must keep the root joint {self._names[0]!r}")
        order = sorted(keep)
        new_index = {j: i for i, j in enumerate(order)}
        parents, offsets = [], []
        for j in order:
            off = self._offsets[j].clone()
            p = self._parents[j]
            while p >= 0 and p not in keep:
                off = off + self._offsets[p]
                p = self._parents[p]
            parents.append(-1 if p < 0 else new_index[p])
            offsets.append(off)
        return Skeleton(
            [self._names[j] for j in order],
            parents,
            torch.stack(offsets),
            end_sites={new_index[j]: v for j, v in self.end_sites.items() if j in keep},
            body_groups=[self._groups[j] for j in order],
            up_axis=self.up_axis,
            name=self.name,
            morphology=self.morphology,
            channels=None if self.channels is None else [self.channels[j] for j in order],
            body_root=new_index.get(self._body_root, 0),
        )

    def rooted_at(self, joint: str | int) -> Skeleton:
        """The subtree under ``joint``, with ``joint`` as its root (offsets kept).

        ``skeleton.rooted_at(skeleton.body_root)`` drops a trajectory carrier. The
        motion counterpart, which keeps the global motion of the kept joints, is
        :func:`skelagnostic.core.motion.reroot`.

        Raises:
            SkeletonError: ``joint`` is unknown.
        """
        new_root = self.index(joint)
        if new_root == 0:
            return self
        keep = [new_root]
        for j in range(new_root + 1, self.num_joints):
            if self._parents[j] in keep:
                keep.append(j)
        index = {j: i for i, j in enumerate(keep)}
        return Skeleton(
            [self._names[j] for j in keep],
            [-1] + [index[self._parents[j]] for j in keep[1:]],
            self._offsets[keep].clone(),
            end_sites={index[j]: v for j, v in self.end_sites.items() if j in index},
            body_groups=[self._groups[j] for j in keep],
            up_axis=self.up_axis,
            name=self.name,
            morphology=self.morphology,
            channels=None if self.channels is None else [self.channels[j] for j in keep],
            body_root=index.get(self._body_root, 0),
        )

    def scaled(self, factor: float) -> Skeleton:
        """The same skeleton with every offset (and end site) multiplied by ``factor``."""
        return Skeleton(
            self._names,
            self._parents,
            self._offsets * factor,
            end_sites={j: [[c * factor for c in e] for e in v] for j, v in self.end_sites.items()},
            body_groups=self._groups,
            up_axis=self.up_axis,
            name=self.name,
            morphology=self.morphology,
            channels=self.channels,
            body_root=self._body_root,
        )

    # --------------------------------------------------------- identity, I/O
    def topology_key(self) -> tuple[tuple[str, ...], tuple[int, ...]]:
        """Names and parents: what ``==`` and ``hash`` compare (offsets excluded)."""
        return tuple(self._names), tuple(self._parents)

    def same_topology(self, other: Skeleton) -> bool:
        """Whether both skeletons have the same joint names and hierarchy."""
        return self.topology_key() == other.topology_key()

    def __eq__(self, other: object) -> bool:
        """Topology equality plus equal offsets (within 1e-6 relative)."""
        if not isinstance(other, Skeleton):
            return NotImplemented
        return self.same_topology(other) and torch.allclose(
            self._offsets.double(), other._offsets.double(), rtol=1e-6, atol=1e-9
        )

    def __hash__(self) -> int:
        return hash(self.topology_key())

    def __repr__(self) -> str:
        label = f" {self.name!r}" if self.name else ""
        return (
            f"Skeleton{label}({self.num_joints} joints, root {self._names[0]!r}, {self.morphology})"
        )

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serialisable description (see :meth:`from_dict`)."""
        return {
            "joint_names": self._names,
            "parents": self._parents,
            "offsets": self._offsets.tolist(),
            "end_sites": {str(k): v for k, v in self.end_sites.items()},
            "body_groups": self._groups,
            "up_axis": self.up_axis,
            "name": self.name,
            "morphology": self.morphology,
            "channels": self.channels,
            "body_root": self._body_root,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Skeleton:
        """Rebuild a skeleton from :meth:`to_dict` output."""
        try:
            return cls(
                data["joint_names"],
                data["parents"],
                data["offsets"],
                end_sites={int(k): v for k, v in (data.get("end_sites") or {}).items()},
                body_groups=data.get("body_groups"),
                up_axis=data.get("up_axis", "y"),
                name=data.get("name"),
                morphology=data.get("morphology"),
                channels=data.get("channels"),
                body_root=data.get("body_root"),
            )
        except KeyError as exc:
            raise SkeletonError(f"skeleton description lacks the field {exc.args[0]!r}") from None

    def __getstate__(self) -> dict[str, Any]:
        return self.to_dict()

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(Skeleton.from_dict(state).__dict__)
