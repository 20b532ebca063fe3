"""DDP for every method plugin: ``fit`` on two CPU processes (gloo) through the CLI.

For each method: the run finishes; the files of the run are written once, by
rank 0 (one run directory, one checkpoint directory, one metrics file, one
config); at the end both ranks hold bitwise the same weights and buffers
(for ``vqpae`` that includes the amplitude codebook shared by the datasets)
and the same validation metrics (logged with ``sync_dist``). The example
aligner's DDP test is ``tests/framework/test_cli.py::test_cli_fit_ddp_two_cpu_processes``;
the codebook's DDP update rule is checked without Lightning in
``tests/vqpae/test_vqpae_codebook.py::test_ddp_ranks_apply_the_same_update_as_one_process``.

The plugins are not installed in the development environment: each run gets
the plugin's ``src`` on ``PYTHONPATH`` and a fake distribution declaring its
entry point (``reliability_env.plugin_env``).

To add a method, append a
:class:`Method` to :data:`METHODS` with model options small enough for a run of
well under a minute, and the names of the state entries that must be shared
(``shared``; every other entry is compared too).
"""

from __future__ import annotations

import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
import torch
from reliability_env import REPO, plugin_env


@dataclass(frozen=True)
class Method:
    """A method plugin and the arguments of a tiny two-process ``fit``.

    Attributes:
        name: Entry-point name (the plugin's folder under ``plugins/``).
        module: Module of its hook implementations.
        args: Overrides making the run small (model, data, trainer).
        shared: State-dict key prefixes that must exist (the state DDP must keep in sync).
        model: ``model=`` name (default: ``name``).
    """

    name: str
    module: str
    args: tuple[str, ...]
    shared: tuple[str, ...] = ()
    model: str | None = None

    @property
    def model_name(self) -> str:
        return self.model or self.name

    @property
    def src(self) -> Path:
        return REPO / "plugins" / self.name / "src"


#: Tiny runs: ``experiment=smoke`` (2 epochs of at most 4 steps, 2 validation batches).
METHODS = [
    Method(
        "humot",
        "skelagnostic_humot.plugin",
        (
            "model.dim=32",
            "model.latent=16",
            "model.blocks=1",
            "model.heads=4",
            "model.kernel_size=3",
            "data.seconds=1.5",
            "data.batch_size=4",
        ),
    ),
    Method(
        "vqpae",
        "skelagnostic_vqpae.plugin",
        (
            "model.num_codes=8",
            "model.kernel_size=7",
            "model.pose_layers=2",
            "data.seconds=2.0",
            "data.clips_per_gait=1",
        ),
        shared=("codebook.",),
    ),
    Method(
        "pcmrl",
        "skelagnostic_pcmrl.plugin",
        (
            "model.dim=8",
            "model.stages=2",
            "model.point_heads=2",
            "model.temporal_dim=16",
            "model.temporal_layers=1",
            "model.temporal_heads=2",
            "model.num_source_points=64",
            "model.num_target_points=128",
            "data.gaits=[walk]",
            "data.clips_per_gait=2",
            "data.seconds=1.5",
            "data.window=12",
            "data.stride=12",
            "data.batch_size=2",
            "data.val_fraction=0.5",
        ),
    ),
    # stage 2: its self-attention blocks hold a memory norm they never use (frozen, else
    # plain ddp stops at the first step on a parameter without a gradient)
    Method(
        "pcmrl",
        "skelagnostic_pcmrl.plugin",
        (
            "model.dim=16",
            "model.heads=2",
            "model.layers=1",
            "data.clips_per_gait=1",
            "data.samples_per_epoch=8",
            "data.batch_size=2",
        ),
        model="pcmrl_interp",
    ),
]


def files_under(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*") if p.is_file())


@pytest.mark.slow
@pytest.mark.parametrize("method", METHODS, ids=lambda m: m.model_name)
def test_fit_ddp_two_cpu_processes(method: Method, tmp_path: Path) -> None:
    env = plugin_env(tmp_path, method.name, method.module, method.src)
    runs, dumps = tmp_path / "runs", tmp_path / "ranks"
    cmd = [
        sys.executable,
        "-m",
        "skelagnostic.cli",
        "fit",
        f"model={method.model_name}",
        "experiment=smoke",
        *method.args,
        "trainer.strategy=ddp",
        "trainer.devices=2",
        "trainer.accelerator=cpu",
        "threads=1",
        "seed=3",
        f"runs_dir={runs}",
        "+callbacks.dump._target_=rank_state.DumpRankState",
        f"+callbacks.dump.path={dumps}",
    ]
    proc = subprocess.run(cmd, env=env, cwd=tmp_path, capture_output=True, text=True, timeout=240)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-4000:]
    assert "Starting with 2 processes" in out and "distributed_backend=gloo" in out

    # rank-zero-only writes: one run directory, one of each output
    (run_dir,) = (runs / method.model_name / "fit").iterdir()
    files = files_under(run_dir)
    assert "train_ddp_process_1.log" in files  # rank 1 re-ran the command line, same dir
    assert sum(f.endswith("metrics.csv") for f in files) == 1, files
    assert sum(f.endswith("config.yaml") and "hydra" not in f for f in files) == 1, files
    checkpoint_dirs = {str(Path(f).parent) for f in files if f.endswith(".ckpt")}
    assert checkpoint_dirs == {"checkpoints"}, files
    assert (run_dir / "checkpoints" / "last.ckpt").is_file()

    # both ranks end with the same replica and the same synchronised metrics
    ranks = [torch.load(dumps / f"rank{r}.pt", weights_only=False) for r in (0, 1)]
    assert [r["world_size"] for r in ranks] == [2, 2]
    a, b = (r["state_dict"] for r in ranks)
    assert a.keys() == b.keys()
    for prefix in method.shared:
        assert any(k.startswith(prefix) for k in a), (prefix, sorted(a))
    for key in a:
        assert torch.equal(a[key], b[key]), key
    val = sorted(k for k in ranks[0]["metrics"] if k.startswith("val/"))
    assert val and val == sorted(k for k in ranks[1]["metrics"] if k.startswith("val/"))
    for key in val:
        torch.testing.assert_close(
            ranks[0]["metrics"][key], ranks[1]["metrics"][key], rtol=1e-5, atol=1e-6, msg=key
        )
    # the checkpoint rank 0 wrote is that replica
    saved = torch.load(
        run_dir / "checkpoints" / "last.ckpt", map_location="cpu", weights_only=False
    )["state_dict"]
    for key in a:
        assert torch.equal(saved[key], a[key]), key
