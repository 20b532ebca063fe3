"""Length units of motion data: the known units and a guess from a skeleton's height.

Converting a motion to metres goes through :meth:`Motion.to_metres
<skelagnostic.core.motion.Motion.to_metres>`, which uses :func:`infer_units`
when the unit is not known.
"""

from __future__ import annotations

import math

from skelagnostic.core.skeleton import Skeleton
from skelagnostic.errors import SkelagnosticError

__all__ = ["HUMAN_HEIGHT", "QUADRUPED_HEIGHT", "UNITS", "infer_units", "units_for_height"]

#: Length units and their size in metres (``"cmu"``: the CMU database unit, 1/0.45 inch).
UNITS: dict[str, float] = {
    "m": 1.0,
    "cm": 0.01,
    "mm": 0.001,
    "inch": 0.0254,
    "ft": 0.3048,
    "cmu": 0.0254 / 0.45,
}

#: Standing height (metres) of the person the unit guess assumes.
HUMAN_HEIGHT = 1.7
#: Height (metres) assumed for a character with a tail (a quadruped): the template holds a
#: quadruped's head level, so this is about its shoulder height (0.43 m for the MANN dog).
QUADRUPED_HEIGHT = 0.5


def units_for_height(height: float, reference: float = HUMAN_HEIGHT) -> str:
    """The unit of :data:`UNITS` that brings ``height`` closest (in ratio) to ``reference`` metres.

    Example:
        >>> units_for_height(171.0), units_for_height(60.0, QUADRUPED_HEIGHT)
        ('cm', 'cm')
    """
    return min(UNITS, key=lambda u: abs(math.log(height * UNITS[u] / reference)))


def infer_units(skeleton: Skeleton, units: str | None = None) -> str:
    """The length unit of a human skeleton: ``units`` if given, else a guess from its height.

    The guess is the unit of :data:`UNITS` that makes :meth:`Skeleton.height`
    closest (in ratio) to :data:`HUMAN_HEIGHT`, or :data:`QUADRUPED_HEIGHT`
    for a skeleton with a tail. It is a guess: a child, an unusual animal or a
    rig with a wrong scale gets a wrong one, which is why the data module logs
    the unit and height of every dataset.

    Args:
        skeleton: The skeleton, in the units of its file.
        units: The unit, when known (checked against :data:`UNITS`).

    Raises:
        SkelagnosticError: ``units`` is not a known unit, or the skeleton has no height.

    Example:
        >>> from skelagnostic import procedural
        >>> motion, _ = procedural.generate("biped22", "walk", seconds=1.0)  # in cm
        >>> infer_units(motion.skeleton), infer_units(motion.skeleton.scaled(0.01))
        ('cm', 'm')
    """
    if units is not None:
        if units not in UNITS:
            raise SkelagnosticError(f"units: unknown unit {units!r}; known: {', '.join(UNITS)}")
        return units
    height = skeleton.height()
    if not height > 0:
        raise SkelagnosticError(
            f"cannot infer the length units of {skeleton!r}: its height is 0; give the units"
        )
    reference = QUADRUPED_HEIGHT if "tail" in skeleton.body_groups else HUMAN_HEIGHT
    return units_for_height(height, reference)
