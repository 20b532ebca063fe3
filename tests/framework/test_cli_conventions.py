"""Conventions every verb follows: threads=, a closed pipe, the options --help lists."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import torch

from skelagnostic import cli


@pytest.mark.parametrize("verb", ["render", "retarget", "interpolate", "transfer"])
def test_file_verbs_take_threads(
    verb: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    before = torch.get_num_threads()
    try:
        # threads= is taken before anything else is checked: a bad value is its own error
        assert cli.main([verb, "a.bvh", "threads=zero"]) != 0
        assert "option threads='zero': must be a positive integer" in capsys.readouterr().err
        assert cli.main([verb, str(tmp_path / "missing.bvh"), "threads=1"]) != 0
        err = capsys.readouterr().err
        assert "option threads" not in err and "unknown option" not in err
        assert torch.get_num_threads() == 1
    finally:
        torch.set_num_threads(before)


def test_help_into_a_closed_pipe_is_quiet(tmp_path: Path) -> None:
    proc = subprocess.Popen(
        [sys.executable, "-m", "skelagnostic.cli", "interpolate", "--help"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        cwd=tmp_path,
    )
    assert proc.stdout is not None and proc.stderr is not None
    proc.stdout.close()  # like `| head` that already exited
    err = proc.stderr.read().decode()
    proc.wait(timeout=120)
    assert "Traceback" not in err and "BrokenPipeError" not in err, err


def test_help_lists_no_internal_data_config(
    example_plugin: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert cli.main(["fit", "--help"]) == 0
    data = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("data: "))
    options = data.removeprefix("data: ").split(", ")
    assert "procedural" in options and "bvh" in options
    assert not [o for o in options if o.startswith("_")]
