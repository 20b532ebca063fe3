"""PC-MRL stage 2: the CITL-style keyframe interpolation transformer (Sec. 3.4).

The model fills the frames between keyframes of a motion on the *target*
skeleton. It follows CITL (Mo et al., CVPR 2023) with PC-MRL's changes:

* per-joint input (keyframes only, zeros and a 0 key flag on the other frames):
  the joint's global position minus the mean of the keyframe positions, the unit
  rest bone direction (:func:`~skelagnostic_pcmrl.rpa.bone_tails`) rotated by the
  joint's first-frame global rotation, and its first-frame offset quaternion
  (FOQ, Sec. 3.3, :class:`~skelagnostic.representations.FirstFrameOffsetQuaternions`);
* an encoder whose self-attention only reads keyframes, an intermediate-token
  module (zero tokens cross-attending to the keyframe encodings) and a decoder
  over all frames (keyframe tokens from the encoder, the others from the
  intermediate module), as in CITL;
* Shaw-style learned relative positions (zero initialised) instead of sinusoids;
* optionally (``interm_tokens="lerp"``, off by default; not in the paper), the
  intermediate tokens start from an embedding of the frame's LERP/SLERP pose and
  its place in its gap instead of zeros, and (``residual_space="local"``) the
  residual correction is added to the SLERPed local rotations instead of the FOQ;
* optionally (``canonical_heading``, off by default; not in the paper), each
  window is turned about the up axis so that its first frame faces a fixed
  direction (:func:`window_heading`), and the prediction is turned back;
* output: FOQ per joint plus the root position; frame 0 is always a key, so its
  global rotations turn FOQ back into rotations;
* loss ``L1(root) + L1(FOQ) + 0.1 (L1(FK positions) + L1(global quaternions))``,
  the quaternion terms taken up to sign (``q`` and ``-q`` are one rotation; a
  sign-continuous target can differ from a prediction by a global sign after a
  fast spin), AdamW with linear warm-up.

:class:`PcmrlInterpAligner` wraps it as an :class:`~skelagnostic.aligners.Aligner`
with ``interpolate(motion, keyframes)``. :data:`INTERP_CONFIG` holds the authors'
settings; ``experiment=pcmrl_interp_cpu`` a smaller CPU configuration.
"""

from __future__ import annotations

from typing import Any

from skelagnostic.core.kinematics import fk_from_global, global_from_local, local_from_global
from skelagnostic.lazy import deprecated_aliases
from skelagnostic_pcmrl.interp_aligner import PcmrlInterpAligner
from skelagnostic_pcmrl.interp_keyframes import (
    key_brackets,
    lerp_baseline,
    lerp_keys,
    sign_invariant_l1,
    slerp_keys,
    window_features,
    window_heading,
)
from skelagnostic_pcmrl.interp_network import CITLInterpolator

__all__ = [
    "INTERP_CONFIG",
    "INTERP_DATA_DEFAULTS",
    "INTERP_DATA_OPTIONS",
    "CITLInterpolator",
    "PcmrlInterpAligner",
    "fk_from_global",
    "global_from_local",
    "key_brackets",
    "lerp_baseline",
    "lerp_keys",
    "sign_invariant_l1",
    "slerp_keys",
    "window_features",
    "window_heading",
]

#: Former name of :func:`skelagnostic.core.kinematics.local_from_global`, kept for existing imports.
global_to_local = local_from_global


#: The authors' settings (paper Sec. 3.4 / METHODS.md): the ``model/pcmrl_interp`` config.
INTERP_CONFIG: dict[str, Any] = {
    "dim": 512,
    "heads": 8,
    "layers": 6,
    "ff_mult": 4,
    "max_relative": 128,
    "residual": False,
    "residual_space": "foq",
    "interm_tokens": "zero",
    "canonical_heading": False,
    "lr": 1e-4,
    "weight_decay": 0.0,
    "warmup_steps": 10000,
    "w_root": 1.0,
    "w_foq": 1.0,
    "w_fk": 0.1,
    "w_quat": 0.1,
}

#: Default data of ``model=pcmrl_interp``: procedural CMU-31-topology bipeds (no files needed).
INTERP_DATA_DEFAULTS: dict[str, Any] = {
    "source": "procedural",
    "kinds": ["biped31"],
    "gaits": ["walk", "run"],
    "clips_per_gait": 4,
    "seconds": 8.0,
}

#: Data-module keys of :class:`~skelagnostic_pcmrl.interp_data.PcmrlInterpDataModule`.
INTERP_DATA_OPTIONS: dict[str, Any] = {
    "fps": 30.0,
    "window": 128,
    "stride": 32,
    "min_keys": 5,
    "max_keys": 36,
    "key_mode": "random",
    "min_gap": 5,
    "max_gap": 30,
    "batch_size": 16,
    "samples_per_epoch": 1024,
    "val_fraction": 0.2,
    "val_gap": 15,
    "rpa_range": 0.1,
    "rpa_prob": 0.5,
    "rpa_offsets": "independent",
    "rpa_solve": "directions",
    "mirror": False,
    "procedural_kind": None,
    "procedural_clips": 0,
    "seed": 0,
    "num_workers": 0,
}


#: Names before the rename to one pattern (``<Method><Part>Aligner``); deprecated.
__getattr__ = deprecated_aliases(__name__, {"InterpolationAligner": "PcmrlInterpAligner"})
