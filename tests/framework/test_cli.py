"""Config composition, run(cfg), the CLI verbs, DDP and the wheel-installed CLI."""

from __future__ import annotations

import csv
import os
import re
import shutil
import subprocess
import sys
import venv
from importlib import resources
from pathlib import Path

import pytest
import torch

import skelagnostic.plugins as plugins
from skelagnostic import cli
from skelagnostic.callbacks import EMAWeights
from skelagnostic.cli import app
from skelagnostic.errors import SkelagnosticError

REPO = Path(__file__).resolve().parents[2]
FAST = [
    "experiment=smoke",
    "data.seconds=2.0",
    "data.clips_per_gait=1",
    "data.window=16",
    "data.stride=8",
    "model.hidden=16",
    "model.latent=4",
]


def group_options() -> list[tuple[str, str]]:
    conf = resources.files("skelagnostic.conf")
    return [
        (group.name, f.name.removesuffix(".yaml"))
        for group in conf.iterdir()
        if group.is_dir() and not group.name.startswith("_")
        for f in group.iterdir()
        if f.name.endswith(".yaml") and not f.name.startswith("_")
    ]


def test_compose_defaults(example_plugin: Path) -> None:
    cfg = app.compose(["model=example", "run_dir=/tmp/x"])
    assert cfg.task == "fit" and cfg.model.name == "example" and cfg.model.hidden == 64
    assert cfg.data.source == "procedural" and cfg.trainer.accelerator == "cpu"
    assert set(cfg.callbacks) == {"model_checkpoint", "rich_progress_bar", "fit_summary"}
    assert cfg.callbacks.model_checkpoint.dirpath == "/tmp/x/checkpoints"
    assert cfg.callbacks.fit_summary.name == "example"
    assert set(cfg.logger) == {"csv"}


def test_every_packaged_option_composes(example_plugin: Path) -> None:
    options = group_options()
    assert {g for g, _ in options} == {
        "data",
        "trainer",
        "callbacks",
        "logger",
        "experiment",
        "debug",
    }
    for group, option in options:
        cfg = app.compose(["model=example", "run_dir=/tmp/x", f"{group}={option}"])
        if group == "data":
            assert cfg.data.source == option
        if group == "trainer" and option == "ddp":
            assert cfg.trainer.strategy == "ddp" and cfg.trainer.devices == 2


def test_plugin_config_path_adds_experiments(example_plugin: Path) -> None:
    cfg = app.compose(["experiment=example_quick", "run_dir=/tmp/x"])
    assert cfg.model.name == "example" and cfg.model.hidden == 32


def test_build_datamodule_routes_keys(example_plugin: Path, tmp_path: Path) -> None:
    pm = plugins.get_plugin_manager()
    cfg = app.compose(
        [
            "model=example",
            "run_dir=/tmp/x",
            "data.seconds=1.5",
            "data.window=12",
            "data.representation=point_cloud",
            "+data.representation_options={num_points: 10}",
        ]
    )
    dm = app.build_datamodule(cfg, pm)
    assert dm.window == 12 and dm.sources[0].seconds == 1.5
    assert dm.representation.num_points == 10
    cfg = app.compose(["model=example", "run_dir=/tmp/x", "+data.bogus=1"])
    with pytest.raises(
        app.ConfigError,
        match=r"data\.bogus is not an option of "
        r"data\.source='procedural'",
    ):
        app.build_datamodule(cfg, pm)
    # the data config, not the constructors' signatures, says where a key goes
    assert list(cfg.data.source_keys) == [
        "kinds", "gaits", "clips_per_gait", "seconds", "seed", "name", "test_clips_per_gait"
    ]  # fmt: skip
    cfg = app.compose(
        ["model=example", "run_dir=/tmp/x", "data.source_keys=[kinds,gaits,clips_per_gait]"]
    )
    with pytest.raises(app.ConfigError, match=r"data\.seconds is not an option of .* nor of Ex"):
        app.build_datamodule(cfg, pm)  # seconds now goes to the data module, which refuses it
    cfg = app.compose(["model=example", "run_dir=/tmp/x", "data.source_keys=kinds"])
    with pytest.raises(app.ConfigError, match=r"data\.source_keys must be a list"):
        app.build_datamodule(cfg, pm)


