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


@pytest.mark.parametrize(
    "args",
    [
        ["interpolate", "--help"],
        ["--help"],  # the dispatcher's own text (issue 48, item 7)
        ["render", "--help"],
        ["plugins"],  # a Rich table
        ["evaluate", "--help"],  # Hydra's help inside the verb's error handling
        ["fit", "--help"],
    ],
)
def test_output_into_a_closed_pipe_is_quiet(args: list[str], tmp_path: Path) -> None:
    proc = subprocess.Popen(
        [sys.executable, "-m", "skelagnostic.cli", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        cwd=tmp_path,
    )
    assert proc.stdout is not None and proc.stderr is not None
    proc.stdout.close()  # like `| head` that already exited
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 1  # what Python's recipe returns
    assert "Traceback" not in err and "BrokenPipeError" not in err, err
    assert "Broken pipe" not in err, err  # not reported as a file error either


def test_help_lists_no_internal_data_config(
    example_plugin: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert cli.main(["fit", "--help"]) == 0
    data = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("data: "))
    options = data.removeprefix("data: ").split(", ")
    assert "procedural" in options and "bvh" in options
    assert not [o for o in options if o.startswith("_")]


def test_the_verb_list_names_every_output_a_verb_writes(capsys: pytest.CaptureFixture[str]) -> None:
    # `render` was "a motion to PNG/GIF" but also writes MP4 and the HTML viewer
    assert cli.main(["--help"]) == 0
    lines = {
        line.split()[0]: line for line in capsys.readouterr().out.splitlines() if line[:2] == "  "
    }
    for kind in ("GIF", "MP4", "PNG", "HTML"):
        assert kind in lines["render"], kind
    assert cli.main(["render", "--help"]) == 0
    out = capsys.readouterr().out
    assert all(suffix in out for suffix in (".gif", ".mp4", ".png", ".html"))
    for kind in ("BVH", "PNG", "GIF", "html="):
        assert kind in lines["demo"], kind


def test_result_tables_never_cut_a_name(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from skelagnostic.cli.evaluate import print_evaluation
    from skelagnostic.cli.runs import summary_table

    long_key = "train/phase_rate/procedural/biped22_and_a_long_suffix"
    run_dir = tmp_path / ("run_" + "x" * 70)
    summary_table("fit", run_dir, {long_key: 0.5, "val/loss": 0.25}, stopped="max_steps 3 reached")
    out = capsys.readouterr().out
    assert "…" not in out
    assert any(long_key in line and "0.5" in line for line in out.splitlines())
    assert any(str(run_dir) in line for line in out.splitlines())  # whole, to copy it
    report = {
        "protocol": "p",
        "data": {"split_name": "test split", "clips": ["a"]},
        "methods": ["model", "a_baseline_with_a_long_name_" + "y" * 40],
        "metrics": {long_key: "a description of the metric " * 4},
        "mean": {"model": {long_key: 1.0}},
    }
    print_evaluation(report, tmp_path)
    assert "…" not in capsys.readouterr().out
