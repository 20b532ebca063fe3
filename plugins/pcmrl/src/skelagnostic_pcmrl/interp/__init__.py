"""PC-MRL stage 2: the CITL-style keyframe interpolation transformer (Sec. 3.4).

The model fills the frames between keyframes of a motion on the *target*
skeleton. It follows CITL (Mo et al., CVPR 2023) with PC-MRL's changes:

* per-joint input (keyframes only, zeros and a 0 key flag on the other frames):
  the joint's global position minus the mean of the keyframe positions, the unit
  rest bone direction (:func:`~skelagnostic_pcmrl.interp.rpa.bone_tails`) rotated by the
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
  direction (:func:`~skelagnostic_pcmrl.interp.keyframes.window_heading`), and the
  prediction is turned back;
* output: FOQ per joint plus the root position; frame 0 is always a key, so its
  global rotations turn FOQ back into rotations;
* loss ``L1(root) + L1(FOQ) + 0.1 (L1(FK positions) + L1(global quaternions))``,
  the quaternion terms taken up to sign (``q`` and ``-q`` are one rotation; a
  sign-continuous target can differ from a prediction by a global sign after a
  fast spin), AdamW with linear warm-up.

:class:`~skelagnostic_pcmrl.interp.aligner.PcmrlInterpAligner` wraps it as an
:class:`~skelagnostic.aligners.Aligner` with ``interpolate(motion, keyframes)``;
``conf/pcmrl_interp.yaml`` holds the authors' settings and the default data,
``experiment=pcmrl_interp_cpu`` a smaller CPU configuration.

Modules: :mod:`~skelagnostic_pcmrl.interp.keyframes` (keyframe brackets, LERP/SLERP,
window features and heading, the sign-invariant loss), :mod:`~skelagnostic_pcmrl.interp.network`
(the CITL network), :mod:`~skelagnostic_pcmrl.interp.aligner` (the aligner),
:mod:`~skelagnostic_pcmrl.interp.rpa` (rest pose augmentation and bone tails),
:mod:`~skelagnostic_pcmrl.interp.data` (data module, keyframe draws) and
:mod:`~skelagnostic_pcmrl.interp.evaluation` (the Table 1 protocol).
"""
