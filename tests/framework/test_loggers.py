"""``logger=wandb`` and ``logger=mlflow``: a tiny fit writes metrics that read back, offline.

Both packages are optional extras (``skelagnostic[wandb]``, ``skelagnostic[mlflow]``):
the fits are skipped where they are not installed; without them, the error names the
extra to install.
"""

from __future__ import annotations

import json
import socket
import time
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from lightning_utilities.core.imports import RequirementCache
from test_config_groups import SMALL

from skelagnostic.cli import app
from skelagnostic.cli.build import instantiate_all


def _fit(tmp_path: Path, logger: str) -> tuple[Path, dict]:
    run_dir = tmp_path / "run"
    cfg = app.compose(
        [
            "model=example",
            f"logger={logger}",
            f"run_dir={run_dir}",
            f"data.cache_dir={tmp_path / 'cache'}",
            "callbacks=render",  # the contact sheet reaches the logger too
            "trainer.max_epochs=1",
            "threads=1",
            *SMALL,
        ]
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        metrics = app.run(cfg)
    return run_dir, metrics


@pytest.fixture
def no_network(monkeypatch: pytest.MonkeyPatch) -> None:
    """Any attempt to open a connection to another host fails the test."""
    real = socket.socket.connect

    def connect(self: socket.socket, address: object) -> object:
        if self.family in (socket.AF_INET, socket.AF_INET6):
            host = address[0] if isinstance(address, tuple) else address
            if host not in ("127.0.0.1", "::1", "localhost"):
                raise AssertionError(f"network connection to {address!r} attempted")
        return real(self, address)

    monkeypatch.setattr(socket.socket, "connect", connect)


def test_mlflow_logs_to_a_file_store_in_the_run_directory(
    example_plugin: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, no_network: None
) -> None:
    mlflow = pytest.importorskip("mlflow")
    monkeypatch.delenv("MLFLOW_ALLOW_FILE_STORE", raising=False)  # set by the logger
    cfg = app.compose(["model=example", "logger=mlflow", "run_dir=/tmp/x"])
    assert cfg.logger.mlflow.tracking_uri == "file:/tmp/x/mlruns"
    run_dir, metrics = _fit(tmp_path, "mlflow")
    client = mlflow.tracking.MlflowClient(tracking_uri=f"file:{run_dir / 'mlruns'}")
    experiment = client.get_experiment_by_name("skelagnostic")
    (run,) = client.search_runs([experiment.experiment_id])
    history = client.get_metric_history(run.info.run_id, "train/loss")
    assert len(history) >= 2  # logged every step (smoke: log_every_n_steps=1)
    assert history[-1].value == pytest.approx(float(metrics["train/loss"]), rel=1e-5)
    assert "val/loss" in run.data.metrics
    assert run.data.params["hidden"] == "16"  # the hyperparameters too
    (sheet,) = client.list_artifacts(run.info.run_id, "val/render")
    assert sheet.path.startswith("val/render/step") and sheet.path.endswith(".png")


def test_wandb_logs_offline_in_the_run_directory(
    example_plugin: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, no_network: None
) -> None:
    pytest.importorskip("wandb")
    for var in ("WANDB_CONFIG_DIR", "WANDB_CACHE_DIR", "WANDB_DATA_DIR", "WANDB_ARTIFACT_DIR"):
        monkeypatch.setenv(var, str(tmp_path / "wandb-home" / var.lower()))
    monkeypatch.setenv("WANDB_SILENT", "true")
    monkeypatch.delenv("WANDB_API_KEY", raising=False)
    monkeypatch.delenv("WANDB_MODE", raising=False)
    cfg = app.compose(["model=example", "logger=wandb", "run_dir=/tmp/x"])
    assert cfg.logger.wandb.offline is True and cfg.logger.wandb.save_dir == "/tmp/x"
    run_dir, metrics = _fit(tmp_path, "wandb")
    (records,) = (run_dir / "wandb").glob("offline-run-*/run-*.wandb")  # for `wandb sync`
    deadline = time.monotonic() + 60  # wandb's service writes the file after finish returns
    while True:
        read = list(wandb_records(records))
        kinds = {record.WhichOneof("record_type") for record in read}
        if "exit" in kinds or time.monotonic() > deadline:
            break
        time.sleep(0.5)
    assert "exit" in kinds  # the run was finished when the fit ended
    history: dict[str, list] = {}
    for record in read:
        if record.HasField("history"):
            for item in record.history.item:
                key = item.key or "/".join(item.nested_key)
                history.setdefault(key, []).append(json.loads(item.value_json))
    assert len(history["train/loss"]) >= 2
    assert history["train/loss"][-1] == pytest.approx(float(metrics["train/loss"]), rel=1e-5)
    assert "val/loss" in history
    (sheet,) = history["val/render/filenames"]  # the contact sheet
    assert (records.parent / "files" / sheet[0]).is_file()


def wandb_records(path: Path) -> Iterator[Any]:
    """The protobuf records of an offline W&B run file (a LevelDB-style log of 32 KiB blocks)."""
    from wandb.proto import wandb_internal_pb2

    data = path.read_bytes()
    assert data[:4] == b":W&B"
    pos, block, chunk = 7, 32768, b""
    while pos + 7 <= len(data):
        if block - pos % block < 7:  # a block's tail too short for a header: padding
            pos += block - pos % block
            continue
        length, kind = int.from_bytes(data[pos + 4 : pos + 6], "little"), data[pos + 6]
        if pos + 7 + length > len(data):  # a record still being written
            return
        chunk += data[pos + 7 : pos + 7 + length]
        pos += 7 + length
        if kind in (1, 4):  # a full record, or the last piece of one
            record = wandb_internal_pb2.Record()
            record.ParseFromString(chunk)
            chunk = b""
            yield record


@pytest.mark.parametrize(
    ("logger", "module", "flag"),
    [
        ("wandb", "lightning.pytorch.loggers.wandb", "_WANDB_AVAILABLE"),
        ("mlflow", "lightning.pytorch.loggers.mlflow", "_MLFLOW_AVAILABLE"),
    ],
)
def test_a_missing_logger_package_names_the_extra(
    example_plugin: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    logger: str,
    module: str,
    flag: str,
) -> None:
    # what Lightning sees when the package is not installed
    monkeypatch.setattr(f"{module}.{flag}", RequirementCache(f"{logger}-not-installed>=1"))
    cfg = app.compose(["model=example", f"logger={logger}", f"run_dir={tmp_path / 'run'}"])
    with pytest.raises(
        app.ConfigError,
        match=rf"logger\.{logger}: .*install it with pip install 'skelagnostic\[{logger}\]'",
    ):
        instantiate_all(cfg.logger, "logger")
