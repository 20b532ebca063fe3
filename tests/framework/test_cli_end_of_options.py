"""``--`` ends the options of the file verbs (issue 47, item 17).

A file whose name looks like an option (``out=x.bvh``, ``--help``, ``help``) is an
input when it comes after ``--``. Before, ``--`` itself was taken for an input
file and ``out=x.bvh`` for a second ``out=`` option.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from pathlib import Path

import pytest

import skelagnostic as sa
from skelagnostic import cli
from skelagnostic.cli.render import parse_arguments

REPO = Path(__file__).resolve().parents[2]
FAST = [
    "experiment=smoke",
    "data.seconds=2.0",
    "data.clips_per_gait=1",
    "data.window=16",
    "data.stride=8",
    "model.hidden=16",
    "model.latent=4",
    "trainer.max_epochs=1",
]


def _clip(path: Path, kind: str = "biped22", gait: str = "walk") -> Path:
    motion, _ = sa.procedural.generate(kind, gait, seconds=1.0, fps=30)
    sa.write_bvh(motion, path)
    return path


def test_words_after_the_end_of_options_are_inputs_as_they_are() -> None:
    from skelagnostic.cli.render import wants_help

    words = ["a.bvh", "out=o.gif", "--", "out=x.bvh", "--help", "help", "--", "~/y.bvh"]
    assert parse_arguments(words) == (
        ["a.bvh", "out=x.bvh", "--help", "help", "--", "~/y.bvh"],
        {"out": "o.gif"},
    )
    assert parse_arguments(["out=o.gif", "--"]) == ([], {"out": "o.gif"})
    assert wants_help(["a.bvh", "--help"]) and wants_help(["help", "--", "a.bvh"])
    assert not wants_help(["a.bvh", "--", "--help"]) and not wants_help(["--", "help"])


def test_render_draws_a_file_named_like_an_option(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    _clip(tmp_path / "out=x.bvh")
    _clip(tmp_path / "--help", "quadruped", "trot")
    code = cli.main(["render", "out=sheet.png", "frames=2", "size=48", "--", "out=x.bvh", "--help"])
    assert code == 0, capsys.readouterr().err
    assert (tmp_path / "sheet.png").is_file() and not (tmp_path / "x.bvh").exists()
    assert "sheet.png" in capsys.readouterr().out
    # a word after -- is never an option, even the only one
    assert cli.main(["render", "--", "out=sheet2.png"]) == 2
    assert (
        capsys.readouterr().err.strip()
        == "skelagnostic render: error: out=sheet2.png: no such file"
    )


def test_demo_reads_a_file_named_like_an_option(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    _clip(tmp_path / "out=x.bvh")
    code = cli.main(["demo", "out=demo", "gif=false", "--", "out=x.bvh"])
    assert code == 0, capsys.readouterr().err
    summary = json.loads((tmp_path / "demo" / "summary.json").read_text())
    assert "out=x" in json.dumps(summary)
    assert not (tmp_path / "x.bvh").exists()


@pytest.fixture(scope="module")
def trained(
    tmp_path_factory: pytest.TempPathFactory, fit_example: Callable[[Path, Sequence[str]], Path]
) -> Path:
    """A run directory of the example aligner trained for one tiny epoch."""
    return fit_example(tmp_path_factory.mktemp("end-of-options"), FAST)


def test_retarget_reads_files_named_like_options(
    example_plugin: Path,
    trained: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    monkeypatch.chdir(tmp_path)
    _clip(tmp_path / "out=x.bvh")
    _clip(tmp_path / "help", "biped31", "run")
    ckpt = trained / "checkpoints" / "last.ckpt"
    code = cli.main(["retarget", f"ckpt={ckpt}", "out=result.bvh", "--", "out=x.bvh", "help"])
    assert code == 0, capsys.readouterr().err
    result = sa.read_bvh(tmp_path / "result.bvh")
    assert result.skeleton.joint_names == sa.read_bvh(tmp_path / "help").skeleton.joint_names
    assert sa.read_bvh(tmp_path / "out=x.bvh").num_frames == result.num_frames


def test_cli_docs_describe_the_end_of_options() -> None:
    text = (REPO / "docs" / "cli.md").read_text(encoding="utf-8")
    assert "skelagnostic render out=sheet.png -- out=x.bvh" in text
