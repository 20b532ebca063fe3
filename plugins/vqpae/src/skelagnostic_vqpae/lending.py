"""How the VQ-PAE model reaches work that lives on higher floors of its plugin.

See :data:`LENT` for why: the model never imports its embedding, transfer or protocols.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar

from skelagnostic.errors import SkelagnosticError

__all__ = ["LENT", "LendsWork"]

#: Work the model hands to higher floors of the plugin, with the module that does it
#: (:meth:`VqpaeAligner.lend`). The framework calls ``fit_summary`` (the ``FitSummary``
#: callback) and ``transfer`` (``skelagnostic transfer``) on the aligner, but their work
#: uses the embedding, transfer and protocol floors, which build on the model: importing
#: them here would make the model import its own evaluation (an import loop). So the
#: plugin's top floor lends them: ``plugin.wire()`` (run when the plugin registers the
#: aligner, so every run through the plugin manager has them, at no import cost until
#: used), and each module lends its own function when imported (a script that builds the
#: aligner by hand and imports the module). Otherwise the call fails with an error naming
#: the module. A Lightning callback would need the CLI's callback list to know the plugin,
#: and it would not serve ``transfer``; lending serves both with one direction of imports.
LENT: dict[str, str] = {
    "fit_summary": "skelagnostic_vqpae.protocols.summary",
    "transfer": "skelagnostic_vqpae.transfer",
}


class LendsWork:
    """Mixin of :class:`~skelagnostic_vqpae.aligner.VqpaeAligner`: work lent by higher floors."""

    #: The functions lent so far (:data:`LENT`), shared by every instance.
    _lent: ClassVar[dict[str, Callable[..., Any]]] = {}

    @classmethod
    def lend(cls, name: str, function: Callable[..., Any]) -> None:
        """Lend the model work that lives on a higher floor of the plugin (see :data:`LENT`).

        Args:
            name: ``"fit_summary"`` or ``"transfer"``.
            function: For ``"fit_summary"``, ``f(aligner, trainer, mode=...) ->
                SummaryContent``; for ``"transfer"``, ``f(aligner, motion, targets) ->
                (motion, transitions)``.

        Raises:
            SkelagnosticError: ``name`` is not in :data:`LENT`.
        """
        if name not in LENT:
            raise SkelagnosticError(f"VqpaeAligner.lend: unknown work {name!r}; known: {LENT}")
        cls._lent[name] = function

    def _borrow(self, name: str) -> Callable[..., Any]:
        """The function a higher floor lent for ``name``, or a clear error naming its module."""
        function = self._lent.get(name)
        if function is None:
            raise SkelagnosticError(
                f"VqpaeAligner.{name} is lent by {LENT[name]}: import it, or call "
                "skelagnostic_vqpae.plugin.wire() (skelagnostic.load_aligner and the command "
                "line do)"
            )
        return function
