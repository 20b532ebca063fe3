"""PC-MRL interpolation data read from the window cache equal the clips held in memory."""

from __future__ import annotations

from pathlib import Path

import torch
from skelagnostic_pcmrl.interp.clips import CachedClip, Clip
from skelagnostic_pcmrl.interp.data import PcmrlInterpDataModule


def test_cached_clips_give_the_windows_of_in_memory_clips(tmp_path: Path) -> None:
    dm = PcmrlInterpDataModule(
        fps=20,
        window=32,
        stride=16,
        batch_size=4,
        samples_per_epoch=12,
        mirror=True,
        procedural_kind="biped31",
        procedural_clips=1,
        cache_dir=tmp_path,
    )
    dm.prepare_data()
    dm.setup("fit")
    source = dm.sources[0]
    refs = {r.id: r for r in source.clips()}
    extra = dm._extra()
    assert extra is not None
    refs.update({f"procedural:{r.id}": r for r in extra.clips()})

    def held(name: str) -> Clip:  # what setup used to keep in memory
        base = name.removesuffix(":mirror")
        src = extra if base.startswith("procedural:") else source
        motion = src.load(refs[base]).resample(dm.fps)
        return Clip.from_motion(motion.mirror() if name.endswith(":mirror") else motion, name)

    names = [c.name for part in dm.clips.values() for c in part]
    assert any(n.endswith(":mirror") for n in names) and any("procedural:" in n for n in names)
    for part in dm.clips.values():
        for clip in part:
            assert isinstance(clip, CachedClip)
            want = held(clip.name)
            assert clip.num_frames == want.num_frames
            for got_t, want_t in zip(clip.frames(3, 40), want.frames(3, 40), strict=True):
                assert torch.equal(got_t, want_t)
            assert torch.equal(clip.global_rotations, want.global_rotations)
            assert torch.equal(clip.offsets, want.offsets)
            assert torch.equal(clip.tails, want.tails)
            assert torch.equal(clip.skeleton.offsets, want.skeleton.offsets)
    # training windows (random keys, rest-pose augmentation) are those of the held clips
    held_set = type(dm.train_set)(
        [held(c.name) for c in dm.clips["train"]],
        dm.window,
        dm.min_keys,
        dm.max_keys,
        dm.rpa_range,
        dm.rpa_prob,
        dm.samples_per_epoch,
        dm.seed,
    )
    for i in range(len(dm.train_set)):
        got, want = dm.train_set[i], held_set[i]
        assert set(got) == set(want)
        for key in want:
            assert torch.equal(got[key], want[key]), (i, key)
