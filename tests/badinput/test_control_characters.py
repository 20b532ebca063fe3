"""Control characters in user-controlled strings never reach the terminal raw.

A file name, joint name or configuration value holding a terminal escape
sequence (``ESC [2J`` clears the screen, ``ESC ]0;...BEL`` sets the window
title) or a line end is shown in messages as Python writes it in a ``repr``
(``\\x1b``, ``\\x07``, ``\\n``): an error stays one line and no escape is sent.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

import skelagnostic as sa
from skelagnostic import cli
from skelagnostic.errors import BVHError, error_line, printable
from skelagnostic.io.bvh import BVHWarning

CORPUS = Path(__file__).resolve().parent / "corpus"
TROUBLESHOOTING = Path(__file__).resolve().parents[2] / "docs" / "troubleshooting.md"
SMOKE = ["model=example", "experiment=smoke", "data.window=2", "data.stride=1"]
#: Clears the screen, sets the terminal's title, then starts a new line.
HOSTILE = "clip\x1b[2J\x1b]0;pwned\x07\nrm -rf ~"
SHOWN = "clip\\x1b[2J\\x1b]0;pwned\\x07\\nrm -rf ~"


@pytest.fixture
def hostile_bvh(tmp_path: Path) -> Path:
    """An empty (malformed) BVH file whose name holds ESC[2J, a title-setting OSC and a newline."""
    folder = tmp_path / "clips"
    folder.mkdir()
    path = folder / f"{HOSTILE}.bvh"
    shutil.copy(CORPUS / "empty.bvh", path)
    return path


def only_line(err: str, prog: str) -> str:
    """The one error line of ``prog`` in ``err``, which holds no escape (ESC, BEL, CSI).

    Lightning's start-up lines (``INFO: ...``) of ``fit`` may come before it.
    """
    assert "\x1b" not in err and "\x07" not in err and "\x9b" not in err, repr(err)
    assert "Traceback" not in err, err
    lines = [line for line in err.splitlines() if not line.startswith("INFO: ")]
    assert len(lines) == 1, repr(err)
    assert lines[0].startswith(f"{prog}: error: "), lines[0]
    return lines[0]


def test_printable_escapes_every_control_character_and_keeps_the_rest() -> None:
    controls = "".join(map(chr, [*range(0x20), 0x7F, *range(0x80, 0xA0), 0x2028, 0x2029]))
    shown = printable(controls)
    assert shown == repr(controls)[1:-1]
    assert shown.isprintable() and shown.isascii()
    kept = "back\\slash 'quotes' \"too\" \U0001f9b4 \u05e2\u05d1\u05e8\u05d9\u05ea \u00e9"
    assert printable(kept) == kept
    assert printable(Path("/a/b\n")) == "/a/b\\n"
    assert error_line("skelagnostic render", ValueError("x\ny")) == (
        "skelagnostic render: error: x\\ny"
    )


def test_bvh_error_names_the_file_with_escapes(hostile_bvh: Path) -> None:
    with pytest.raises(BVHError) as info:
        sa.read_bvh(hostile_bvh)
    assert info.value.path == hostile_bvh  # the attribute keeps the real name
    assert str(info.value) == f"{hostile_bvh.parent}/{SHOWN}.bvh:1: the file is empty"


def test_bvh_warning_names_the_file_with_escapes(tmp_path: Path) -> None:
    path = tmp_path / f"{HOSTILE}.bvh"
    shutil.copy(CORPUS / "cut_last_number.bvh", path)
    with pytest.warns(BVHWarning) as caught:
        sa.read_bvh(path)
    assert str(caught[0].message).startswith(f"{tmp_path}/{SHOWN}.bvh:35: the last motion line")


def test_render_error_is_one_line_without_escapes(
    hostile_bvh: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert cli.main(["render", str(hostile_bvh), f"out={tmp_path / 'x.gif'}"]) == 2
    line = only_line(capsys.readouterr().err, "skelagnostic render")
    assert line == (
        f"skelagnostic render: error: {hostile_bvh.parent}/{SHOWN}.bvh:1: the file is empty"
    )
    assert line.replace(str(tmp_path), "<tmp>") in TROUBLESHOOTING.read_text(encoding="utf-8")


def test_bidirectional_controls_are_escaped(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bidi = "".join(map(chr, [0x200E, 0x200F, *range(0x202A, 0x202F), *range(0x2066, 0x206A)]))
    assert printable(bidi) == repr(bidi)[1:-1]
    missing = tmp_path / "clip\u202egpj.bvh"  # shown reversed: "clipsvb.jpg"
    assert cli.main(["render", str(missing)]) == 2
    line = only_line(capsys.readouterr().err, "skelagnostic render")
    assert line == f"skelagnostic render: error: {tmp_path}/clip\\u202egpj.bvh: no such file"


def test_render_option_value_and_missing_input_are_escaped(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # a value quoted with repr by the message, and a path formatted as it is
    assert cli.main(["render", str(CORPUS / "valid_small.bvh"), f"mode={HOSTILE}"]) == 2
    assert "\\x1b[2J" in only_line(capsys.readouterr().err, "skelagnostic render")
    missing = tmp_path / f"{HOSTILE}.bvh"
    words = [str(missing), str(CORPUS / "valid_small.bvh"), "ckpt=x.ckpt", f"out={tmp_path}/o.bvh"]
    assert cli.main(["retarget", *words]) == 2
    line = only_line(capsys.readouterr().err, "skelagnostic retarget")
    assert line == f"skelagnostic retarget: error: {tmp_path}/{SHOWN}.bvh: no such file"


def test_fit_error_on_a_hostile_file_name_is_one_line(
    site: Path, hostile_bvh: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = [*SMOKE, "data=bvh", f"data.paths=[{hostile_bvh.parent}]"]
    code = cli.main(["fit", *args, f"runs_dir={tmp_path / 'runs'}", f"data.cache_dir={tmp_path}/c"])
    assert code == 1
    line = only_line(capsys.readouterr().err, "skelagnostic fit")
    assert line == f"skelagnostic fit: error: {hostile_bvh.parent}/{SHOWN}.bvh:1: the file is empty"


def test_fit_error_on_a_hostile_config_value_is_one_line(
    site: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = cli.main(["fit", "model=ex\x1b]0;pwned\x07ample", f"runs_dir={tmp_path / 'runs'}"])
    assert code == 1
    line = only_line(capsys.readouterr().err, "skelagnostic fit")
    assert "model=ex\\x1b]0;pwned\\x07ample" in line


def test_output_paths_on_stdout_are_escaped(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The lines naming what a verb wrote escape control characters, and Rich markup stays text."""
    assert cli.main(["cache", "info", "--cache-dir", str(tmp_path / HOSTILE)]) == 0
    assert capsys.readouterr().out.splitlines()[0] == f"cache: {tmp_path}/{SHOWN}"
    out = tmp_path / f"{HOSTILE}.png"
    assert cli.main(["render", str(CORPUS / "valid_small.bvh"), f"out={out}", "size=32"]) == 0
    assert capsys.readouterr().out == f"{tmp_path}/{SHOWN}.png\n"
    demo = tmp_path / f"[bold]{HOSTILE}"
    assert cli.main(["demo", f"out={demo}", "seconds=0.2", "gif=false", "threads=1"]) == 0
    shown = capsys.readouterr().out
    assert "\x1b" not in shown
    assert f"{tmp_path}/[bold]{SHOWN}/demo.png" in shown.replace("\n", "")
