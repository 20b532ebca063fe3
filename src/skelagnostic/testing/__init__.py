"""A reusable contract test for aligners: what ``skelagnostic fit`` and users rely on.

Subclass :class:`AlignerContract` in a pytest module of your plugin and name
your aligner; pytest then runs six tests against it, at the sizes you give::

    from skelagnostic.testing import AlignerContract

    class TestMyAligner(AlignerContract):
        aligner = "mine"                      # the model=<name> you register
        overrides = ("model.hidden=8",)       # Hydra overrides: keep it tiny and fast

The tests share one short training run (``experiment=smoke``, :attr:`~AlignerContract.steps`
optimizer steps, one validation pass, CPU) made through the same
:func:`skelagnostic.cli.app.compose` and :func:`~skelagnostic.cli.app.run` as
``skelagnostic fit``:

* ``test_fit_a_few_steps``: the run logs a finite ``train/loss`` and ``val/loss``,
  changes the weights and writes ``checkpoints/last.ckpt``;
* ``test_checkpoint_round_trip``: :func:`skelagnostic.plugins.load_aligner` rebuilds
  the network from the checkpoint alone (sizes that depend on the data must be
  saved in the hyper-parameters) with exactly the saved weights, and encodes
  like the trained model;
* ``test_encode_decode_shapes``: ``encode`` a clip of the training data and
  ``decode`` it (and ``retarget``, if declared) onto :meth:`~AlignerContract.target_skeleton`:
  a finite :class:`~skelagnostic.core.motion.Motion` of that skeleton with the
  clip's length and frame rate;
* ``test_encode_ignores_the_length_unit``: the same clip in metres and in
  centimetres (and in centimetres with its unit left to the height guess, as
  ``read_bvh`` leaves a file's) encodes to the same latent: models train on the
  data sources' metres, and users pass files in any unit;
* ``test_steps_without_a_trainer``: the aligner rebuilt from the checkpoint, attached
  to no Trainer (``self.trainer`` raises), runs ``training_step`` (a finite loss whose
  gradient is finite and not zero) and ``validation_step`` on the first batches of the
  run's data module: a batch carries the skeleton information its model needs
  (``batch["skeleton"]``, :func:`~skelagnostic.aligners.batch_skeleton`), so a model
  runs without a Trainer or a data module;
* ``test_logging_is_ddp_safe``: every ``self.log`` in a step passes an explicit
  ``batch_size`` (batches are dicts of datasets, which Lightning cannot size),
  and every epoch-level value logged in a step (validation, test, ``on_epoch=True``)
  passes ``sync_dist=True`` so that DDP ranks agree; torchmetrics ``Metric``
  objects are exempt (they synchronise themselves), and so are values logged in
  epoch-end hooks (compute them from synchronised state).

The same checks are plain functions (:func:`fit_for_contract`,
:func:`check_fit`, :func:`check_checkpoint_round_trip`,
:func:`check_encode_decode`, :func:`check_length_units`,
:func:`check_steps_without_trainer`, :func:`check_logging`) for
other test runners.
The package imports pytest: use it from tests.

The checks live in :mod:`skelagnostic.testing.checks`, the pytest class in
:mod:`skelagnostic.testing.contract`; this package re-exports both, the import
path plugins use.
"""

from skelagnostic.testing.checks import (
    ContractRun,
    LogCall,
    check_checkpoint_round_trip,
    check_encode_decode,
    check_fit,
    check_length_units,
    check_logging,
    check_steps_without_trainer,
    contract_motion,
    fit_for_contract,
)
from skelagnostic.testing.contract import AlignerContract

__all__ = [
    "AlignerContract",
    "ContractRun",
    "LogCall",
    "check_checkpoint_round_trip",
    "check_encode_decode",
    "check_fit",
    "check_length_units",
    "check_logging",
    "check_steps_without_trainer",
    "contract_motion",
    "fit_for_contract",
]
