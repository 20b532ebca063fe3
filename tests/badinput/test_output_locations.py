"""Outputs that cannot be written, sizes that cannot fit and thread counts the machine cannot run.

Every case is one line ``skelagnostic <verb>: error: ...`` naming the option and the
cause, a non-zero exit, and nothing written: locations are checked before any
output is produced (issue 47, items 6, 7 and 12). Read-only directories cannot be
made read-only for root (root writes anyway), so those cases skip as root; the
other cases (a path under a regular file, a directory where a file is expected, a
dangling symbolic link, an existing file where a directory is expected) run everywhere.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
import torch
from test_badinput import CORPUS, SMOKE, documented

from skelagnostic import cli
from skelagnostic.cli import app
from skelagnostic.cli.render import apply_threads
from skelagnostic.data import MotionDataModule
from skelagnostic.errors import SkelagnosticError
from skelagnostic.plugins import PluginManager

EXAMPLE_SRC = Path(__file__).resolve().parents[2] / "plugins" / "example-aligner" / "src"
CLIP = CORPUS / "valid_small.bvh"
ROOT = hasattr(os, "geteuid") and os.geteuid() == 0
#: The documented limit of threads=: 4 per CPU core.
LIMIT = 4 * (os.cpu_count() or 1)
needs_permissions = pytest.mark.skipif(
    ROOT or sys.platform == "win32",
    reason="root writes into read-only directories (the other cases cover the check as root)",
)


def one_error(capsys: pytest.CaptureFixture[str], verb: str) -> str:
    """The single error line of a failed verb (no traceback, nothing else on stderr)."""
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    lines = [line for line in err.splitlines() if line.startswith(f"skelagnostic {verb}: ")]
    assert len(lines) == 1 and lines[0].startswith(f"skelagnostic {verb}: error: "), err
    return lines[0]


@pytest.fixture
def places(tmp_path: Path) -> dict[str, Path]:
    """A regular file, a folder named like a file, a dangling link and a read-only folder."""
    afile = tmp_path / "afile"
    afile.write_text("not a folder\n")
    folder = tmp_path / "folder.gif"
    folder.mkdir()
    dangling = tmp_path / "dangling"
    dangling.symlink_to(tmp_path / "nowhere")
    readonly = tmp_path / "readonly"
    readonly.mkdir()
    readonly.chmod(0o555)
    yield {"afile": afile, "folder": folder, "dangling": dangling, "readonly": readonly}
    readonly.chmod(0o755)


def _written(tmp_path: Path) -> set[str]:
    return {p.name for p in tmp_path.rglob("*") if p.name not in ("afile", "nowhere")}


# ------------------------------------------------------------------------ render out=
@pytest.mark.parametrize(
    ("option", "message"),
    [
        ("out={folder}", "out='{folder}': is a directory; give a file name"),
        ("out={afile}/x.gif", "out='{afile}/x.gif': {afile} is a file, not a directory"),
        ("out={afile}/deeper/x.html", "out='{afile}/deeper/x.html': {afile} is a file, not a"),
        ("sheet={afile}/s.png", "sheet='{afile}/s.png': {afile} is a file, not a directory"),
        (
            "html={dangling}/v.html",
            "html='{dangling}/v.html': {dangling} is a symbolic link to '{nowhere}', which does "
            "not exist",
        ),
    ],
)
def test_render_refuses_an_unusable_output_before_drawing(
    places: dict[str, Path], tmp_path: Path, capsys, monkeypatch, option: str, message: str
) -> None:
    import skelagnostic.viz.render as render

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(render, "Scene", None)  # nothing may be drawn
    names = {**places, "nowhere": tmp_path / "nowhere"}
    words = [str(CLIP), option.format(**names)]
    if not option.startswith("out="):
        words.append(f"out={tmp_path / 'a.gif'}")
    assert cli.main(["render", *words]) == 2
    line = one_error(capsys, "render")
    assert message.format(**names) in line
    documented(line, tmp_path)
    assert _written(tmp_path) == {"folder.gif", "dangling", "readonly"}


@needs_permissions
def test_render_refuses_a_read_only_directory(places, tmp_path, capsys) -> None:
    out = places["readonly"] / "x.gif"
    assert cli.main(["render", str(CLIP), f"out={out}"]) == 2
    line = one_error(capsys, "render")
    assert f"the directory {places['readonly']} is not writable" in line
    documented(line, tmp_path)


def test_read_only_directory_is_refused_even_as_root(places, tmp_path, capsys, monkeypatch):
    # Root writes into read-only folders, so the permission answer is simulated here: the
    # check asks os.access (W_OK | X_OK), which is what a non-root user gets refused by.
    import skelagnostic.io.outputs as outputs

    readonly = places["readonly"]
    real = os.access
    monkeypatch.setattr(
        outputs.os, "access", lambda p, mode: False if Path(p) == readonly else real(p, mode)
    )
    assert cli.main(["render", str(CLIP), f"out={readonly / 'x.gif'}"]) == 2
    line = one_error(capsys, "render")
    assert line.endswith(f"out='{readonly / 'x.gif'}': the directory {readonly} is not writable")
    documented(line, tmp_path)
    assert cli.main(["demo", f"out={readonly / 'demo'}", "gif=false"]) != 0
    assert f"the directory {readonly} is not writable" in one_error(capsys, "demo")
    assert list(readonly.iterdir()) == []


# ------------------------------------------------------------- export / demo out=
def test_export_refuses_an_existing_file_as_its_folder(places, tmp_path, capsys) -> None:
    code = cli.main(
        ["export", f"ckpt_path={tmp_path / 'none.ckpt'}", "format=onnx", f"out={places['afile']}"]
    )
    assert code == 2
    line = one_error(capsys, "export")
    assert f"out='{places['afile']}': is a file, not a directory" in line  # before the ckpt
    documented(line, tmp_path)


@needs_permissions
def test_export_refuses_a_read_only_folder(places, tmp_path, capsys) -> None:
    out = places["readonly"] / "onnx"
    assert cli.main(["export", "ckpt_path=x.ckpt", "format=onnx", f"out={out}"]) == 2
    assert "is not writable" in one_error(capsys, "export")


@pytest.mark.parametrize(
    ("where", "message"),
    [
        ("{afile}", "out='{afile}': is a file, not a directory"),
        ("{afile}/demo", "out='{afile}/demo': {afile} is a file, not a directory"),
        ("{dangling}", "out='{dangling}': a symbolic link to '{nowhere}', which does not exist"),
    ],
)
def test_demo_refuses_an_unusable_folder(places, tmp_path, capsys, where, message) -> None:
    names = {**places, "nowhere": tmp_path / "nowhere"}
    assert cli.main(["demo", f"out={where.format(**names)}", "gif=false"]) != 0
    line = one_error(capsys, "demo")
    assert message.format(**names) in line
    documented(line, tmp_path)
    assert _written(tmp_path) == {"folder.gif", "dangling", "readonly"}


@needs_permissions
def test_demo_refuses_a_read_only_folder(places, tmp_path, capsys) -> None:
    assert cli.main(["demo", f"out={places['readonly'] / 'demo'}", "gif=false"]) != 0
    assert "is not writable" in one_error(capsys, "demo")
    assert list(places["readonly"].iterdir()) == []


# ------------------------------------------------------------------ fit run folders
@pytest.mark.parametrize(
    ("option", "message"),
    [
        ("runs_dir={afile}", "runs_dir='{afile}': is a file, not a directory"),
        ("runs_dir={afile}/sub", "runs_dir='{afile}/sub': {afile} is a file, not a directory"),
        ("hydra.run.dir={afile}", "hydra.run.dir='{afile}': is a file, not a directory"),
        (
            "hydra.run.dir={dangling}",
            "hydra.run.dir='{dangling}': a symbolic link to '{nowhere}', which does not exist",
        ),
        (
            "hydra.run.dir={afile}/${{now:%H-%M-%S}}",
            "hydra.run.dir='{afile}': is a file, not a directory",
        ),
    ],
)
def test_fit_refuses_an_unusable_run_folder(
    site: Path, places, tmp_path: Path, capsys, monkeypatch, option: str, message: str
) -> None:
    monkeypatch.chdir(tmp_path)
    names = {**places, "nowhere": tmp_path / "nowhere"}
    code = cli.main(["fit", *SMOKE, f"data.cache_dir={tmp_path / 'cache'}", option.format(**names)])
    assert code == 1
    line = one_error(capsys, "fit")
    assert message.format(**names) in line
    documented(line, tmp_path)
    assert places["afile"].read_text() == "not a folder\n"
    assert not (tmp_path / "runs").exists() and not (tmp_path / "cache").exists()


@needs_permissions
def test_fit_refuses_a_read_only_runs_dir(site, places, tmp_path, capsys, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    assert cli.main(["fit", *SMOKE, f"runs_dir={places['readonly']}"]) == 1
    line = one_error(capsys, "fit")
    assert f"the directory {places['readonly']} is not writable" in line


# ---------------------------------------------- retarget: every output before any
@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """``last.ckpt`` of the example aligner after a smoke run (config.yaml beside it)."""
    sys.path.insert(0, str(EXAMPLE_SRC))
    try:
        import skelagnostic_example.plugin as plugin

        pm = PluginManager(load_entrypoints=False)
        pm.register(plugin, "example")
        root = tmp_path_factory.mktemp("trained")
        app.run(
            app.compose(
                [
                    *SMOKE,
                    f"run_dir={root / 'run'}",
                    f"data.cache_dir={root / 'cache'}",
                    "trainer.max_epochs=1",
                    "threads=1",
                ],
                plugin_manager=pm,
            ),
            plugin_manager=pm,
        )
        yield root / "run" / "checkpoints" / "last.ckpt"
    finally:
        sys.path.remove(str(EXAMPLE_SRC))


@pytest.mark.parametrize(
    ("option", "message"),
    [
        ("render={afile}/r.gif", "render='{afile}/r.gif': {afile} is a file, not a directory"),
        ("html={afile}/v.html", "html='{afile}/v.html': {afile} is a file, not a directory"),
        ("render={folder}", "render='{folder}': is a directory; give a file name"),
    ],
)
def test_retarget_checks_every_output_before_writing_any(
    site: Path, trained: Path, places, tmp_path: Path, capsys, option: str, message: str
) -> None:
    out = tmp_path / "result.bvh"
    out.write_text("previous result\n")
    words = ["retarget", str(CLIP), str(CLIP), f"ckpt={trained}", f"out={out}"]
    assert cli.main([*words, option.format(**places)]) == 2
    line = one_error(capsys, "retarget")
    assert message.format(**places) in line
    assert out.read_text() == "previous result\n"  # out= was not written first


@pytest.mark.parametrize(
    ("option", "message"),
    [
        ("fps=1e9", "fps=1e+09: at most 240 frames per second"),
        ("fps=1e-300", "fps=1e-300: at least 1 frame per second"),
        ("size=99999", "size=99999x99999: a panel is at most 4096 pixels a side"),
    ],
)
def test_retarget_with_a_render_refused_late_keeps_the_previous_out(
    site: Path, trained: Path, tmp_path: Path, capsys, option: str, message: str
) -> None:
    """A render option refused only when drawing leaves out= as it was, and no picture."""
    out = tmp_path / "result.bvh"
    out.write_text("previous result\n")
    words = ["retarget", str(CLIP), str(CLIP), f"ckpt={trained}", f"out={out}"]
    assert cli.main([*words, f"render={tmp_path / 'r.gif'}", option, "threads=1"]) == 2
    assert message in one_error(capsys, "retarget")
    assert out.read_text() == "previous result\n"
    assert not (tmp_path / "r.gif").exists()


def test_retarget_refuses_a_folder_as_out(site: Path, trained: Path, tmp_path, capsys) -> None:
    folder = tmp_path / "as_folder.bvh"
    folder.mkdir()
    words = ["retarget", str(CLIP), str(CLIP), f"ckpt={trained}", f"out={folder}"]
    assert cli.main(words) == 2
    line = one_error(capsys, "retarget")
    assert f"out='{folder}': is a directory; give a file name" in line
    documented(line, tmp_path)


# ------------------------------------------------------------ sizes that cannot fit
@pytest.mark.parametrize(
    ("option", "message"),
    [
        ("size=20000x20000", "size=20000x20000: a panel is at most 4096 pixels a side"),
        ("fps=1e9", "fps=1e+09: at most 240 frames per second"),
        ("start=1e308", "option start=1e308: past the end of every clip (the longest lasts"),
        ("start=inf", "option start=inf: must be a number of seconds >= 0"),
        ("frames=100000", "frames=100000: a contact sheet of 4x25000 frames of 320x320 pixels"),
    ],
)
def test_render_refuses_sizes_that_cannot_fit_before_drawing(
    tmp_path: Path, capsys, monkeypatch, option: str, message: str
) -> None:
    import skelagnostic.viz.render as render

    monkeypatch.setattr(render, "Scene", None)  # refused before any figure or frame
    out = "s.png" if option.startswith("frames") else "a.gif"
    assert cli.main(["render", str(CLIP), option, f"out={tmp_path / out}"]) == 2
    line = one_error(capsys, "render")
    assert message in line
    documented(line, tmp_path)
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize(
    ("option", "message"),
    [
        ("fps=1e6", "option fps='1e6': must be above 0 and at most 240"),
        ("fps=nan", "option fps='nan': must be above 0 and at most 240"),
        ("seconds=inf", "option seconds='inf': must be above 0 and at most 600"),
        ("seconds=1e9", "option seconds='1e9': must be above 0 and at most 600"),
        ("seed=-1", "option seed='-1': must be a whole number >= 0"),
    ],
)
def test_demo_refuses_clip_sizes_before_generating(
    tmp_path: Path, capsys, monkeypatch, option: str, message: str
) -> None:
    import skelagnostic.procedural as procedural

    def never(*args: object, **kwargs: object) -> None:
        raise AssertionError("generated before the options were checked")

    monkeypatch.setattr(procedural, "generate", never)
    assert cli.main(["demo", option, f"out={tmp_path / 'demo'}"]) == 2
    line = one_error(capsys, "demo")
    assert message in line
    documented(line, tmp_path)
    assert not (tmp_path / "demo").exists()


def test_procedural_refuses_an_infinite_duration() -> None:
    import skelagnostic as sa

    with pytest.raises(SkelagnosticError, match="must be positive and finite, got inf"):
        sa.procedural.generate(seconds=float("inf"))


def test_end_far_past_the_clip_is_its_end(tmp_path: Path, capsys) -> None:
    out = tmp_path / "a.gif"
    assert cli.main(["render", str(CLIP), "end=1e308", "size=32", f"out={out}"]) == 0
    assert out.is_file()


def test_data_fps_beyond_the_limit_is_one_line(tmp_path: Path) -> None:
    with pytest.raises(SkelagnosticError, match=r"data\.fps=1e\+06: .* at most 1000") as info:
        MotionDataModule(fps=1e6, cache_dir=tmp_path)
    documented(str(info.value), tmp_path)
    with pytest.raises(SkelagnosticError, match=r"data\.fps=nan"):
        MotionDataModule(fps=float("nan"), cache_dir=tmp_path)


def test_fit_with_data_fps_1e6_is_one_line(site: Path, tmp_path: Path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code = cli.main(["fit", *SMOKE, "data.fps=1e6", f"data.cache_dir={tmp_path / 'cache'}"])
    assert code == 1
    assert "data.fps=1e+06: must be a number of frames per second of at most 1000" in one_error(
        capsys, "fit"
    )


# ---------------------------------------------------------------------- threads=
@pytest.fixture
def set_threads(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """The counts torch.set_num_threads is called with (not passed on to torch)."""
    calls: list[int] = []
    monkeypatch.setattr(torch, "set_num_threads", calls.append)
    return calls


def test_threads_above_four_per_core_are_refused(set_threads: list[int]) -> None:
    from skelagnostic.cli.render import max_threads

    limit = max_threads()
    assert limit == LIMIT
    for value in ("99999", str(limit + 1), "9" * 40):
        with pytest.raises(SkelagnosticError, match=rf"threads={value}: at most {limit} \(4 per"):
            apply_threads({"threads": value})
    apply_threads({"threads": str(limit)})
    assert set_threads == [limit]  # torch only ever saw the valid count


def machine_free(line: str) -> str:
    """``line`` with this machine's thread limit and core count as placeholders."""
    cores = os.cpu_count() or 1
    return line.replace(
        f"at most {LIMIT} (4 per CPU core; this machine has {cores})",
        "at most <4 x cores> (4 per CPU core; this machine has <cores>)",
    )