def read_metrics(run_dir: Path) -> list[dict[str, str]]:
    with (run_dir / "csv" / "metrics.csv").open() as fh:
        return list(csv.DictReader(fh))


def test_run_fit_resume_validate_predict(example_plugin: Path, tmp_path: Path) -> None:
    common = ["model=example", f"data.cache_dir={tmp_path / 'cache'}", *FAST]
    run_dir = tmp_path / "run"
    metrics = app.run(app.compose([*common, f"run_dir={run_dir}"]))
    assert metrics["val/loss"] > 0
    for name in (
        "checkpoints/best.ckpt",
        "checkpoints/last.ckpt",
        "csv/metrics.csv",
        "config.yaml",
    ):
        assert (run_dir / name).is_file(), name
    saved = (run_dir / "config.yaml").read_text()
    assert f"run_dir: {run_dir}" in saved and "${" not in saved
    assert {row["epoch"] for row in read_metrics(run_dir)} == {"0", "1"}

    resumed = tmp_path / "resumed"
    app.run(
        app.compose(
            [
                *common,
                f"run_dir={resumed}",
                "trainer.max_epochs=3",
                f"ckpt_path={run_dir / 'checkpoints' / 'last.ckpt'}",
            ]
        )
    )
    assert {row["epoch"] for row in read_metrics(resumed)} == {"2"}  # epochs 0-1 restored

    best = run_dir / "checkpoints" / "best.ckpt"
    val = app.run(
        app.compose([*common, f"run_dir={tmp_path / 'val'}", f"ckpt_path={best}"], task="validate")
    )
    assert val["val/loss"] == pytest.approx(
        min(float(r["val/loss"]) for r in read_metrics(run_dir) if r["val/loss"]), rel=1e-4
    )
    app.run(
        app.compose([*common, f"run_dir={tmp_path / 'pred'}", f"ckpt_path={best}"], task="predict")
    )
    preds = torch.load(tmp_path / "pred" / "predictions.pt")
    assert [list(p[0]) for p in preds] == [["procedural/biped22"], ["procedural/quadruped"]]
    assert preds[0][0]["procedural/biped22"].shape[-1] == 4

    model = plugins.load_aligner("example", checkpoint=best)
    assert model.hparams.hidden == 16


def test_fit_without_validation_still_checkpoints_every_epoch(
    example_plugin: Path, tmp_path: Path
) -> None:
    """No validation batch: the ``val/loss`` checkpoint keeps the latest epoch (not nothing)."""
    run_dir = tmp_path / "run"
    app.run(
        app.compose(
            [
                "model=example",
                f"data.cache_dir={tmp_path / 'cache'}",
                *FAST,
                f"run_dir={run_dir}",
                "trainer.limit_val_batches=0",
                "trainer.max_epochs=1",
            ]
        )
    )
    for name in ("best.ckpt", "last.ckpt"):
        ckpt = torch.load(run_dir / "checkpoints" / name, weights_only=False)
        assert ckpt["epoch"] == 0, name
        assert not any("val/" in str(k) for k in ckpt["callbacks"]), name  # monitor switched off


def test_fit_with_late_validation_keeps_monitoring(example_plugin: Path, tmp_path: Path) -> None:
    """Validation data that is not loaded at the start (every 2nd epoch) is not "none"."""
    run_dir = tmp_path / "run"
    app.run(
        app.compose(
            [
                "model=example",
                f"data.cache_dir={tmp_path / 'cache'}",
                *FAST,
                f"run_dir={run_dir}",
                "trainer.max_epochs=2",
                "trainer.check_val_every_n_epoch=2",
                "+trainer.num_sanity_val_steps=0",
            ]
        )
    )
    ckpt = torch.load(run_dir / "checkpoints" / "best.ckpt", weights_only=False)
    assert ckpt["epoch"] == 1
    assert any("val/loss" in str(k) for k in ckpt["callbacks"])  # still monitored


def test_run_rejects_unknown_task(example_plugin: Path) -> None:
    cfg = app.compose(["model=example", "run_dir=/tmp/x"], task="dance")
    with pytest.raises(app.ConfigError, match="task must be one of"):
        app.run(cfg)


