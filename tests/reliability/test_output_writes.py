"""CLI outputs on a full disk, and renders whose memory does not grow with the clip.

A full disk is simulated two portable ways, without privileges: a file-size limit
(``RLIMIT_FSIZE``, set in a child process: writes past it fail with ``EFBIG``) and
a file object whose writes raise ``ENOSPC`` midway. Either way the previous file
must survive, no temporary file may be left, and the verb prints one line naming
the output and the cause (issue 47, item 4). Renders stream their frames to the
encoder, so the peak memory of a 4x longer clip stays within a margin (item 6).
"""

from __future__ import annotations

import errno
import io
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from omegaconf import OmegaConf

import skelagnostic as sa
from skelagnostic import cli
from skelagnostic.callbacks.fit_summary import FitSummary
from skelagnostic.errors import SkelagnosticError

REPO = Path(__file__).resolve().parents[2]
TROUBLESHOOTING = REPO / "docs" / "troubleshooting.md"
OLD = "the previous content\n"
resource = pytest.importorskip("resource")  # POSIX: RLIMIT_FSIZE


def documented(line: str, tmp_path: Path) -> None:
    """``line`` (with ``<tmp>`` for the test's folder) is quoted in docs/troubleshooting.md."""
    text = line.replace(str(tmp_path), "<tmp>")
    assert text in TROUBLESHOOTING.read_text(encoding="utf-8"), text


@pytest.fixture
def clip(tmp_path: Path) -> Path:
    motion, _ = sa.procedural.generate("biped22", "walk", seconds=0.5, fps=30)
    path = tmp_path / "in" / "walk.bvh"
    path.parent.mkdir()
    sa.write_bvh(motion, path)
    return path


def run_limited(
    args: list[str], limit: int, cwd: Path, env: dict[str, str] | None = None
) -> subprocess.CompletedProcess[str]:
    """``skelagnostic ARGS`` in a child whose files cannot grow past ``limit`` bytes.

    The modules a render needs are imported before the limit is set, so only the
    verb's own outputs meet it.
    """
    script = textwrap.dedent(
        f"""
        import resource, sys
        import PIL.GifImagePlugin, PIL.PngImagePlugin, rich.progress
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from skelagnostic import cli
        import skelagnostic.viz, skelagnostic.viz.html, skelagnostic.cli.render
        resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, resource.RLIM_INFINITY))
        sys.exit(cli.main(sys.argv[1:]))
        """
    )
    env = env or {**os.environ, "PYTHONPATH": str(REPO / "src"), "OMP_NUM_THREADS": "1"}
    return subprocess.run(
        [sys.executable, "-c", script, *args],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )


@pytest.mark.parametrize(
    ("name", "extra", "limit"),
    [
        ("view.html", [], 64 * 1024),  # the page inlines three.js: far more than 64 KiB
        ("anim.gif", ["size=200"], 1024),
        ("sheet.png", ["size=200"], 1024),
    ],
)
def test_render_on_a_full_disk_keeps_the_previous_file(
    clip: Path, tmp_path: Path, name: str, extra: list[str], limit: int
) -> None:
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    out = out_dir / name
    out.write_text(OLD)
    result = run_limited(["render", str(clip), f"out={out}", *extra], limit, tmp_path)
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr
    assert result.stderr.strip().splitlines() == [
        f"skelagnostic render: error: out='{out}': cannot write (File too large); "
        "the previous file is unchanged"
    ]
    assert out.read_text() == OLD
    assert sorted(p.name for p in out_dir.iterdir()) == [name]  # no temporary file left
    documented(result.stderr.strip(), tmp_path)


def test_demo_on_a_full_disk_is_one_line(tmp_path: Path) -> None:
    out = tmp_path / "demo"
    result = run_limited(["demo", f"out={out}", "gif=false", "seconds=0.3"], 2048, tmp_path)
    assert result.returncode != 0
    assert "Traceback" not in result.stderr
    (line,) = result.stderr.strip().splitlines()
    assert line.startswith("skelagnostic demo: error: ") and "File too large" in line
    assert not [p for p in out.rglob("*") if p.name.endswith(".tmp")]


