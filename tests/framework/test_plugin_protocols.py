"""Each hook's ``register`` is typed: a ``Protocol`` per hook, matching what skelagnostic calls."""

from __future__ import annotations

import inspect
import typing

import pytest

import skelagnostic.plugins as plugins
from skelagnostic.plugins import hookspecs
from skelagnostic.plugins.registration import HOOKS, Registrar

PROTOCOLS = {
    "register_aligners": plugins.RegisterAligner,
    "register_representations": plugins.RegisterRepresentation,
    "register_datasets": plugins.RegisterDataset,
    "register_config_paths": plugins.RegisterConfigPath,
    "register_evaluations": plugins.RegisterEvaluation,
    "register_checkpoint_readers": plugins.RegisterCheckpointReader,
}


def test_every_hook_has_a_protocol() -> None:
    assert sorted(PROTOCOLS) == sorted(HOOKS)
    for protocol in PROTOCOLS.values():
        assert protocol.__name__ in plugins.__all__
        assert getattr(protocol, "_is_protocol", False)


@pytest.mark.parametrize("hook", HOOKS)
def test_the_hookspec_annotates_register_with_its_protocol(hook: str) -> None:
    hints = typing.get_type_hints(getattr(hookspecs, hook))
    assert hints["register"] is PROTOCOLS[hook]


@pytest.mark.parametrize("hook", HOOKS)
def test_the_protocol_is_the_callback_skelagnostic_hands_over(hook: str) -> None:
    def shape(function: object) -> list[tuple[str, object]]:
        params = inspect.signature(function).parameters.values()  # type: ignore[arg-type]
        return [(p.name, p.default) for p in params if p.name != "self"]

    callback = Registrar("test").callbacks()[hook]
    assert shape(PROTOCOLS[hook].__call__) == shape(callback)
