"""glTF 2.0 reading and writing of skeletal motion (``.glb`` and ``.gltf``).

:func:`write_gltf` writes the skeleton as a node hierarchy (one node per joint,
``translation`` = the joint's rest offset, no rest rotation), one animation with
a rotation channel per joint and a translation channel on the root (and on every
joint whose motion carries animated translations), keyed at ``k / fps`` with
``LINEAR`` interpolation, and, by default, a skin with a simple bone mesh so that
a viewer shows a figure. Lengths stay in the motion's own units (glTF viewers
assume metres: call :meth:`Motion.to_metres <skelagnostic.Motion.to_metres>`
first for a life-size figure); the axes are the motion's own (glTF is +Y up).

:func:`read_gltf` reads skeletal animation from any glTF 2.0 file: the skeleton
is the joints of a skin (the skin whose joints the animation moves most), else
the node tree the animation moves; node rest rotations, static uniform scales and
the transforms of the nodes above the skeleton are folded into the motion.

pygltflib (the ``gltf`` extra) loads and builds the container (GLB chunks, data
URIs, the JSON objects); the checks of every field read, accessor decoding,
keyframe evaluation and the folding of node transforms are this module's own.
Every problem raises :class:`~skelagnostic.errors.GLTFError` naming the file and
the glTF field at fault.
"""

from skelagnostic.io.gltf._common import GLTF_SUFFIXES
from skelagnostic.io.gltf.read import read_gltf
from skelagnostic.io.gltf.write import write_gltf

__all__ = ["GLTF_SUFFIXES", "read_gltf", "write_gltf"]
