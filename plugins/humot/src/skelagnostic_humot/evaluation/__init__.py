"""HuMoT evaluations (Sec. 4) on 1 s chunks of held-out clips, one module per protocol.

Protocols (``skelagnostic evaluate model=humot ckpt_path=... [protocol=...]``):

* ``humot.reconstruction`` (the default,
  :func:`~skelagnostic_humot.evaluation.reconstruction.reconstruction_protocol`):
  Table 2 per held-out human clip beside the mean-pose baselines, the denoising
  (Fig. 8) and joint-upsampling (Fig. 9) curves in ``extra`` and two plots
  (:mod:`~skelagnostic_humot.evaluation.reconstruction`).
* ``humot.retarget``
  (:func:`~skelagnostic_humot.evaluation.retarget.retarget_protocol`): the cycle
  error of every held-out human clip via a rig of another topology beside the
  copy baselines, plus paired procedural retargeting
  (:mod:`~skelagnostic_humot.evaluation.retarget`).

Both use :mod:`~skelagnostic_humot.evaluation.held_out` (the held-out human clips,
``+protocol_options.extra`` files, the seen/unseen topology status);
:mod:`~skelagnostic_humot.evaluation.suite` runs every evaluation on groups of
clips for the benchmarks.
"""