def test_fit_on_a_full_disk_is_one_line(tmp_path: Path, cli_env: dict[str, str]) -> None:
    # Hydra writes the run folder's .hydra/ files before any skelagnostic code runs
    args = ["fit", "model=example", "experiment=smoke", "threads=1", f"runs_dir={tmp_path}/r"]
    result = run_limited(args, 300, tmp_path, env=cli_env)
    assert result.returncode == 1
    assert "Traceback" not in result.stderr
    lines = [ln for ln in result.stderr.splitlines() if ln.startswith("skelagnostic fit:")]
    assert lines == ["skelagnostic fit: error: cannot read or write a file: File too large"]
    documented(lines[0], tmp_path)


class _FullDisk(io.RawIOBase):
    """A binary file whose writes fail with ``ENOSPC`` once ``room`` bytes are written."""

    def __init__(self, inner: Any, room: int) -> None:
        self.inner, self.room = inner, room

    def writable(self) -> bool:
        return True

    def write(self, data: Any) -> int:
        data = bytes(data)
        if len(data) > self.room:
            self.inner.write(data[: self.room])  # part of it reaches the disk
            self.room = 0
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        self.room -= len(data)
        return self.inner.write(data)

    def fileno(self) -> int:
        return self.inner.fileno()

    def flush(self) -> None:
        self.inner.flush()

    def close(self) -> None:
        super().close()  # flushes through self.flush while the inner file is open
        self.inner.close()


