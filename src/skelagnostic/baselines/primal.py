"""A retargeting baseline that pairs joints through the skeletons' primal graphs.

Aberman et al. (Skeleton-Aware Networks, SIGGRAPH 2020), which PC-MRL compares
with, reduce homeomorphic skeletons to a common *primal skeleton* by merging
chains of joints that have exactly one child. This module keeps that
reduction and replaces their learned networks by a direct copy, which makes a
baseline that needs no joint names:

1. :func:`primal_skeleton`: the primal joints of a skeleton are its root, its
   leaves and its branching joints (not exactly one child); every other joint
   lies on the *chain* that ends at the next primal joint below it.
2. :func:`primal_match`: the two primal trees are aligned from the roots down;
   the primal children of two matched joints are paired within the same body
   group (:attr:`~skelagnostic.core.skeleton.Skeleton.body_groups`), the ones
   with the most primal joints below them first; a subtree without a partner is
   left unmatched.
3. :func:`primal_copy`: every joint of a matched target chain takes the
   *global* rotation of the source chain joint at the same relative position
   along its chain (chains of different lengths are resampled by rank), so a
   chain bends like its source; joints without a match keep their parent's
   global rotation (identity local rotation). The root trajectory follows
   :func:`~skelagnostic.baselines.names.scaled_root`, as for every copy (or, with
   ``root="source"``, is the source's own root path).

Like the name copy it assumes both rigs share their rest-pose convention and
world axes.
"""

from __future__ import annotations

from skelagnostic.baselines.names import copied_motion
from skelagnostic.core import quaternion as Q
from skelagnostic.core.motion import Motion
from skelagnostic.core.skeleton import Skeleton

__all__ = ["primal_copy", "primal_match", "primal_skeleton"]


def primal_skeleton(skeleton: Skeleton) -> dict[int, list[int]]:
    """The primal joints and their chains.

    Args:
        skeleton: The skeleton.

    Returns:
        ``primal joint -> chain``: the joints from just below its primal parent down
        to the primal joint itself (root first). The root's chain is ``[0]``.

    Example:
        >>> from skelagnostic import procedural
        >>> sk = procedural.skeleton("biped22")
        >>> chains = primal_skeleton(sk)
        >>> all(chain[-1] == p for p, chain in chains.items())
        True
    """
    children = [skeleton.children(j) for j in range(skeleton.num_joints)]
    primal = [j for j in range(skeleton.num_joints) if j == 0 or len(children[j]) != 1]
    chains: dict[int, list[int]] = {}
    for p in primal:
        chain = [p]
        j = skeleton.parents[p]
        while j > 0 and len(children[j]) == 1:
            chain.insert(0, j)
            j = skeleton.parents[j]
        chains[p] = chain
    return chains


def _primal_children(skeleton: Skeleton, chains: dict[int, list[int]]) -> dict[int, list[int]]:
    out: dict[int, list[int]] = {p: [] for p in chains}
    for p, chain in chains.items():
        if p:
            out[skeleton.parents[chain[0]]].append(p)
    return out


def _size(node: int, kids: dict[int, list[int]]) -> int:
    return 1 + sum(_size(k, kids) for k in kids[node])


def primal_match(source: Skeleton, target: Skeleton) -> dict[int, int]:
    """``target primal joint -> source primal joint`` (see the module's rule).

    Args:
        source: Skeleton copied from.
        target: Skeleton copied to.

    Returns:
        The matched primal joints; the roots always match.
    """
    src_chains, dst_chains = primal_skeleton(source), primal_skeleton(target)
    src_kids = _primal_children(source, src_chains)
    dst_kids = _primal_children(target, dst_chains)
    match = {0: 0}
    todo = [(0, 0)]
    while todo:
        t, s = todo.pop()
        free = sorted(src_kids[s], key=lambda k: (-_size(k, src_kids), k))
        for tk in sorted(dst_kids[t], key=lambda k: (-_size(k, dst_kids), k)):
            group = target.body_groups[tk]
            sk = next((k for k in free if source.body_groups[k] == group), None)
            if sk is None:
                continue
            free.remove(sk)
            match[tk] = sk
            todo.append((tk, sk))
    return match


def primal_copy(
    motion: Motion,
    target: Skeleton,
    source_units: str | None = None,
    target_units: str | None = None,
    root: str = "scaled",
) -> Motion:
    """Retarget by copying global rotations along matched primal chains.

    Args:
        motion: Source motion.
        target: Target skeleton.
        source_units: Units of ``motion`` (default: ``motion.units``, else guessed).
        target_units: Units of ``target`` (default: guessed).
        root: ``"scaled"`` (:func:`~skelagnostic.baselines.scaled_root`, default) or
            ``"source"`` (the source's root path unscaled); see
            :func:`~skelagnostic.baselines.names.copied_motion`.

    Returns:
        A motion on ``target`` at the source's fps, in the target's units.

    Raises:
        MotionError: ``root`` is not ``"scaled"`` or ``"source"``.
    """
    src_chains, dst_chains = primal_skeleton(motion.skeleton), primal_skeleton(target)
    donor: dict[int, int] = {}
    for t, s in primal_match(motion.skeleton, target).items():
        t_chain, s_chain = dst_chains[t], src_chains[s]
        for k, j in enumerate(t_chain):
            # rank k of n -> rank round((k + 1) * m / n) - 1 of m, so both ends match
            donor[j] = s_chain[max(0, round((k + 1) * len(s_chain) / len(t_chain)) - 1)]
    src_global = motion.global_rotations()
    frames = motion.num_frames
    glob = Q.identity(frames, target.num_joints, dtype=src_global.dtype)
    local = Q.identity(frames, target.num_joints, dtype=src_global.dtype)
    for j, p in enumerate(target.parents):
        if j in donor:
            glob[:, j] = src_global[:, donor[j]]
            local[:, j] = glob[:, j] if p < 0 else Q.mul(Q.inv(glob[:, p]), glob[:, j])
        elif p >= 0:
            glob[:, j] = glob[:, p]
    return copied_motion(motion, target, local, source_units, target_units, root)
