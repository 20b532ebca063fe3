"""RenderSamples: a Lightning callback writing validation renders every N epochs."""

from __future__ import annotations

import lightning.pytorch as pl
import numpy as np
import pytest
import torch
from lightning.pytorch.loggers import Logger
from PIL import Image
from torch.utils.data import DataLoader, TensorDataset

import skelagnostic as sa
from skelagnostic.callbacks import RenderSamples, RenderSampleSource
from skelagnostic.viz import RenderError


class _Experiment:
    def __init__(self):
        self.images = []

    def add_image(self, tag, image, global_step=None, dataformats="CHW"):
        self.images.append((tag, np.asarray(image), global_step, dataformats))


class _ImageLogger(Logger):
    """A logger whose experiment has TensorBoard's add_image (tensorboard is not installed)."""

    def __init__(self):
        super().__init__()
        self._experiment = _Experiment()

    @property
    def name(self):
        return "fake"

    @property
    def version(self):
        return 0

    @property
    def experiment(self):
        return self._experiment

    def log_metrics(self, metrics, step=None):
        pass

    def log_hyperparams(self, params, *args, **kwargs):
        pass


class _Model(pl.LightningModule):
    """Scales the root trajectory of a procedural walk; renders input vs output."""

    def __init__(self):
        super().__init__()
        self.scale = torch.nn.Parameter(torch.ones(()))
        self.motion, _ = sa.procedural.generate(kind="biped22", seconds=0.5, fps=30, seed=0)
        self.seen_batches = []

    def training_step(self, batch, batch_idx):
        return (self.scale * batch[0]).pow(2).mean()

    def validation_step(self, batch, batch_idx):
        self.log("val/loss", (self.scale * batch[0]).pow(2).mean())

    def configure_optimizers(self):
        return torch.optim.SGD(self.parameters(), lr=0.01)


class _RenderingModel(_Model):
    def render_sample(self, batch):
        self.seen_batches.append(batch[0].clone())
        return {"input": self.motion, "output": self.motion}


def _fit(model, callback, tmp_path, epochs, logger=None):
    data = DataLoader(TensorDataset(torch.arange(8.0)[:, None]), batch_size=4)
    trainer = pl.Trainer(
        max_epochs=epochs,
        logger=logger if logger is not None else False,
        callbacks=[callback],
        default_root_dir=tmp_path,
        enable_checkpointing=False,
        enable_progress_bar=False,
        enable_model_summary=False,
        num_sanity_val_steps=1,
        log_every_n_steps=1,
        accelerator="cpu",
    )
    trainer.fit(model, data, data)
    return trainer


def test_renders_every_n_epochs_and_last_epoch(tmp_path):
    logger = _ImageLogger()
    model = _RenderingModel()
    callback = RenderSamples(every_n_epochs=2, mode="overlay", size=(64, 48), sheet_frames=3)
    _fit(model, callback, tmp_path, epochs=3, logger=logger)
    renders = tmp_path / "renders"
    assert sorted(p.name for p in renders.iterdir()) == [
        "epoch0001.gif",
        "epoch0001.png",
        "epoch0002.gif",
        "epoch0002.png",
    ]
    assert callback.last_paths == (renders / "epoch0002.gif", renders / "epoch0002.png")
    with Image.open(renders / "epoch0001.gif") as gif:
        assert gif.size == (64, 48) and gif.n_frames == 16
    # the first validation batch of the epoch is what the model was asked to render
    assert len(model.seen_batches) == 2
    torch.testing.assert_close(model.seen_batches[0], torch.arange(4.0)[:, None])
    tags = [(tag, step, fmt) for tag, _, step, fmt in logger.experiment.images]
    assert tags == [("val/render", 4, "HWC"), ("val/render", 6, "HWC")]
    image = logger.experiment.images[0][1]
    assert image.shape == (48, 3 * 64 + 2 * 4, 3) and image.dtype == np.uint8
    np.testing.assert_array_equal(image, np.asarray(Image.open(renders / "epoch0001.png")))


def test_html_writes_the_viewer_page_beside_the_gif(tmp_path):
    from skelagnostic.viz.html import decode_payload

    model = _RenderingModel()
    callback = RenderSamples(every_n_epochs=1, size=(48, 48), sheet_frames=2, html=True)
    _fit(model, callback, tmp_path, epochs=1)
    page = tmp_path / "renders" / "epoch0000.html"
    assert callback.last_html == page
    text = page.read_text(encoding="utf-8")
    assert '"name":"input"' in text and '"name":"output"' in text
    assert len(decode_payload(text)) == 2


def test_module_without_render_sample_warns_once(tmp_path):
    callback = RenderSamples(every_n_epochs=1, dirpath=tmp_path / "out")
    assert not isinstance(_Model(), RenderSampleSource)
    with pytest.warns(UserWarning, match="render_sample") as record:
        _fit(_Model(), callback, tmp_path, epochs=2)
    assert sum("render_sample" in str(w.message) for w in record) == 1
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    ("kwargs", "word"),
    [
        ({"every_n_epochs": 0}, "every_n_epochs"),
        ({"sheet_frames": 0}, "sheet_frames"),
        ({"mode": "grid"}, "mode"),
    ],
)
def test_bad_arguments(kwargs, word):
    with pytest.raises(RenderError, match=word):
        RenderSamples(**kwargs)
