"""skelagnostic.testing: the contract's checks catch what they promise to catch."""

from __future__ import annotations

from pathlib import Path

import pytest

from skelagnostic.testing import ContractRun, LogCall, check_logging


class Stub:
    """Stands in for the trained aligner (only its class name is used)."""


def _run(*logs: LogCall) -> ContractRun:
    return ContractRun("stub", Path("."), {}, Stub(), None, {}, None, list(logs))  # type: ignore[arg-type]


VAL = LogCall("validation_step", "val/loss", {"batch_size": 4, "sync_dist": True}, False)


def test_logging_without_batch_size_or_sync_dist_is_flagged() -> None:
    check_logging(_run(LogCall("training_step", "train/loss", {"batch_size": 4}, False), VAL))
    with pytest.raises(
        AssertionError,
        match=r"Stub\.training_step logs 'train/loss' without "
        r"batch_size=",
    ):
        check_logging(_run(LogCall("training_step", "train/loss", {}, False), VAL))
    with pytest.raises(
        AssertionError,
        match=r"Stub\.validation_step logs 'val/mpjpe' per epoch "
        r"without sync_dist=True",
    ):
        check_logging(_run(VAL, LogCall("validation_step", "val/mpjpe", {"batch_size": 4}, False)))
    with pytest.raises(AssertionError, match=r"'train/x' per epoch without sync_dist"):
        check_logging(
            _run(
                VAL, LogCall("training_step", "train/x", {"batch_size": 4, "on_epoch": True}, False)
            )
        )
    # torchmetrics Metric objects synchronise themselves
    check_logging(_run(VAL, LogCall("validation_step", "val/m", {}, True)))


def test_validation_must_log_val_loss() -> None:
    with pytest.raises(AssertionError, match="must log 'val/loss'"):
        check_logging(_run(LogCall("training_step", "train/loss", {"batch_size": 4}, False)))
