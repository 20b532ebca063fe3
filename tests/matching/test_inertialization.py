import pytest
import torch

from skelagnostic.core import quaternion as Q
from skelagnostic.matching import MatchingError, decay_offset, inertialize, inertialize_rotations

DT = 1 / 30


def test_unbroken_replay_is_unchanged():
    ramp = (torch.arange(40.0) ** 2 / 40)[:, None].repeat(1, 3)
    pieces = [ramp[:10], ramp[10:25], ramp[25:38]]
    conts = [ramp[10:12], ramp[25:27]]
    assert torch.equal(inertialize(pieces, conts, DT, 0.1), ramp[:38])


def test_value_and_velocity_continue_the_source_then_decay():
    source = torch.arange(10.0)[:, None] * 0.1  # 0.1 per frame
    target = torch.full((300, 1), 1.5)  # still, 0.5 above where the source goes
    out = inertialize([source, target], [torch.tensor([[1.0], [1.1]])], DT, 1.0)
    assert float(out[10, 0]) == pytest.approx(1.0)  # where the source would have been
    assert float(out[11, 0] - out[10, 0]) == pytest.approx(0.1, abs=5e-3)  # at its speed
    assert float(out[-1, 0]) == pytest.approx(1.5, abs=1e-3)  # offset gone after 10 s


def test_offsets_carry_over_quick_transitions():
    a = torch.zeros(5, 1)
    b = torch.ones(3, 1)
    c = torch.full((30, 1), 2.0)
    conts = [torch.zeros(2, 1), torch.ones(2, 1)]
    out = inertialize([a, b, c], conts, DT, 0.1)
    # at the second transition the output continues from where it was, not from b
    assert float(out[8, 0]) < 0.5
    assert torch.all(out.diff(dim=0).abs() < 0.5)


def test_decay_offset_starts_at_the_offset_and_its_velocity():
    x, v = decay_offset(torch.ones(1), torch.full((1,), -2.0), torch.tensor([0.0, 0.5, 50.0]), 0.5)
    assert float(x[0, 0]) == 1.0 and float(v[0, 0]) == -2.0
    assert 0.0 < float(x[1, 0]) < 1.0
    assert abs(float(x[2, 0])) < 1e-12


def test_errors():
    with pytest.raises(MatchingError, match="segments"):
        inertialize([], [], DT, 0.1)
    with pytest.raises(MatchingError, match="continuations"):
        inertialize([torch.zeros(2, 1), torch.zeros(2, 1)], [], DT, 0.1)
    with pytest.raises(MatchingError, match=r"segments\[1\]"):
        inertialize([torch.zeros(2, 1), torch.zeros(2, 2)], [torch.zeros(2, 1)], DT, 0.1)
    with pytest.raises(MatchingError, match="halflife"):
        inertialize([torch.zeros(2, 1)], [], DT, 0.0)


def _turning(frames: int, joints: int, rate: float, start: float = 0.0) -> torch.Tensor:
    """``[frames, joints, 4]``: every joint turning about y at ``rate`` rad/frame."""
    angle = start + rate * torch.arange(frames, dtype=torch.float64)
    zero = torch.zeros_like(angle)
    q = torch.stack([(angle / 2).cos(), zero, (angle / 2).sin(), zero], -1)
    return q[:, None].expand(frames, joints, 4).contiguous()


def _angle(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Angle in radians between unit quaternions."""
    return 2 * Q.mul(a, Q.inv(b))[..., 0].abs().clamp(max=1).acos()


def test_rotations_unbroken_replay_is_unchanged():
    turn = _turning(40, 3, 0.05)
    pieces = [turn[:10], turn[10:25], turn[25:38]]
    conts = [turn[10:12], turn[25:27]]
    out = inertialize_rotations(pieces, conts, DT, 0.1)
    assert float(_angle(out, turn[:38]).max()) < 1e-6


def test_rotations_continue_the_source_then_decay():
    source = _turning(10, 2, 0.05)  # turning 0.05 rad per frame
    cont = _turning(2, 2, 0.05, start=0.5)
    target = _turning(300, 2, 0.0, start=2.0)  # still, 1.5 rad away from the continuation
    out = inertialize_rotations([source, target], [cont], DT, 0.5)
    assert float(_angle(out[10], cont[0]).max()) < 1e-6  # where the source would have been
    assert float(_angle(out[11], out[10]).max()) == pytest.approx(0.05, abs=5e-3)  # its speed
    assert float(_angle(out[-1], target[-1]).max()) < 1e-3  # offset gone after 10 s
    # unit quaternions throughout, and no frame-to-frame step larger than the cut's
    assert torch.allclose(out.norm(dim=-1), torch.ones(310, 2, dtype=out.dtype))
    raw = torch.cat([source, target])
    assert float(_angle(out[1:], out[:-1]).max()) < 0.2 < float(_angle(raw[1:], raw[:-1]).max())


def test_rotation_errors():
    one = torch.tensor([1.0, 0.0, 0.0, 0.0]).expand(2, 1, 4)
    with pytest.raises(MatchingError, match="segments"):
        inertialize_rotations([], [], DT, 0.1)
    with pytest.raises(MatchingError, match=r"segments\[1\]"):
        inertialize_rotations([one, one.expand(2, 2, 4)], [one], DT, 0.1)
    with pytest.raises(MatchingError, match="quaternions"):
        inertialize_rotations([torch.zeros(2, 1, 3)], [], DT, 0.1)
    with pytest.raises(MatchingError, match=r"continuations\[0\]"):
        inertialize_rotations([one, one], [one[:1]], DT, 0.1)
    with pytest.raises(MatchingError, match="halflife"):
        inertialize_rotations([one], [], DT, -1.0)