def test_usage_lists_the_verbs(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main([]) == 0
    out = capsys.readouterr().out
    for verb in ("fit", "validate", "test", "predict", "plugins", "render"):
        assert f"  {verb}" in out


def test_usage_lists_the_environment_variables_the_modules_read(
    capsys: pytest.CaptureFixture[str],
) -> None:
    from skelagnostic.cli.allocator import ALLOCATOR_ENV
    from skelagnostic.data.cache import CACHE_ENV
    from skelagnostic.data.sources import DATA_ROOT_ENV
    from skelagnostic.plugins.manager import LOAD_PLUGINS_ENV

    read = {ALLOCATOR_ENV, CACHE_ENV, DATA_ROOT_ENV, LOAD_PLUGINS_ENV, app.DEBUG_ENV}
    assert set(cli.ENVIRONMENT) == read
    assert cli.main(["--help"]) == 0
    out = capsys.readouterr().out
    assert out.index("environment:") > out.index("verbs:")
    for name in read:
        assert f"\n  {name} " in out


@pytest.mark.parametrize(
    ("args", "message"),
    [
        ([], "You must specify 'model', e.g, model=<OPTION> Available options: example"),
        (["model=nope"], "Could not find 'model/nope'"),
        (["model=example", "trainer.foo=1"], "Could not override 'trainer.foo'"),
        (["model=example", "data.window=0"], "data.window must be > 0, got 0"),
    ],
)
def test_cli_errors_are_one_line(
    example_plugin: Path,
    tmp_path: Path,
    args: list[str],
    message: str,
    capsys: pytest.CaptureFixture[str],
) -> None:
    code = cli.main(["fit", *args, f"runs_dir={tmp_path}", f"data.cache_dir={tmp_path}"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1
    assert err[-1].startswith("skelagnostic fit: error: ") and message in err[-1]
    assert not any("Traceback" in line or "Error executing job" in line for line in err)


def test_a_lightning_misconfiguration_is_one_line(
    example_plugin: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """Lightning's own configuration error, caught although ``cli.app`` does not import it."""
    from lightning.fabric.utilities.exceptions import MisconfigurationException

    from skelagnostic.cli import tasks

    def refuse(cfg: object, pm: object) -> None:
        raise MisconfigurationException("the strategy refuses this")

    monkeypatch.setattr(tasks, "run", refuse)
    code = cli.main(["fit", "model=example", f"runs_dir={tmp_path}"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1
    assert err[-1] == "skelagnostic fit: error: the strategy refuses this", err
    assert list((tmp_path / "example" / "fit").iterdir()) == []  # only bookkeeping: discarded


def test_cli_debug_flag_raises(example_plugin: Path, tmp_path: Path) -> None:
    with pytest.raises(Exception, match="You must specify 'model'"):
        cli.main(["fit", "--debug", f"runs_dir={tmp_path}"])


def run_cli(cmd: list[str], env: dict[str, str], cwd: Path, timeout: float) -> str:
    proc = subprocess.run(cmd, env=env, cwd=cwd, capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return proc.stdout + proc.stderr


def only_run_dir(root: Path) -> Path:
    (run_dir,) = [p for p in (root / "example" / "fit").iterdir()]
    return run_dir


@pytest.mark.slow
def test_cli_fit_ddp_two_cpu_processes(subprocess_env: dict[str, str], tmp_path: Path) -> None:
    out = run_cli(
        [
            sys.executable,
            "-m",
            "skelagnostic.cli",
            "fit",
            "model=example",
            *FAST,
            "trainer.strategy=ddp",
            "trainer.devices=2",
            "trainer.accelerator=cpu",
            f"runs_dir={tmp_path / 'runs'}",
        ],
        subprocess_env,
        tmp_path,
        timeout=170,
    )
    assert "Starting with 2 processes" in out and "distributed_backend=gloo" in out
    run_dir = only_run_dir(tmp_path / "runs")
    assert (run_dir / "checkpoints" / "best.ckpt").is_file()
    assert (run_dir / "checkpoints" / "last.ckpt").is_file()
    assert (run_dir / "train_ddp_process_1.log").is_file()  # rank 1 re-ran the command line
    assert {row["epoch"] for row in read_metrics(run_dir)} == {"0", "1"}


@pytest.mark.slow
def test_cli_commands_started_together_get_their_own_run_dirs(
    subprocess_env: dict[str, str], tmp_path: Path
) -> None:
    cmd = [
        sys.executable,
        "-m",
        "skelagnostic.cli",
        "fit",
        "model=example",
        *FAST,
        f"runs_dir={tmp_path / 'runs'}",
    ]
    procs = [
        subprocess.Popen(
            cmd,
            env=subprocess_env,
            cwd=tmp_path,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        for _ in range(2)
    ]
    for proc in procs:
        out, _ = proc.communicate(timeout=170)
        assert proc.returncode == 0, out[-3000:]
    run_dirs = sorted(p.name for p in (tmp_path / "runs" / "example" / "fit").iterdir())
    assert len(run_dirs) == 2, run_dirs  # one directory each, even within the same second
    assert all(re.fullmatch(r"\d{4}-\d{2}-\d{2}_\d{2}-\d{2}-\d{2}_\d{6}", n) for n in run_dirs)


def _copy_filter(root: Path):
    """Copy a project's sources only (not venvs, caches, build outputs or sibling projects)."""
    top = {
        ".venv",
        ".git",
        "build",
        "dist",
        "runs",
        "outputs",
        "tests",
        "docs",
        "plugins",
        "benchmarks",
    }

    def ignore(directory: str, names: list[str]) -> list[str]:
        at_top = Path(directory) == root
        return [
            n
            for n in names
            if n == "__pycache__" or n.endswith(".egg-info") or (at_top and n in top)
        ]

    return ignore


@pytest.mark.slow
def test_wheel_installed_cli_from_another_directory(tmp_path: Path) -> None:
    wheels = tmp_path / "wheels"
    for project in (REPO, REPO / "plugins" / "example-aligner"):
        build = tmp_path / "build" / project.name
        shutil.copytree(project, build, ignore=_copy_filter(project))
        subprocess.run(
            [
                sys.executable,
                "-m",
                "pip",
                "wheel",
                "--no-deps",
                "--no-build-isolation",
                "-q",
                "-w",
                str(wheels),
                str(build),
            ],
            check=True,
            timeout=300,
        )
    env_dir = tmp_path / "env"
    venv.create(env_dir, system_site_packages=True, with_pip=False)
    py = env_dir / "bin" / "python"
    site = subprocess.run(
        [str(py), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    # the test interpreter's packages (torch, lightning, ...) without its editable skelagnostic
    deps = [p for p in sys.path if p.endswith("site-packages")]
    Path(site, "deps.pth").write_text("\n".join(deps) + "\n")
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "--python",
            str(py),
            "install",
            "--no-deps",
            "--no-index",
            "-q",
            *map(str, wheels.glob("*.whl")),
        ],
        check=True,
        timeout=300,
    )
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env.update({"SKELAGNOSTIC_CACHE": str(tmp_path / "cache"), plugins.LOAD_PLUGINS_ENV: "example"})
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    where = run_cli(
        [str(py), "-c", "import skelagnostic.conf as c; print(c.__file__)"],
        env,
        elsewhere,
        timeout=60,
    )
    assert str(env_dir) in where  # the wheel's copy, not the source tree
    out = run_cli(
        [str(env_dir / "bin" / "skelagnostic"), "plugins", "--json"], env, elsewhere, timeout=120
    )
    assert '"source": "skelagnostic-example-aligner"' in out
    run_cli(
        [str(env_dir / "bin" / "skelagnostic"), "fit", "model=example", *FAST],
        env,
        elsewhere,
        timeout=240,
    )
    assert (only_run_dir(elsewhere / "runs") / "checkpoints" / "last.ckpt").is_file()


def test_threads_option_sets_torch_threads(example_plugin: Path, tmp_path: Path) -> None:
    common = ["model=example", f"data.cache_dir={tmp_path / 'cache'}", *FAST]
    before = torch.get_num_threads()
    try:
        app.run(
            app.compose(
                [*common, f"run_dir={tmp_path / 'run'}", "threads=1", "trainer.max_epochs=1"]
            )
        )
        assert torch.get_num_threads() == 1
    finally:
        torch.set_num_threads(before)
    with pytest.raises(app.ConfigError, match="threads must be a positive integer"):
        app.run(app.compose([*common, f"run_dir={tmp_path / 'bad'}", "threads=0"]))


def test_fit_with_render_callback_writes_renders(example_plugin: Path, tmp_path: Path) -> None:
    from PIL import Image

    run_dir = tmp_path / "run"
    app.run(
        app.compose(
            [
                "model=example",
                f"data.cache_dir={tmp_path / 'cache'}",
                *FAST,
                f"run_dir={run_dir}",
                "callbacks=render",
                "trainer.max_epochs=2",
                "callbacks.render_samples.every_n_epochs=1",
            ]
        )
    )
    renders = sorted(p.name for p in (run_dir / "renders").iterdir())
    assert any(n.endswith(".gif") for n in renders) and any(n.endswith(".png") for n in renders)
    sheet = next((run_dir / "renders").glob("*.png"))
    pixels = Image.open(sheet).convert("L")
    assert min(pixels.getextrema()) < 128  # something is drawn, not a blank image


def test_fit_with_ema_checkpoints_the_averaged_weights(
    example_plugin: Path, tmp_path: Path
) -> None:
    """``callbacks=ema``: the checkpoint's weights are the EMA, the raw ones ride along."""
    common = ["model=example", f"data.cache_dir={tmp_path / 'cache'}", *FAST]
    run_dir = tmp_path / "run"
    app.run(
        app.compose(
            [
                *common,
                f"run_dir={run_dir}",
                "callbacks=[render,ema]",
                "callbacks.ema.decay=0.9",
                "trainer.max_epochs=1",
            ]
        )
    )
    assert (run_dir / "renders").is_dir()  # combines with another option
    ckpt = torch.load(run_dir / "checkpoints" / "last.ckpt", weights_only=False)
    averaged, raw = ckpt["state_dict"], ckpt["current_model_state"]
    assert averaged.keys() == raw.keys()
    assert any(not torch.equal(averaged[k], raw[k]) for k in raw)
    model = plugins.load_aligner("example", checkpoint=run_dir / "checkpoints" / "last.ckpt")
    for name, value in model.state_dict().items():
        assert torch.equal(value, averaged[name]), name  # a loaded model gets the average

    # decay 0: the average is the latest weights
    zero = tmp_path / "zero"
    app.run(
        app.compose(
            [
                *common,
                f"run_dir={zero}",
                "callbacks=ema",
                "callbacks.ema.decay=0",
                "trainer.max_epochs=1",
            ]
        )
    )
    ckpt0 = torch.load(zero / "checkpoints" / "last.ckpt", weights_only=False)
    assert all(
        torch.equal(ckpt0["state_dict"][k], v) for k, v in ckpt0["current_model_state"].items()
    )

    # resuming continues from the raw weights and the average
    resumed = tmp_path / "resumed"
    app.run(
        app.compose(
            [
                *common,
                f"run_dir={resumed}",
                "callbacks=ema",
                "callbacks.ema.decay=0.9",
                "trainer.max_epochs=2",
                f"ckpt_path={run_dir / 'checkpoints' / 'last.ckpt'}",
            ]
        )
    )
    assert {row["epoch"] for row in read_metrics(resumed)} == {"1"}
    after = torch.load(resumed / "checkpoints" / "last.ckpt", weights_only=False)
    assert after["epoch"] == 1 and "current_model_state" in after


class _LateLayerPlugin:
    """An aligner that creates a layer in setup(), after callbacks=ema copied it."""

    @staticmethod
    @plugins.hookimpl
    def register_aligners(register) -> None:
        from skelagnostic_example.aligner import ExampleAligner

        class LateLayer(ExampleAligner):
            def setup(self, stage: str) -> None:
                self.late = torch.nn.Linear(2, 2)

        register("latelayer", LateLayer, config={"model": {"hidden": 8}})


def test_ema_names_the_layers_an_aligner_builds_too_late(
    example_plugin: Path, tmp_path: Path
) -> None:
    pm = plugins.PluginManager(load_entrypoints=False)
    pm.register(_LateLayerPlugin(), "latelayer")
    cfg = app.compose(
        [
            "model=latelayer",
            f"data.cache_dir={tmp_path / 'cache'}",
            *FAST[:-2],
            f"run_dir={tmp_path / 'run'}",
            "callbacks=ema",
        ],
        plugin_manager=pm,
    )
    with pytest.raises(
        SkelagnosticError,
        match=r"LateLayer created 2 parameters \(late\.weight, "
        r"late\.bias\).*configure_model",
    ):
        app.run(cfg, pm)
    with pytest.raises(SkelagnosticError, match=r"decay must lie in \[0, 1\)"):
        EMAWeights(decay=1.0)


class _DataDefaultsPlugin:
    """A plugin whose aligner brings its own default data and data-module keys."""

    @staticmethod
    @plugins.hookimpl
    def register_aligners(register) -> None:
        from skelagnostic_example.aligner import ExampleAligner

        register(
            "withdata",
            ExampleAligner,
            config={
                "model": {"hidden": 8},
                "data": {"source": "procedural", "kinds": ["biped31"], "seconds": 3.0},
                "data_options": {"window": 20, "fps": 25},
                "trainer_options": {"max_time": "00:00:01:00", "max_epochs": 3},
            },
        )


def test_aligner_data_defaults_merge_under_the_command_line(example_plugin: Path) -> None:
    pm = plugins.PluginManager(load_entrypoints=False)
    pm.register(_DataDefaultsPlugin(), "withdata")
    # The aligner's default data replaces data=procedural's options ...
    cfg = app.compose(["model=withdata", "run_dir=/tmp/x"], plugin_manager=pm)
    assert cfg.model.hidden == 8
    assert list(cfg.data.kinds) == ["biped31"] and cfg.data.seconds == 3.0
    assert cfg.data.window == 20 and cfg.data.fps == 25 and cfg.data.batch_size == 32
    assert cfg.trainer.max_time == "00:00:01:00" and cfg.trainer.max_epochs == 3
    assert cfg.trainer.accelerator == "cpu"  # the rest of trainer=default stays
    # ... a data=... choice wins over it, but keeps the aligner's data-module keys ...
    cfg = app.compose(
        ["model=withdata", "run_dir=/tmp/x", "data=bvh", "data.paths=[a]"], plugin_manager=pm
    )
    assert cfg.data.source == "bvh" and "kinds" not in cfg.data and cfg.data.window == 20
    # ... and data.<key>=... overrides everything.
    cfg = app.compose(
        [
            "model=withdata",
            "run_dir=/tmp/x",
            "data.window=7",
            "data.kinds=[quadruped]",
            "trainer.max_epochs=9",
        ],
        plugin_manager=pm,
    )
    assert cfg.data.window == 7 and list(cfg.data.kinds) == ["quadruped"]
    assert cfg.trainer.max_epochs == 9
    cfg = app.compose(
        ["model=withdata", "run_dir=/tmp/x", "trainer.max_time=null"], plugin_manager=pm
    )
    assert cfg.trainer.max_time is None
    # experiment=smoke (after model in the defaults list) still sets the trainer
    cfg = app.compose(["model=withdata", "run_dir=/tmp/x", "experiment=smoke"], plugin_manager=pm)
    assert cfg.trainer.max_epochs == 2
    # Aligners without data defaults keep data=procedural.
    cfg = app.compose(["model=example", "run_dir=/tmp/x"])
    assert cfg.data.source == "procedural" and cfg.data.window == 32


def test_aligner_data_defaults_need_a_source(example_plugin: Path) -> None:
    class Bad:
        @staticmethod
        @plugins.hookimpl
        def register_aligners(register) -> None:
            from skelagnostic_example.aligner import ExampleAligner

            register("bad", ExampleAligner, config={"data": {"kinds": ["biped31"]}})

    pm = plugins.PluginManager(load_entrypoints=False)
    pm.register(Bad(), "bad")
    with pytest.warns(plugins.PluginLoadWarning, match="needs a 'source'"):
        assert "bad" not in pm.aligners
    assert "needs a 'source'" in pm.plugins()[-1].error
