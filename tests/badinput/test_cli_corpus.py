"""The whole bad-input corpus through the installed ``skelagnostic`` command: no tracebacks.

Every file of ``tests/badinput/corpus`` (the directory is listed, so files
added later are included), bad checkpoints and bad command-line values run as
real processes of the console script (``python -m skelagnostic.cli`` without
it), two at a time. Each must end with a short error on stderr (at most three
lines besides Lightning's own start-up messages, which a run that fails while
reading its data prints first), no traceback, and, for input that is bad, a
non-zero exit code. The in-process tests (test_badinput.py, test_checkpoints.py,
test_config_errors.py) check every file and checkpoint with every verb and the
exact lines; this test runs each case through one verb, rotating, so that every
verb is used and the run stays around two minutes.
"""

from __future__ import annotations

import os
import random
import shutil
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import pytest
import torch
from test_badinput import CORPUS, REPO, SMOKE, documented

import skelagnostic as sa
from skelagnostic import cli
from skelagnostic.cli import app
from skelagnostic.errors import SkelagnosticError
from skelagnostic.plugins import PluginManager

TRAIN_VERBS = ("fit", "validate", "test", "predict")
INFER_VERBS = ("retarget", "interpolate", "transfer")
BVH_VERBS = ("retarget", "interpolate", "transfer", "render", "demo")
#: Bad checkpoints, in the order of the verbs they go through (fit, validate, ... transfer).
CHECKPOINTS = ("missing", "payload", "architecture", "random", "empty", "other_model", "truncated")
MAX_STDERR_LINES = 3
#: Informational lines Lightning writes to stderr when a run starts (not errors).
LIGHTNING_INFO = (
    "Seed set to ",
    "GPU available: ",
    "TPU available: ",
    "💡 Tip: ",
    "Restoring states from the checkpoint path at ",
)
EXAMPLE_SRC = REPO / "plugins" / "example-aligner" / "src"


@dataclass
class Case:
    """One command line and whether it must fail."""

    name: str
    argv: list[str]
    bad: bool = True


