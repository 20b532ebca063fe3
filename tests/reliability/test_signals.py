"""Signals (issue 47, item 15): one line each, nothing half-written left behind.

* SIGINT (Ctrl+C) during ``fit``: after Lightning's own line, one line naming the
  newest checkpoint and the command that resumes from it (which works).
* SIGTERM while a window-cache entry or ``retarget``'s output is being written:
  no ``.tmp`` file is left, one line, exit code 143.

The SIGTERM cases run the CLI under ``python -m killer PATTERN ...``, which sends
SIGTERM to the process just before the atomic writer renames a finished
temporary file onto a path containing ``PATTERN``.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import lightning as L
import pytest
import torch
from reliability_env import EVERY_STEP, EXAMPLE_SRC, REPO, SMALL

from skelagnostic.cli.runs import LOCK_FILE

CLIP = REPO / "tests" / "badinput" / "corpus" / "valid_small.bvh"


def cli(
    env: dict[str, str], cwd: Path, *args: str, killer: str | None = None
) -> subprocess.CompletedProcess:
    """``skelagnostic ARGS`` in a subprocess (under ``python -m killer KILLER`` if given)."""
    prefix = ["-m", "killer", killer] if killer else ["-m", "skelagnostic.cli"]
    return subprocess.run(
        [sys.executable, *prefix, *args],
        env=env,
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=300,
    )


def temporaries(root: Path) -> list[Path]:
    return [p for p in root.rglob("*") if p.name.endswith(".tmp")]


@pytest.mark.slow
def test_ctrl_c_during_fit_says_how_to_resume(cli_env: dict[str, str], tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    proc = cli(
        cli_env,
        tmp_path,
        "fit",
        *SMALL,
        "trainer.max_steps=8",
        *EVERY_STEP,
        "+callbacks.kill._target_=killer.KillAt",
        "+callbacks.kill.step=3",
        "+callbacks.kill.signum=2",
        f"hydra.run.dir={run_dir}",
    )
    assert proc.returncode != 0
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    lines = proc.stderr.splitlines()
    lightning = next(i for i, s in enumerate(lines) if s.startswith("Detected KeyboardInterrupt"))
    last = run_dir / "checkpoints" / "last.ckpt"
    ours = [s for s in lines if s.startswith("skelagnostic fit: ")]
    assert ours == [
        f"skelagnostic fit: interrupted at step 3; the last checkpoint is {last} (step 2): "
        f"resume with skelagnostic fit ckpt_path={last}"
    ]
    assert lines.index(ours[0]) > lightning
    assert not (run_dir / LOCK_FILE).exists()
    assert torch.load(last, map_location="cpu", weights_only=True)["global_step"] == 2

    # the command the line gives resumes (in a directory of its own) and finishes the run
    resumed = cli(
        cli_env,
        tmp_path,
        "fit",
        f"ckpt_path={last}",
        "threads=1",
        "trainer.max_steps=4",
        "trainer.limit_val_batches=1",
    )
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    runs = [p for p in (tmp_path / "runs" / "example" / "fit").iterdir()]
    assert len(runs) == 1 and (runs[0] / "checkpoints" / "last.ckpt").is_file()
    state = torch.load(runs[0] / "checkpoints" / "last.ckpt", map_location="cpu", weights_only=True)
    assert state["global_step"] == 4


@pytest.mark.slow
def test_sigterm_while_the_window_cache_is_written(cli_env: dict[str, str], tmp_path: Path) -> None:
    cache = Path(cli_env["SKELAGNOSTIC_CACHE"])
    run_dir = tmp_path / "run"
    proc = cli(
        cli_env,
        tmp_path,
        "fit",
        *SMALL,
        "trainer.max_steps=2",
        f"hydra.run.dir={run_dir}",
        killer=str(cache),
    )
    assert proc.returncode == 143, proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    assert [s for s in proc.stderr.splitlines() if s.startswith("skelagnostic")] == [
        "skelagnostic fit: terminated by SIGTERM"
    ]
    assert cache.is_dir() and not temporaries(cache)
    assert not run_dir.exists()  # held only what a run writes at start-up: discarded


@pytest.mark.slow
def test_sigterm_while_retarget_writes_its_output(cli_env: dict[str, str], tmp_path: Path) -> None:
    sys.path.insert(0, str(EXAMPLE_SRC))
    try:
        from skelagnostic_example import ExampleAligner
    finally:
        sys.path.remove(str(EXAMPLE_SRC))
    model = ExampleAligner(hidden=8, latent=4)
    ckpt = tmp_path / "model.ckpt"
    torch.save(
        {
            "state_dict": model.state_dict(),
            "hyper_parameters": dict(model.hparams),
            "pytorch-lightning_version": L.__version__,
        },
        ckpt,
    )
    out = tmp_path / "out" / "moved.bvh"
    out.parent.mkdir()
    out.write_text("the previous output\n")
    args = ["retarget", str(CLIP), str(CLIP), f"ckpt={ckpt}", "model=example", f"out={out}"]
    proc = cli(cli_env, tmp_path, *args, killer="moved.bvh")
    assert proc.returncode == 143, proc.stderr[-3000:]
    assert proc.stderr.splitlines() == [
        "skelagnostic retarget: terminated by SIGTERM; files still being written were "
        "discarded (none is left half-written)"
    ]
    assert sorted(p.name for p in out.parent.iterdir()) == ["moved.bvh"]
    assert out.read_text() == "the previous output\n"
    done = cli(cli_env, tmp_path, *args)  # without the signal the same command succeeds
    assert done.returncode == 0, done.stderr[-3000:]
    assert out.read_text().startswith("HIERARCHY")
