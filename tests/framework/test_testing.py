"""skelagnostic.testing: the contract's checks catch what they promise to catch."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from skelagnostic.testing import ContractRun, LogCall, check_logging

TROUBLESHOOTING = Path(__file__).resolve().parents[2] / "docs" / "troubleshooting.md"


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


def test_a_checkout_folder_named_skelagnostic_is_reported(tmp_path: Path) -> None:
    # issue 48, item 9: run beside a checkout named skelagnostic, `import skelagnostic`
    # is that folder (an empty namespace package), and the errors did not say so
    (tmp_path / "skelagnostic" / "src").mkdir(parents=True)

    def python(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, *args], cwd=tmp_path, capture_output=True, text=True, timeout=300
        )

    found = python("-c", "import skelagnostic; print(getattr(skelagnostic, '__file__', None))")
    if found.stdout.strip() != "None":
        pytest.skip("the installed package is found before the folder (not an editable install)")
    expected = f"'import skelagnostic' found the folder {tmp_path / 'skelagnostic'} (no __init__.py"
    contract = python("-c", "from skelagnostic.testing import AlignerContract")
    assert contract.returncode != 0
    assert f"ShadowedPackageError: {expected}" in contract.stderr.splitlines()[-1]
    cli_run = python("-m", "skelagnostic.cli", "plugins")
    assert cli_run.returncode == 2
    (line,) = cli_run.stderr.splitlines()
    assert line.startswith(f"skelagnostic: error: {expected}")
    assert line.replace(str(tmp_path), "<tmp>") in TROUBLESHOOTING.read_text()