@pytest.fixture
def full_disk(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every file opened by the atomic writer runs out of space after 100 bytes."""
    real = os.fdopen
    monkeypatch.setattr(os, "fdopen", lambda fd, *a, **k: _FullDisk(real(fd, *a, **k), 100))


def _left(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir())


def test_render_html_with_enospc_midway_keeps_the_page(
    clip: Path, tmp_path: Path, capsys, full_disk
) -> None:
    page = tmp_path / "view.html"
    page.write_text(OLD)
    assert cli.main(["render", str(clip), f"out={page}"]) == 2
    err = capsys.readouterr().err
    assert err.splitlines() == [
        f"skelagnostic render: error: out='{page}': cannot write (No space left on device); "
        "the previous file is unchanged"
    ]
    assert page.read_text() == OLD
    assert _left(tmp_path) == ["in", "view.html"]
    documented(err.strip(), tmp_path)


def test_run_files_with_enospc_midway_keep_the_previous_ones(tmp_path: Path, full_disk) -> None:
    from skelagnostic.cli.tasks import _save_config

    (tmp_path / "config.yaml").write_text(OLD)
    with pytest.raises(SkelagnosticError, match=r"config\.yaml'?: cannot write \(No space left"):
        _save_config(OmegaConf.create({"model": {"name": "x" * 500}}), tmp_path)
    assert (tmp_path / "config.yaml").read_text() == OLD

    (tmp_path / "summary.md").write_text(OLD)
    (tmp_path / "metrics.json").write_text(OLD)
    trainer = SimpleNamespace(callback_metrics={"loss": 1.0}, current_epoch=1, global_step=2)
    with pytest.raises(SkelagnosticError, match=r"metrics\.json'?: cannot write \(No space left"):
        FitSummary().write(trainer, {"metrics": {"x" * 200: 1.0}}, tmp_path)  # type: ignore[arg-type]
    assert (tmp_path / "metrics.json").read_text() == OLD
    assert (tmp_path / "summary.md").read_text() == OLD
    assert _left(tmp_path) == ["config.yaml", "metrics.json", "summary.md"]


def test_write_output_failure_names_the_option(tmp_path: Path) -> None:
    from skelagnostic.io.outputs import write_output

    target = tmp_path / "evaluation.json"
    target.write_text(OLD)

    def fail_midway(fh: Any) -> None:
        fh.write(b"{partial")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    with pytest.raises(SkelagnosticError) as info:
        write_output(target, fail_midway, "out")
    assert str(info.value) == (
        f"out='{target}': cannot write (No space left on device); the previous file is unchanged"
    )
    assert target.read_text() == OLD and _left(tmp_path) == ["evaluation.json"]
    with pytest.raises(SkelagnosticError, match="nothing was written"):
        write_output(tmp_path / "new.json", fail_midway)
    assert _left(tmp_path) == ["evaluation.json"]


# --------------------------------------------------------------- flat render memory
# VmHWM (the peak resident set of this process image) rather than ru_maxrss, which
# Linux carries over from the forking parent (here the test process) across exec.
PEAK = """
import json, sys
import numpy as np
from skelagnostic.viz import StickFigure, render_motion
frames = int(sys.argv[1])
t = np.arange(frames)[:, None] / 30.0
legs = [np.hstack([np.sin(t + k), 0 * t + 1.0 - 0.2 * k, np.cos(t * k)]) for k in range(6)]
figure = StickFigure(np.stack(legs, 1), parents=[-1, 0, 1, 0, 3, 0], fps=30.0)
render_motion(figure, sys.argv[2], size=(256, 256))
status = open("/proc/self/status").read().split("VmHWM:")[1]
print(json.dumps(int(status.split()[0])))
"""


def _peak_kib(frames: int, out: Path) -> int:
    env = {**os.environ, "PYTHONPATH": str(REPO / "src"), "OMP_NUM_THREADS": "1"}
    result = subprocess.run(
        [sys.executable, "-c", PEAK, str(frames), str(out)],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        check=True,
    )
    return int(json.loads(result.stdout.strip().splitlines()[-1]))


@pytest.mark.skipif(sys.platform != "linux", reason="reads VmHWM in /proc/self/status")
def test_render_memory_is_flat_in_the_clip_length(tmp_path: Path) -> None:
    # 256x256 RGB frames are 192 KiB: keeping 450 more of them (as the frame list did)
    # costs > 80 MiB; streamed, the longer clip only adds its joint positions.
    short = _peak_kib(150, tmp_path / "short.gif")
    long = _peak_kib(600, tmp_path / "long.gif")
    assert long - short < 30 * 1024, (short, long)
    from PIL import Image

    with Image.open(tmp_path / "long.gif") as gif:
        assert gif.n_frames == 600 and gif.size == (256, 256)


def test_long_renders_show_progress_on_a_terminal(
    clip: Path, tmp_path: Path, capsys, monkeypatch
) -> None:
    monkeypatch.setenv("FORCE_COLOR", "1")
    monkeypatch.setenv("TTY_COMPATIBLE", "1")
    monkeypatch.setattr("skelagnostic.viz.render.PROGRESS_FRAMES", 10)
    out = tmp_path / "a.gif"
    assert cli.main(["render", str(clip), f"out={out}", "size=32"]) == 0
    assert "render a.gif" in capsys.readouterr().err
    monkeypatch.setattr("skelagnostic.viz.render.PROGRESS_FRAMES", 1000)  # a short render
    assert cli.main(["render", str(clip), f"out={out}", "size=32"]) == 0
    assert "render a.gif" not in capsys.readouterr().err


def test_new_plugin_on_a_full_disk_leaves_no_half_package(
    tmp_path: Path, capsys, full_disk
) -> None:
    from skelagnostic.cli import new_plugin

    target = tmp_path / "pkg"
    assert new_plugin.main(["tiny", "--dir", str(target)]) == 1
    err = capsys.readouterr().err
    assert err.splitlines() == [
        f"skelagnostic new-plugin: error: --dir='{target}': cannot write pyproject.toml "
        "(No space left on device); nothing was left behind"
    ]
    assert _left(tmp_path) == []
    documented(err.strip(), tmp_path)
