"""The hook specifications of skelagnostic plugins.

Every hook is *callback-style*: skelagnostic calls it with a ``register``
function, and the plugin calls ``register(...)`` once per thing it contributes.
A plugin is a module (or any object) with functions decorated by
:data:`skelagnostic.plugins.hookimpl` whose names match the specs below; it is
found through the ``skelagnostic`` entry-point group::

    # pyproject.toml of the plugin distribution
    [project.entry-points.skelagnostic]
    example = "skelagnostic_example.plugin"

Built-in components register through these same hooks (see
:mod:`skelagnostic.plugins.builtin`). Each ``register`` is typed by a
:class:`~typing.Protocol` of :mod:`skelagnostic.plugins.protocols` (``RegisterAligner``,
``RegisterDataset``, ...): annotate a hook's parameter with it to have its calls checked.
"""

from __future__ import annotations

import pluggy

from skelagnostic.plugins.protocols import (
    RegisterAligner,
    RegisterCheckpointReader,
    RegisterConfigPath,
    RegisterDataset,
    RegisterEvaluation,
    RegisterRepresentation,
)

#: Marker for hook specifications (project name ``skelagnostic``).
hookspec = pluggy.HookspecMarker("skelagnostic")
#: Marker for hook implementations in plugins: ``@hookimpl def register_aligners(register): ...``.
hookimpl = pluggy.HookimplMarker("skelagnostic")


@hookspec
def register_aligners(register: RegisterAligner) -> None:
    """Contribute aligners (trainable models) to ``model=<name>``.

    Call ``register(name, module, datamodule=MotionDataModule, config=None,
    description="")`` once per aligner (:class:`~skelagnostic.plugins.RegisterAligner`),
    where ``module`` is an :class:`~skelagnostic.aligners.Aligner` subclass,
    ``datamodule`` a :class:`~skelagnostic.data.MotionDataModule` subclass that
    produces the batches the aligner trains on, and ``config`` the aligner's config
    file, e.g. ``files("my_plugin.conf") / "mine.yaml"``: the one place of its
    configuration, read once here (:func:`skelagnostic.plugins.read_aligner_config`).

    Its ``model`` section is the Hydra config ``model/<name>``: ``_target_`` naming
    ``module``, then every constructor argument with its default value (checked
    against ``module``; ``name`` is reserved). ``data`` (optional) is the aligner's
    default data config, with a ``source`` key: it becomes ``data/<name>`` and is
    used when the command line names no ``data=...``. ``data_options`` (optional)
    are data-module keys the aligner needs whatever the data (e.g. ``fps: 30``):
    they are merged over the selected data config, and command-line
    ``data.<key>=...`` overrides still win. ``trainer_options`` (optional) do the
    same for the trainer config (e.g. ``gradient_clip_val: 1.0``). They must not set
    a limit (``max_time``, ``max_steps``, ``max_epochs``, ...): a model's defaults
    that end a run would override the user's ``trainer.max_steps``; put budgets in
    an ``experiment/`` config.

    Args:
        register: The registration callback (its signature: the ``Protocol`` named
            in the annotation, exported by :mod:`skelagnostic.plugins`).
    """


@hookspec
def register_representations(register: RegisterRepresentation) -> None:
    """Contribute motion representations, selectable with ``data.representation=<name>``.

    Call ``register(name, cls)`` once per representation, where ``cls`` is a
    :class:`~skelagnostic.representations.MotionRepresentation` subclass whose
    constructor takes keyword options only.

    Args:
        register: The registration callback (its signature: the ``Protocol`` named
            in the annotation, exported by :mod:`skelagnostic.plugins`).
    """


@hookspec
def register_datasets(register: RegisterDataset) -> None:
    """Contribute dataset readers and presets, selectable with ``data.source=<name>``.

    Call ``register(name, factory, description="")`` once per dataset, where
    ``factory(**options)`` returns a :class:`~skelagnostic.data.ClipSource`
    (``options`` come from ``data.options`` in the config).

    Args:
        register: The registration callback (its signature: the ``Protocol`` named
            in the annotation, exported by :mod:`skelagnostic.plugins`).
    """


@hookspec
def register_config_paths(register: RegisterConfigPath) -> None:
    """Contribute Hydra config search paths (extra ``model/``, ``experiment/``, ... files).

    Call ``register(path)`` with a Hydra search-path URL, for example
    ``"pkg://my_plugin.conf"`` (a package holding YAML files) or
    ``"file:///abs/dir"``.

    Args:
        register: The registration callback (its signature: the ``Protocol`` named
            in the annotation, exported by :mod:`skelagnostic.plugins`).
    """


@hookspec
def register_evaluations(register: RegisterEvaluation) -> None:
    """Contribute evaluation protocols, run by ``skelagnostic evaluate protocol=<name>``.

    Call ``register(name, function, model, description="", default=False)``
    once per protocol, where ``name`` reads ``<method>.<what>`` (for example
    ``humot.reconstruction``), ``model`` is the aligner name the protocol
    evaluates, and ``function(aligner, held_out, out_dir)`` returns an
    :class:`~skelagnostic.evaluation.Evaluation`: ``aligner`` is the trained
    aligner (weights loaded, eval mode), ``held_out`` the
    :class:`~skelagnostic.evaluation.HeldOut` clips of the run's data, and
    ``out_dir`` the directory for the protocol's plots; keyword arguments after
    these three are the protocol's options (``+protocol_options.KEY=VALUE`` on the
    command line). ``default=True`` marks
    the protocol ``evaluate`` runs when the command line names none (one per
    model).

    Args:
        register: The registration callback (its signature: the ``Protocol`` named
            in the annotation, exported by :mod:`skelagnostic.plugins`).
    """


@hookspec
def register_checkpoint_readers(register: RegisterCheckpointReader) -> None:
    """Contribute readers of trained models that ``skelagnostic fit`` did not write.

    Call ``register(scheme, reader, model, description="")`` once per reader:
    the inference verbs then accept ``ckpt=<scheme>:<path>`` (for example
    ``ckpt=authors:runs/human_dog`` for a run of a method's official code), and
    build the aligner with ``reader(path)``, which returns it with its weights
    loaded (an instance of the class registered as ``model``). ``scheme`` is a
    lower-case word of two or more letters, digits or underscores.

    Args:
        register: The registration callback (its signature: the ``Protocol`` named
            in the annotation, exported by :mod:`skelagnostic.plugins`).
    """