@pytest.mark.parametrize(
    ("verb", "words"),
    [
        ("render", [str(CLIP)]),
        ("retarget", [str(CLIP), str(CLIP), "ckpt=x.ckpt", "out=y.bvh"]),
        ("interpolate", [str(CLIP), "ckpt=x.ckpt", "every=2", "out=y.bvh"]),
        ("transfer", [str(CLIP), str(CLIP), "ckpt=x.ckpt", "out=y.bvh"]),
        ("demo", []),
        ("export", ["ckpt_path=x.ckpt", "format=onnx"]),
    ],
)
def test_file_verbs_refuse_threads_99999(
    verb: str, words: list[str], tmp_path: Path, capsys, monkeypatch, set_threads
) -> None:
    monkeypatch.chdir(tmp_path)
    assert cli.main([verb, *words, "threads=99999"]) == 2
    line = one_error(capsys, verb)
    assert f"option threads=99999: at most {LIMIT} (4 per CPU core" in line
    assert set_threads == []
    documented(machine_free(line), tmp_path)
    assert not list(tmp_path.iterdir())


def test_fit_refuses_threads_99999(site: Path, tmp_path: Path, capsys, monkeypatch, set_threads):
    monkeypatch.chdir(tmp_path)
    code = cli.main(["fit", *SMOKE, "threads=99999", f"data.cache_dir={tmp_path / 'cache'}"])
    assert code == 1
    line = one_error(capsys, "fit")
    assert f"threads=99999: at most {LIMIT} (4 per CPU core" in line
    assert set_threads == []
    documented(machine_free(line), tmp_path)
