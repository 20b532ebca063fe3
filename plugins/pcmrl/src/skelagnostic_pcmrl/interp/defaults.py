"""Default data of ``model=pcmrl_interp`` and the keys of its data module.

Registered with the aligner by :mod:`skelagnostic_pcmrl.plugin`.
"""

from __future__ import annotations

from typing import Any

__all__ = ["INTERP_DATA_DEFAULTS", "INTERP_DATA_OPTIONS"]

#: Default data of ``model=pcmrl_interp``: procedural CMU-31-topology bipeds (no files needed).
INTERP_DATA_DEFAULTS: dict[str, Any] = {
    "source": "procedural",
    "kinds": ["biped31"],
    "gaits": ["walk", "run"],
    "clips_per_gait": 4,
    "seconds": 8.0,
}

#: Data-module keys of :class:`~skelagnostic_pcmrl.interp.data.PcmrlInterpDataModule`.
INTERP_DATA_OPTIONS: dict[str, Any] = {
    "fps": 30.0,
    "window": 128,
    "stride": 32,
    "min_keys": 5,
    "max_keys": 36,
    "key_mode": "random",
    "min_gap": 5,
    "max_gap": 30,
    "batch_size": 16,
    "samples_per_epoch": 1024,
    "val_fraction": 0.2,
    "val_gap": 15,
    "rpa_range": 0.1,
    "rpa_prob": 0.5,
    "rpa_offsets": "independent",
    "rpa_solve": "directions",
    "mirror": False,
    "procedural_kind": None,
    "procedural_clips": 0,
    "seed": 0,
    "num_workers": 0,
}
