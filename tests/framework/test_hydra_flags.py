"""Hydra's own flags work on every Hydra verb, wherever they stand on the command line.

The CLI adds overrides of its own (``task=<verb>``), which once followed the
user's arguments and made argparse reject every flag (``unrecognized
arguments: task=fit``). Each flag is checked through the installed console
script (a subprocess, as a user runs it) and, for every verb with and without
``model=``, in-process (fast).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from skelagnostic import cli
from skelagnostic.cli.app import split_hydra_flags

SCRIPT = Path(sys.executable).with_name("skelagnostic")
VERBS = ("fit", "validate", "test", "predict", "evaluate")

#: flag arguments -> text their output must contain
FLAGS: dict[str, tuple[list[str], str]] = {
    "help": (["--help"], "== Configuration groups =="),
    "h": (["-h"], "== Configuration groups =="),
    "hydra-help": (["--hydra-help"], "Hydra ("),
    "cfg": (["--cfg", "job"], "seed: 42"),
    "cfg-resolve": (["--cfg", "job", "--resolve"], "seed: 42"),
    "info": (["--info", "defaults"], "Defaults List"),
    "completion": (["--shell-completion", "install=bash"], "complete -o nospace"),
}


def console(
    args: list[str], env: dict[str, str], cwd: Path, **extra_env: str
) -> subprocess.CompletedProcess[str]:
    if not SCRIPT.exists():
        pytest.skip(f"console script not installed next to {sys.executable}")
    return subprocess.run(
        [str(SCRIPT), *args],
        env={**env, **extra_env},
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=180,
    )


def test_split_keeps_flag_values_with_their_flags() -> None:
    assert split_hydra_flags(["a=1", "--cfg", "job", "b=2", "--resolve", "-m", "c=1,2"]) == (
        ["--cfg", "job", "--resolve", "-m"],
        ["a=1", "b=2", "c=1,2"],
    )
    assert split_hydra_flags(["--info", "a=1"]) == (["--info"], ["a=1"])
    assert split_hydra_flags(["--info", "defaults", "a=1"]) == (["--info", "defaults"], ["a=1"])
    assert split_hydra_flags(["--cfg=job", "x=~/y"]) == (["--cfg=job"], ["x=~/y"])
    assert split_hydra_flags(["~trainer.max_time"]) == ([], ["~trainer.max_time"])


@pytest.mark.parametrize("flag", list(FLAGS))
def test_flag_through_the_console_script(
    flag: str, subprocess_env: dict[str, str], tmp_path: Path
) -> None:
    args, expected = FLAGS[flag]
    verb = VERBS[list(FLAGS).index(flag) % len(VERBS)]
    # the flag after the overrides, as users type it (this once gave "unrecognized arguments")
    proc = console([verb, "model=example", *args], subprocess_env, tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert expected in proc.stdout, proc.stdout[-2000:]
    assert "unrecognized arguments" not in proc.stderr
    assert not (tmp_path / "runs").exists()  # showing something runs nothing


@pytest.mark.parametrize("verb", VERBS)
@pytest.mark.parametrize("flag", list(FLAGS))
@pytest.mark.parametrize("with_model", [True, False])
def test_every_flag_on_every_verb(
    verb: str,
    flag: str,
    with_model: bool,
    example_plugin: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.chdir(tmp_path)
    args, expected = FLAGS[flag]
    model = ["model=example"] if with_model else []
    assert cli.main([verb, *model, *args]) == 0
    out = capsys.readouterr().out
    assert expected in out
    if flag == "cfg":
        cfg = yaml.safe_load(out)
        assert cfg["task"] == verb
        assert ("model" in cfg) == with_model


def test_help_lists_aligners_and_plugin_experiments(
    example_plugin: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert cli.main(["fit", "--help"]) == 0
    out = capsys.readouterr().out
    groups = dict(
        line.split(": ", 1) for line in out.split("== Config ==")[0].splitlines() if ": " in line
    )
    assert "example" in groups["model"].split(", ")
    assert "example_quick" in groups["experiment"].split(", ")  # from the plugin's conf/
    assert "debug" in groups and "_aligner" not in groups  # the internal group stays hidden


def test_help_with_a_model_shows_its_resolved_defaults(
    example_plugin: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert cli.main(["fit", "model=example", "--cfg", "job", "--resolve"]) == 0
    cfg = yaml.safe_load(capsys.readouterr().out)
    assert cfg["model"]["name"] == "example" and cfg["model"]["hidden"] > 0


def test_multirun_sweeps_into_one_directory(subprocess_env: dict[str, str], tmp_path: Path) -> None:
    proc = console(
        [
            "fit",
            "-m",
            "model=example",
            "experiment=smoke",
            "model.hidden=8,16",
            "trainer.max_epochs=1",
            "threads=1",
            "data.seconds=2.0",
            "data.clips_per_gait=1",
        ],
        subprocess_env,
        tmp_path,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    sweeps = list((tmp_path / "runs" / "example" / "fit").glob("multirun_*"))
    assert len(sweeps) == 1
    hidden = []
    for job in ("0", "1"):
        run = sweeps[0] / job
        assert (run / "checkpoints" / "last.ckpt").is_file()
        hidden.append(yaml.safe_load((run / "config.yaml").read_text())["model"]["hidden"])
    assert sorted(hidden) == [8, 16]


def test_shell_completion_queries(subprocess_env: dict[str, str], tmp_path: Path) -> None:
    line = "skelagnostic f"
    proc = console(
        ["-sc", "query=bash"], subprocess_env, tmp_path, COMP_LINE=line, COMP_POINT=str(len(line))
    )
    assert proc.returncode == 0 and proc.stdout.split() == ["fit"]
    line = "skelagnostic fit model=exa"
    proc = console(
        ["-sc", "query=bash"], subprocess_env, tmp_path, COMP_LINE=line, COMP_POINT=str(len(line))
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["model=example"]