@pytest.fixture(scope="module")
def workdir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A trained example checkpoint, bad checkpoints made from it, and a plugin site."""
    root = tmp_path_factory.mktemp("corpus")
    dist = root / "site" / "skelagnostic_example_aligner-0.1.0.dist-info"  # as conftest.site
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text(
        "Metadata-Version: 2.1\nName: skelagnostic-example-aligner\nVersion: 0.1.0\n"
    )
    (dist / "entry_points.txt").write_text(
        "[skelagnostic]\nexample = skelagnostic_example.plugin\n"
    )
    sys.path.insert(0, str(EXAMPLE_SRC))
    try:
        import skelagnostic_example.plugin as plugin

        pm = PluginManager(load_entrypoints=False)
        pm.register(plugin, "example")
        app.run(
            app.compose(
                [
                    *SMOKE,
                    f"run_dir={root / 'run'}",
                    f"data.cache_dir={root / 'c'}",
                    "trainer.max_epochs=1",
                    "logger=none",
                ],
                plugin_manager=pm,
            ),
            plugin_manager=pm,
        )
    finally:
        sys.path.remove(str(EXAMPLE_SRC))
    good = root / "run" / "checkpoints" / "last.ckpt"
    data = good.read_bytes()
    (root / "empty.ckpt").write_bytes(b"")
    (root / "truncated.ckpt").write_bytes(data[: len(data) // 2])
    (root / "random.ckpt").write_bytes(random.Random(1).randbytes(8192))
    checkpoint = torch.load(good, map_location="cpu", weights_only=True)
    for kind in ("other_model", "architecture"):
        shutil.copy(good, root / f"{kind}.ckpt")
    checkpoint["hyper_parameters"]["note"] = _Payload(root / "pwned")
    torch.save(checkpoint, root / "payload.ckpt")
    return root


class _Payload:
    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self) -> tuple[object, tuple[str]]:
        return os.system, (f"touch {self.marker}",)


def _command() -> list[str]:
    script = Path(sys.executable).with_name("skelagnostic")
    return [str(script)] if script.is_file() else [sys.executable, "-m", "skelagnostic.cli"]


def _env(root: Path) -> dict[str, str]:
    paths = [root / "site", EXAMPLE_SRC, REPO / "src", REPO / "plugins" / "humot" / "src"]
    inherited = os.environ.get("PYTHONPATH", "")
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([*map(str, paths), inherited]),
        "SKELAGNOSTIC_LOAD_PLUGINS": "example,humot",
        "OMP_NUM_THREADS": "1",
    }
    for name in ("SKELAGNOSTIC_DEBUG", "HYDRA_FULL_ERROR"):
        env.pop(name, None)
    return env


def _readable(path: Path) -> bool:
    try:
        sa.read_bvh(path)
    except SkelagnosticError:
        return False
    return True


def bvh_cases(root: Path) -> list[Case]:
    """Every corpus file through one verb, rotating over ``fit`` and the BVH verbs."""
    valid = str(CORPUS / "valid_small.bvh")
    ckpt = root / "run" / "checkpoints" / "last.ckpt"
    cases = []
    files = sorted(p for p in CORPUS.iterdir() if p.is_file())
    for i, path in enumerate(files):
        out = root / "out" / path.stem
        verb = ("fit", *BVH_VERBS)[i % (len(BVH_VERBS) + 1)]
        argv = {
            "fit": [
                "fit",
                *SMOKE,
                "data=bvh",
                f"data.paths=[{path}]",
                f"runs_dir={out}/runs",
                f"data.cache_dir={out}/cache",
            ],
            "retarget": ["retarget", str(path), valid, f"ckpt={ckpt}", f"out={out}/r.bvh"],
            "interpolate": [
                "interpolate",
                str(path),
                f"ckpt={ckpt}",
                "every=2",
                f"out={out}/i.bvh",
            ],
            "transfer": ["transfer", valid, str(path), f"ckpt={ckpt}", f"out={out}/t.bvh"],
            "render": ["render", str(path), f"out={out}/r.png", "size=48", "max_frames=2"],
            "demo": ["demo", str(path), "--out", f"{out}/demo", "--no-gif"],
        }[verb]
        # a readable file may be fine for a verb (and then run as usual); it still must not
        # end in a traceback
        cases.append(Case(f"{verb} {path.name}", argv, not _readable(path)))
    return cases


def checkpoint_cases(root: Path) -> list[Case]:
    """Each bad checkpoint through one verb (seven kinds, seven verbs)."""
    clip = str(CORPUS / "valid_small.bvh")
    cases = []
    for kind, verb in zip(CHECKPOINTS, (*TRAIN_VERBS, *INFER_VERBS), strict=True):
        ckpt = root / f"{kind}.ckpt"
        out = root / "out" / kind
        if verb in TRAIN_VERBS:
            model = list(SMOKE)
            if kind == "other_model":
                model = ["model=humot"]
            elif kind == "architecture":
                model = [*SMOKE[:-2], "model.hidden=16", "model.latent=4"]
            cases.append(
                Case(
                    f"{verb} {kind}",
                    [
                        verb,
                        *model,
                        f"ckpt_path={ckpt}",
                        f"runs_dir={out}/runs",
                        f"data.cache_dir={out}/cache",
                    ],
                )
            )
            continue
        inputs = [clip, "every=2"] if verb == "interpolate" else [clip, clip]
        name = "model=humot" if kind == "other_model" else "model=example"
        cases.append(
            Case(f"{verb} {kind}", [verb, *inputs, f"ckpt={ckpt}", name, f"out={out}/o.bvh"])
        )
    return cases


def value_cases(root: Path) -> list[Case]:
    """Bad command-line values."""
    out = root / "out" / "values"
    common = [f"runs_dir={out}/runs", f"data.cache_dir={out}/cache"]
    clip = str(CORPUS / "valid_small.bvh")
    ckpt = root / "run" / "checkpoints" / "last.ckpt"
    return [
        Case(" ".join(argv[:2]), argv)
        for argv in (
            ["fit", *SMOKE, "trainer.devices=abc", *common],
            ["fit", "model=nope", *common],
            ["validate", *SMOKE, "data=nope", *common],
            ["test", *SMOKE, "model.hidden=big", *common],
            ["predict", *SMOKE, "trainer.max_epochs=ten", *common],
            ["fit", *SMOKE, "callbacks=nope", *common],
            ["fit", *SMOKE, "data.batch_size=abc", *common],
            ["interpolate", clip, f"ckpt={ckpt}", "every=abc", f"out={out}/o.bvh"],
            ["retarget", clip, clip, f"ckpt={ckpt}", "speed=2", f"out={out}/o.bvh"],
            ["nope"],
        )
    ]


def _run(case: Case, root: Path) -> tuple[Case, subprocess.CompletedProcess[str]]:
    done = subprocess.run(
        [*_command(), *case.argv],
        env=_env(root),
        cwd=root,
        capture_output=True,
        text=True,
        timeout=300,
    )
    return case, done


@pytest.mark.slow
def test_whole_corpus_gives_no_traceback(workdir: Path) -> None:
    cases = [*bvh_cases(workdir), *checkpoint_cases(workdir), *value_cases(workdir)]
    verbs = {case.argv[0] for case in cases}
    assert {*TRAIN_VERBS, *BVH_VERBS} <= verbs
    with ThreadPoolExecutor(max_workers=2) as pool:
        results = list(pool.map(lambda case: _run(case, workdir), cases))
    failures = []
    for case, done in results:
        lines = [line for line in done.stderr.splitlines() if not line.startswith(LIGHTNING_INFO)]
        problems = []
        if "Traceback" in done.stderr or "Error executing job" in done.stderr:
            problems.append("traceback")
        if case.bad and len(lines) > MAX_STDERR_LINES:  # a good input may train and log
            problems.append(f"{len(lines)} lines on stderr")
        if case.bad and done.returncode == 0:
            problems.append("exit code 0")
        if problems:
            failures.append(f"{case.name}: {', '.join(problems)}\n{done.stderr[-2000:]}")
    assert not (workdir / "pwned").exists()
    if failures:
        pytest.fail(
            f"{len(failures)} of {len(cases)} cases:\n\n" + "\n\n".join(failures), pytrace=False
        )


@pytest.mark.parametrize("name", ["single_joint.bvh", "all_bones_zero.bvh"])
@pytest.mark.parametrize("position", [0, 1])
def test_retarget_with_a_skeleton_of_height_zero(
    site: Path,
    workdir: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    name: str,
    position: int,
) -> None:
    paths = [str(CORPUS / "valid_small.bvh")] * 2
    paths[position] = str(CORPUS / name)
    ckpt = workdir / "run" / "checkpoints" / "last.ckpt"
    assert cli.main(["retarget", *paths, f"ckpt={ckpt}", f"out={tmp_path / 'o.bvh'}"]) == 2
    err = capsys.readouterr().err.strip()
    joints = {"single_joint.bvh": 1, "all_bones_zero.bvh": 4}[name]
    assert err == (
        f"skelagnostic retarget: error: model=example: skeleton '{name[:-4]}' has "
        f"height 0 ({joints} joint(s), no bone of non-zero length); the example "
        "aligner normalises positions by the skeleton height"
    )
    assert not (tmp_path / "o.bvh").exists()
    documented(err, tmp_path)
