import math

import numpy as np
import pytest
import torch
from _matching_helpers import random_clips

from skelagnostic.errors import SkelagnosticError
from skelagnostic.matching import MatchingError, MotionDatabase


def make_db(**kwargs) -> MotionDatabase:
    return MotionDatabase.from_clips(random_clips(4, (20, 40), seed=0), fps=30, **kwargs)


class TestBuild:
    def test_layout_and_clip_ranges(self):
        clips = random_clips(3, (10, 20), seed=1)
        db = MotionDatabase.from_clips(clips, fps=30, clip_names=["a", "b", "c"])
        lengths = [c["pose"].shape[0] for c in clips]
        assert db.num_frames == sum(lengths)
        assert db.num_clips == 3
        assert db.dims == {"manifold": 3, "pose": 5, "frequency": 1}
        assert db.clip_range(1) == (lengths[0], lengths[0] + lengths[1])
        clip, local = db.locate(torch.tensor([0, lengths[0], lengths[0] + 2, db.num_frames - 1]))
        assert clip.tolist() == [0, 1, 1, 2]
        assert local.tolist() == [0, 0, 2, lengths[2] - 1]
        torch.testing.assert_close(db.raw("pose"), torch.cat([c["pose"] for c in clips]))
        assert db.build_seconds >= 0 and db.nbytes > 0
        assert "clips=3" in repr(db)

    def test_group_normalisation_and_weights(self):
        db = make_db(weights={"pose": 2.0})
        for name in ("manifold", "pose"):
            norm = db.normalized(name).double()
            weight = db.weights[name]
            torch.testing.assert_close(
                norm.mean(0), torch.zeros(db.dims[name], dtype=torch.float64), atol=1e-5, rtol=0
            )
            # one scale per group: the mean channel std becomes the weight
            assert norm.std(0, unbiased=False).mean().item() == pytest.approx(weight, rel=1e-4)
        raw = db.raw("pose")[:5]
        torch.testing.assert_close(
            db.denormalize("pose", db.normalize("pose", raw)), raw, atol=1e-5, rtol=1e-5
        )

    def test_constant_group_keeps_unit_scale(self):
        db = MotionDatabase({"c": torch.ones(10, 2)}, [10], fps=30)
        assert float(db.scale["c"]) == 1.0
        assert torch.equal(db.normalized("c"), torch.zeros(10, 2))

    def test_numpy_and_float64_input(self):
        values = np.random.default_rng(0).normal(size=(12, 3))
        db = MotionDatabase({"x": values}, [5, 7], fps=60)
        assert db.raw("x").dtype == torch.float32
        np.testing.assert_allclose(db.raw("x").numpy(), values, rtol=1e-6)

    def test_save_load_round_trip(self, tmp_path):
        db = make_db(weights={"manifold": 3.0})
        path = tmp_path / "db.pt"
        db.save(path)
        back = MotionDatabase.load(path)
        assert back.groups == db.groups and back.weights == db.weights and back.fps == db.fps
        assert torch.equal(back.clip_starts, db.clip_starts)
        for name in db.groups:
            assert torch.equal(back.raw(name), db.raw(name))
            assert torch.equal(back.normalized(name), db.normalized(name))

    def test_to_same_device(self):
        db = make_db()
        copy = db.to("cpu")
        assert torch.equal(copy.normalized("pose"), db.normalized("pose"))


class TestErrors:
    def test_is_a_skelagnostic_value_error(self):
        assert issubclass(MatchingError, SkelagnosticError)
        assert issubclass(MatchingError, ValueError)

    @pytest.mark.parametrize(
        ("kwargs", "message"),
        [
            ({"features": {}, "clip_lengths": [3]}, "features"),
            ({"features": {"x": torch.zeros(0, 2)}, "clip_lengths": [1]}, "empty"),
            ({"features": {"x": torch.zeros(4, 2)}, "clip_lengths": []}, "clip_lengths"),
            ({"features": {"x": torch.zeros(4, 2)}, "clip_lengths": [2, 3]}, "sum to 5"),
            ({"features": {"x": torch.zeros(4, 2)}, "clip_lengths": [4, 0]}, "clip_lengths"),
            ({"features": {"x": torch.zeros(4, 2, 2)}, "clip_lengths": [4]}, "shape"),
            (
                {"features": {"x": torch.tensor([[0.0], [math.nan]])}, "clip_lengths": [2]},
                "frame 1",
            ),
            ({"features": {"x": torch.zeros(2, 1)}, "clip_lengths": [2], "fps": 0}, "fps"),
            (
                {"features": {"x": torch.zeros(2, 1)}, "clip_lengths": [2], "weights": {"y": 1}},
                "'y'",
            ),
            (
                {"features": {"x": torch.zeros(2, 1)}, "clip_lengths": [2], "weights": {"x": -1}},
                "x",
            ),
            (
                {
                    "features": {"x": torch.zeros(2, 1)},
                    "clip_lengths": [2],
                    "clip_names": ["a", "b"],
                },
                "clip_names",
            ),
            (
                {"features": {"x": torch.zeros(2, 1, dtype=torch.bool)}, "clip_lengths": [2]},
                "dtype",
            ),
        ],
    )
    def test_bad_construction(self, kwargs, message):
        kwargs = {"fps": 30, **kwargs}
        with pytest.raises(MatchingError, match=message):
            MotionDatabase(**kwargs)

    def test_non_numeric_weight(self):
        with pytest.raises(MatchingError, match=r"weights\['x'\]"):
            MotionDatabase({"x": torch.zeros(2, 1)}, [2], fps=30, weights={"x": "heavy"})

    def test_bad_clips(self):
        with pytest.raises(MatchingError, match="at least one clip"):
            MotionDatabase.from_clips([], fps=30)
        with pytest.raises(MatchingError, match=r"clips\[1\]"):
            MotionDatabase.from_clips([{"a": torch.zeros(3, 2)}, {"b": torch.zeros(3, 2)}], fps=30)
        with pytest.raises(MatchingError, match=r"clips\[1\]\['a'\]: has 3 dims"):
            MotionDatabase.from_clips([{"a": torch.zeros(3, 2)}, {"a": torch.zeros(3, 3)}], fps=30)
        with pytest.raises(MatchingError, match="frames"):
            MotionDatabase.from_clips([{"a": torch.zeros(3, 2), "b": torch.zeros(4, 1)}], fps=30)

    def test_bad_group_and_query_width(self):
        db = make_db()
        with pytest.raises(MatchingError, match="unknown feature group 'nope'"):
            db.raw("nope")
        with pytest.raises(MatchingError, match="pose: expected last dimension 5"):
            db.normalize("pose", torch.zeros(3, 4))
        with pytest.raises(MatchingError, match="clip"):
            db.clip_range(10)

    def test_load_rejects_other_files(self, tmp_path):
        path = tmp_path / "other.pt"
        torch.save({"hello": torch.zeros(1)}, path)
        with pytest.raises(MatchingError, match="not a saved MotionDatabase"):
            MotionDatabase.load(path)
        with pytest.raises(MatchingError, match="cannot read"):
            MotionDatabase.load(tmp_path / "missing.pt")
