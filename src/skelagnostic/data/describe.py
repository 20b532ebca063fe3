"""The log line that describes a dataset: clips per split, joints, height and unit, file axes."""

from __future__ import annotations

from collections.abc import Sequence

from skelagnostic.core.skeleton import Skeleton
from skelagnostic.core.units import infer_units
from skelagnostic.data.cache import CacheEntry
from skelagnostic.data.sources import ClipRef

__all__ = ["describe_axes", "describe_dataset"]


def describe_dataset(
    name: str, members: Sequence[tuple[ClipRef, CacheEntry]], assigned: dict[str, str]
) -> str:
    """One log line on a dataset: clips per split, joints, standing height and its unit, axes.

    The unit is what a wrong ``data.units`` (or a wrong guess) would show
    first: a person 171 m tall, or a dog of 0.6 m logged as centimetres. The
    files' axes (``data.up``, ``data.forward``) follow, with those that
    ``"auto"`` detected marked, and a count per frame when the clips differ.
    """
    meta = members[0][1].meta
    skeleton = Skeleton.from_dict(meta["skeleton"])
    height = skeleton.height()
    units = meta.get("units", "?")
    if units == "?":  # an entry cached before units were recorded
        size = f"height {height:.3g}"
    elif units == "m":
        size = f"height {height:.2f} m"
    elif units is not None:
        size = f"height {height:.3g} {units}"
    else:
        size = (
            f"height {height:.3g} in the files' unit (not converted; data.units or a "
            f"data.paths entry's units: sets it; the height suggests {infer_units(skeleton)})"
        )
    parts = [assigned.get(clip.id) for clip, _ in members]
    order = ("train", "val", "test")
    splits = ", ".join(f"{part} {parts.count(part)}" for part in order if part in parts)
    return (
        f"data: dataset {name!r}: {len(members)} clip(s) ({splits}), "
        f"{skeleton.num_joints} joints, {size}{describe_axes(members)}"
    )


def describe_axes(members: Sequence[tuple[ClipRef, CacheEntry]]) -> str:
    """``", file axes up z, forward -y (detected)"``: the axes the clips were read with."""
    counts: dict[str, int] = {}
    for _, entry in members:
        axes = entry.meta.get("axes")
        if not isinstance(axes, dict):
            continue
        detected = axes.get("detected") or []
        text = f"up {axes.get('up')}, forward {axes.get('forward')}"
        text += f" ({' and '.join(detected)} detected)" if detected else ""
        counts[text] = counts.get(text, 0) + 1
    if len(counts) <= 1:
        return "".join(f", file axes {text}" for text in counts)
    return ", file axes " + "; ".join(f"{text}: {n} clip(s)" for text, n in counts.items())
