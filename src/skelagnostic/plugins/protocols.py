"""The signatures of the ``register`` callbacks, one :class:`~typing.Protocol` per hook.

A hook of :mod:`skelagnostic.plugins.hookspecs` receives one of these; annotate
the hook's parameter with it and a type checker (and an editor) checks the calls::

    from skelagnostic.plugins import RegisterAligner, hookimpl


    @hookimpl
    def register_aligners(register: RegisterAligner) -> None:
        register("mine", MyAligner, MyDataModule, config=files("my_plugin.conf") / "mine.yaml")

The classes are imported lazily by skelagnostic (the types here are names only),
so importing this module costs nothing.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any, Protocol, TypeAlias

if TYPE_CHECKING:
    import os
    from importlib.resources.abc import Traversable

    from skelagnostic.aligners import Aligner
    from skelagnostic.data import ClipSource, MotionDataModule
    from skelagnostic.representations import MotionRepresentation


#: Where an aligner's config comes from: its YAML file (a path, or a
#: :class:`~importlib.resources.abc.Traversable` such as
#: ``importlib.resources.files("my_plugin.conf") / "mine.yaml"``), or the same
#: sections as a mapping (handy for a plugin defined in a test).
AlignerConfigSource: TypeAlias = "str | os.PathLike[str] | Traversable | Mapping[str, Any]"


class RegisterAligner(Protocol):
    """``register`` of ``register_aligners``: contribute ``model=<name>``."""

    def __call__(
        self,
        name: str,
        module: type[Aligner] | str,
        datamodule: type[MotionDataModule] | str | None = None,
        config: AlignerConfigSource | None = None,
        description: str = "",
    ) -> None:
        """Register one aligner.

        Args:
            name: The ``model=<name>`` of the aligner.
            module: The :class:`~skelagnostic.aligners.Aligner` subclass, or a
                reference ``"package.module:Class"`` imported when first used (so
                ``skelagnostic plugins`` and ``--help`` import no model and no
                Lightning); the config's ``_target_`` must name the same class.
            datamodule: The :class:`~skelagnostic.data.MotionDataModule` subclass
                producing its batches, or a reference (``None``: ``MotionDataModule``).
            config: The aligner's config file, read once here: its sections
                ``model`` (``_target_`` and every constructor argument), ``data``
                (the default data), ``data_options`` and ``trainer_options``
                (see :func:`skelagnostic.plugins.read_aligner_config`). ``None``:
                the constructor's own defaults and ``data=procedural``.
            description: One line for ``skelagnostic plugins``.
        """


class RegisterRepresentation(Protocol):
    """``register`` of ``register_representations``: contribute ``data.representation=<name>``."""

    def __call__(self, name: str, cls: type[MotionRepresentation] | str) -> None:
        """Register one motion representation (its constructor takes keyword options only).

        ``cls`` may be a reference ``"package.module:Class"``, imported when first used.
        """


class RegisterDataset(Protocol):
    """``register`` of ``register_datasets``: contribute ``data.source=<name>``."""

    def __call__(
        self, name: str, factory: Callable[..., ClipSource] | str, description: str = ""
    ) -> None:
        """Register one dataset: ``factory(**options)`` returns its clips.

        ``factory`` may be a reference ``"package.module:function"``, imported when first used.
        """


class RegisterConfigPath(Protocol):
    """``register`` of ``register_config_paths``: add a Hydra search path."""

    def __call__(self, path: str) -> None:
        """Register ``"pkg://my_plugin.conf"`` (a package of YAML files) or ``"file:///abs/dir"``."""


class RegisterEvaluation(Protocol):
    """``register`` of ``register_evaluations``: contribute ``protocol=<name>``."""

    def __call__(
        self,
        name: str,
        function: Callable[..., Any] | str,
        model: str,
        description: str = "",
        default: bool = False,
    ) -> None:
        """Register one protocol: ``function(aligner, held_out, out_dir, **options)``.

        Args:
            name: ``<method>.<what>``, e.g. ``humot.reconstruction``.
            function: Returns a :class:`~skelagnostic.evaluation.Evaluation`; or a
                reference ``"package.module:function"``, imported when first used.
            model: The aligner name the protocol evaluates.
            description: One line (empty: the function's first docstring line, for
                a function given as an object).
            default: The protocol ``evaluate`` runs for ``model`` when none is named.
        """


class RegisterCheckpointReader(Protocol):
    """``register`` of ``register_checkpoint_readers``: accept ``ckpt=<scheme>:<path>``."""

    def __call__(
        self,
        scheme: str,
        reader: Callable[[str], Aligner] | str,
        model: str,
        description: str = "",
    ) -> None:
        """Register one reader: ``reader(path)`` returns the ``model`` aligner, weights loaded.

        ``reader`` may be a reference ``"package.module:function"``, imported when first used.
        """
