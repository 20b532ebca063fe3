"""Suite ``startup``: how long the light commands take against ``python -c "import torch"``.

Issue 48 (item 10) sets the goal: ``plugins``, ``render``, ``retarget --help`` and
``fit --help`` each under 2x the time of ``python -c "import torch"`` measured in
the same run, and the inference verbs never import Lightning. Each command runs
as a user runs it, ``python -m skelagnostic.cli ...`` in a fresh process (that dies
with this one); the rounds alternate the commands (torch, lightning, plugins,
render, ...), so a machine that speeds up or slows down during the run moves every
command alike.

Figures per command ``<cmd>`` (``plugins``, ``render``, ``retarget_help``,
``fit_help``, and ``import_lightning``, ``python -c "import lightning"``, the
floor of every command that imports Lightning):

* ``<cmd>_s``: the median wall time of the command, with the median of
  ``python -c "import torch"`` as its baseline (``speedup`` below 0.5 misses the
  goal);
* ``<cmd>_x_torch``: the median over the rounds of the command's time divided by
  the same round's ``import torch`` (the goal is under 2);
* ``<cmd>_meets_2x``: 1 when that median ratio is under 2, else 0;
* ``<cmd>_imports_lightning``: 1 when the command imported ``lightning``
  (``python -X importtime``, a separate run), else 0.

``render`` draws a 2 s procedural biped walk (60 frames at 30 fps) to a PNG contact
sheet. ``default`` runs 3 rounds after a warm-up round, ``large`` 9; ``--size smoke``
(the tests' check of the format) one round of ``import torch`` and ``retarget --help``
only, the two fastest.
"""

from __future__ import annotations

import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.harness import REPO_ROOT, Result, run_process

ROUNDS = {"smoke": 1, "default": 3, "large": 9}
WARMUP = {"smoke": 0, "default": 1, "large": 1}
#: The goal: each command under this many times ``import torch``.
GOAL_RATIO = 2.0
BASELINE = "python -c 'import torch'"
#: The commands of ``--size smoke``.
SMOKE = ("import_torch", "retarget_help")


def _env() -> dict[str, str]:
    """This process's environment, with the checkout's sources first on ``PYTHONPATH``."""
    env = dict(os.environ)
    paths = [str(REPO_ROOT / "src")]
    paths += sorted(str(p) for p in (REPO_ROOT / "plugins").glob("*/src"))
    env["PYTHONPATH"] = os.pathsep.join([*paths, *filter(None, [env.get("PYTHONPATH")])])
    return env


def commands(work: Path) -> dict[str, list[str]]:
    """Name -> the arguments after ``python`` (the first is the ``import torch`` baseline)."""
    import skelagnostic as sa

    motion, _ = sa.procedural.generate("biped22", "walk", seconds=2.0, fps=30.0, seed=0)
    clip = work / "walk.bvh"
    sa.write_bvh(motion, clip)
    cli = ["-m", "skelagnostic.cli"]
    return {
        "import_torch": ["-c", "import torch"],
        "import_lightning": ["-c", "import lightning"],
        "plugins": [*cli, "plugins"],
        "render": [*cli, "render", str(clip), f"out={work / 'walk.png'}"],
        "retarget_help": [*cli, "retarget", "--help"],
        "fit_help": [*cli, "fit", "--help"],
    }


def _seconds(argv: list[str], cwd: Path) -> float:
    """Wall time of ``python ARGV`` in a fresh process; a failure raises."""
    start = time.perf_counter()
    proc = run_process([sys.executable, *argv], cwd=cwd, env=_env())
    seconds = time.perf_counter() - start
    if proc.returncode != 0:
        raise RuntimeError(
            f"startup suite: 'python {' '.join(argv)}' failed (exit {proc.returncode}):\n"
            f"{proc.stderr[-3000:]}"
        )
    return seconds


def imports_lightning(argv: list[str], cwd: Path) -> bool:
    """Whether ``python ARGV`` imports ``lightning`` (from ``python -X importtime``)."""
    proc = run_process([sys.executable, "-X", "importtime", *argv], cwd=cwd, env=_env())
    if proc.returncode != 0:
        raise RuntimeError(f"startup suite: 'python {' '.join(argv)}' failed:\n{proc.stderr}")
    return any(line.rsplit("|", 1)[-1].strip() == "lightning" for line in proc.stderr.splitlines())


def run(size: str) -> list[Result]:
    """Run the suite at ``size`` and return its results."""
    rounds, warmup = ROUNDS[size], WARMUP[size]
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        cmds = commands(work)
        if size == "smoke":
            cmds = {name: cmds[name] for name in SMOKE}
        times: dict[str, list[float]] = {name: [] for name in cmds}
        for index in range(warmup + rounds):
            for name, argv in cmds.items():
                seconds = _seconds(argv, work)
                if index >= warmup:
                    times[name].append(seconds)
        lightning = {name: imports_lightning(cmds[name], work) for name in cmds}
    torch_s = times.pop("import_torch")
    baseline = statistics.median(torch_s)
    results = [Result("import_torch_s", "s", baseline)]
    for name, measured in times.items():
        ratio = statistics.median(m / t for m, t in zip(measured, torch_s, strict=True))
        results += [
            Result(f"{name}_s", "s", statistics.median(measured), BASELINE, baseline),
            Result(f"{name}_x_torch", "ratio", ratio),
            Result(f"{name}_meets_2x", "bool", float(ratio < GOAL_RATIO)),
            Result(f"{name}_imports_lightning", "bool", float(lightning[name])),
        ]
    return results
