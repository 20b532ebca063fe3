import errno
import itertools
import os
import stat
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

import skelagnostic as sa
from skelagnostic.core import quaternion as Q
from skelagnostic.io.bvh import BVHWarning

REPO = Path(__file__).resolve().parents[2]

TINY = """HIERARCHY
ROOT Hips
{
  OFFSET 0 90 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
  JOINT Spine
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 5 0
    }
  }
  JOINT LeftUpLeg
  {
    OFFSET 8 -5 0
    CHANNELS 3 Xrotation Yrotation Zrotation
    End Site
    {
      OFFSET 0 -40 0
    }
  }
}
MOTION
Frames: 3
Frame Time: 0.0333333
0 90 0 0 0 0 10 20 30 1 2 3
1 91 2 5 -5 10 15 25 35 4 5 6
2 92 4 10 -10 20 20 30 40 7 8 9
"""


def write(tmp_path: Path, text: str, name: str = "clip.bvh", newline: str = "\n") -> Path:
    path = tmp_path / name
    path.write_bytes(text.replace("\n", newline).encode())
    return path


def max_angle_deg(a: torch.Tensor, b: torch.Tensor) -> float:
    dots = (a * b).sum(-1).abs().clamp(max=1.0)
    return float(torch.rad2deg(2 * torch.acos(dots)).max())


@pytest.mark.parametrize("newline", ["\n", "\r\n", "\r"])
def test_read_tiny_file(tmp_path, newline):
    m = sa.read_bvh(write(tmp_path, TINY, newline=newline))
    s = m.skeleton
    assert s.joint_names == ["Hips", "Spine", "LeftUpLeg"] and s.parents == [-1, 0, 0]
    assert m.num_frames == 3 and m.fps == 30 and m.name == "clip"
    assert s.end_sites == {1: [[0.0, 5.0, 0.0]], 2: [[0.0, -40.0, 0.0]]}
    assert s.channels[1] == ["Zrotation", "Xrotation", "Yrotation"]
    torch.testing.assert_close(
        m.root_positions[2], torch.tensor([2.0, 92.0, 4.0], dtype=torch.float64)
    )
    # Spine: intrinsic Z then X then Y with the values in channel order
    ref = Q.euler_to_quat(torch.tensor([20.0, 30.0, 40.0], dtype=torch.float64), "ZXY")
    assert max_angle_deg(m.rotations[2, 1], ref) < 1e-5
    ref = Q.euler_to_quat(torch.tensor([7.0, 8.0, 9.0], dtype=torch.float64), "XYZ")
    assert max_angle_deg(m.rotations[2, 2], ref) < 1e-5


def test_six_channels_on_every_joint_translate_children(tmp_path):
    """Bandai-style: every joint has position channels and a non-root joint moves."""
    text = (
        TINY.replace(
            "CHANNELS 3 Zrotation Xrotation Yrotation",
            "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation",
        )
        .replace("10 20 30 1 2 3", "0 10 0 10 20 30 1 2 3")
        .replace("15 25 35 4 5 6", "0 12 0 15 25 35 4 5 6")
        .replace("20 30 40 7 8 9", "3 10 0 20 30 40 7 8 9")
    )
    m = sa.read_bvh(write(tmp_path, text))
    assert m.translations is not None
    torch.testing.assert_close(
        m.translations[:, 1],
        torch.tensor([[0.0, 10.0, 0.0], [0.0, 12.0, 0.0], [3.0, 10.0, 0.0]], dtype=torch.float64),
    )
    out = tmp_path / "out.bvh"
    sa.write_bvh(m, out)
    back = sa.read_bvh(out)
    torch.testing.assert_close(back.global_positions(), m.global_positions(), atol=1e-5, rtol=0)
    assert back.skeleton.channels[1][:3] == ["Xposition", "Yposition", "Zposition"]


@pytest.mark.parametrize("order", ["".join(p) for p in itertools.permutations("XYZ")])
def test_round_trip_every_channel_order(tmp_path, order):
    motion, _ = sa.procedural.generate("biped17", "run", seconds=1, fps=30, seed=2)
    channels = [[*("Xposition", "Yposition", "Zposition")] + [f"{a}rotation" for a in order]]
    channels += [[f"{a}rotation" for a in order]] * (motion.num_joints - 1)
    sk = motion.skeleton
    sk2 = sa.Skeleton(
        sk.joint_names, sk.parents, sk.offsets, end_sites=sk.end_sites, channels=channels
    )
    m = sa.Motion(sk2, motion.rotations, motion.root_positions, motion.fps)
    path = tmp_path / "o.bvh"
    sa.write_bvh(m, path)
    assert f"CHANNELS 3 {' '.join(channels[1])}" in path.read_text()
    back = sa.read_bvh(path)
    assert max_angle_deg(back.rotations, m.rotations) < 1e-4
    torch.testing.assert_close(back.global_positions(), m.global_positions(), atol=1e-5, rtol=0)


@pytest.mark.data
def test_every_real_clip_loads_and_round_trips(shared_data, tmp_path):
    files = sorted(shared_data.rglob("*.bvh"))
    assert len(files) >= 20
    expected_joints = {"cmu": 31, "xia_cmu": 31, "lafan1": 22, "mann": 21}
    for path in files:
        m = sa.read_bvh(path)
        assert m.num_joints == expected_joints[path.parent.name], path
        assert torch.isfinite(m.global_positions()).all()
        out = tmp_path / path.name
        sa.write_bvh(m, out)
        back = sa.read_bvh(out)
        assert back.skeleton.joint_names == m.skeleton.joint_names
        assert back.skeleton.channels == m.skeleton.channels
        assert back.fps == m.fps and back.num_frames == m.num_frames
        assert max_angle_deg(back.rotations, m.rotations) < 1e-4, path
        torch.testing.assert_close(back.root_positions, m.root_positions, atol=1e-5, rtol=0)
        torch.testing.assert_close(back.skeleton.offsets, m.skeleton.offsets, atol=1e-5, rtol=0)
        assert back.skeleton.end_sites.keys() == m.skeleton.end_sites.keys()


@pytest.mark.data
def test_read_quaternions_are_sign_continuous(shared_data):
    m = sa.read_bvh(shared_data / "human" / "lafan1" / "Lafan1_example.bvh")
    dots = (m.rotations[1:] * m.rotations[:-1]).sum(-1)
    assert (dots >= 0).all()


@pytest.mark.data
def test_euler_values_round_trip_on_real_clip(shared_data, tmp_path):
    """The written channel values equal the file's within 1e-4 degrees (mod 360)."""
    src = shared_data / "dog" / "mann" / "D1_010_KAN01_002.bvh"
    out = tmp_path / "dog.bvh"
    sa.write_bvh(sa.read_bvh(src), out)

    def values(path):
        lines = path.read_text().splitlines()
        start = next(i for i, line in enumerate(lines) if line.startswith("Frame Time")) + 1
        return np.array(
            [[float(v) for v in line.split()] for line in lines[start:] if line.strip()]
        )

    a, b = values(src), values(out)
    diff = np.abs((a - b + 180.0) % 360.0 - 180.0)
    pos_cols = [0, 1, 2]
    assert diff[:, pos_cols].max() < 1e-5
    assert diff[:, 3:].max() < 1e-4


BAD_CASES = {
    "truncated hierarchy": (TINY.split("MOTION")[0][:120], "unexpected end", 6),
    "no motion section": (TINY.split("MOTION")[0], "no MOTION", None),
    "channel count": (
        TINY.replace(
            "CHANNELS 3 Zrotation Xrotation Yrotation", "CHANNELS 4 Zrotation Xrotation Yrotation"
        ),
        "declares 4",
        10,
    ),
    "unknown channel": (
        TINY.replace("Xrotation Yrotation Zrotation", "Xrotation Wrotation Zrotation"),
        "unknown channel 'Wrotation'",
        18,
    ),
    "duplicate joint": (
        TINY.replace("JOINT LeftUpLeg", "JOINT Spine"),
        "duplicate joint name 'Spine'",
        15,
    ),
    "short line": (
        TINY.replace("1 91 2 5 -5 10 15 25 35 4 5 6", "1 91 2 5 -5 10 15 25 35 4 5"),
        "has 11 values",
        29,
    ),
    "nan value": (TINY.replace("2 92 4", "2 nan 4"), "not finite", 30),
    "inf value": (TINY.replace("2 92 4", "2 inf 4"), "not finite", 30),
    "text value": (TINY.replace("2 92 4", "2 abc 4"), "'abc' is not a number", 30),
    "zero frames": (
        TINY.replace("Frames: 3", "Frames: 0").rsplit("Frame Time: 0.0333333", 1)[0]
        + "Frame Time: 0.0333333\n",
        "at least one",
        26,
    ),
    "missing frames": (TINY.replace("Frames: 3", "Frames: 5"), "declares 5 frames but has 3", 30),
    "bad frame time": (TINY.replace("Frame Time: 0.0333333", "Frame Time: -1"), "positive", 27),
    "bad offset": (TINY.replace("OFFSET 0 10 0", "OFFSET 0 x 0"), "'x' is not a number", 8),
    "nan offset": (TINY.replace("OFFSET 0 10 0", "OFFSET 0 nan 0"), "not finite", 8),
    "not a bvh": ("hello world\n", "starts with 'HIERARCHY'", 1),
    "motion not alone on its line": (
        TINY.replace("}\nMOTION", "} MOTION"),
        "'MOTION' must stand alone on its line",
        24,
    ),
    "empty": ("", "empty", 1),
}


@pytest.mark.parametrize("case", sorted(BAD_CASES))
def test_bad_input_names_file_and_line(tmp_path, case):
    text, message, line = BAD_CASES[case]
    path = write(tmp_path, text, name="bad.bvh")
    with pytest.raises(sa.BVHError, match=message) as info:
        sa.read_bvh(path)
    err = info.value
    assert err.path == path and str(path) in str(err)
    if line is not None:
        assert err.line == line, str(err)
        assert f"bad.bvh:{line}:" in str(err)
    assert isinstance(err, sa.SkelagnosticError) and isinstance(err, ValueError)


def test_missing_file_and_directory(tmp_path):
    with pytest.raises(sa.BVHError, match="no such file"):
        sa.read_bvh(tmp_path / "nope.bvh")
    with pytest.raises(sa.BVHError, match="directory"):
        sa.read_bvh(tmp_path)


def test_write_is_atomic(tmp_path):
    motion, _ = sa.procedural.generate("biped22", "idle", seconds=0.5, fps=30)
    target = tmp_path / "missing_dir" / "x.bvh"
    with pytest.raises(sa.BVHError, match="cannot write"):
        sa.write_bvh(motion, target)
    out = tmp_path / "x.bvh"
    sa.write_bvh(motion, out)
    assert [p.name for p in tmp_path.iterdir()] == ["x.bvh"]  # no temporary left behind
    back = sa.read_bvh(out)
    assert back.skeleton.channels[0][:3] == ["Xposition", "Yposition", "Zposition"]
    torch.testing.assert_close(
        back.global_positions(), motion.global_positions(), atol=1e-5, rtol=0
    )


def test_parse_bvh_from_text():
    m = sa.parse_bvh(TINY)
    assert m.num_frames == 3
    with pytest.raises(sa.BVHError, match=r"<bvh text>:\d+"):
        sa.parse_bvh(TINY.replace("2 92 4", "2 nan 4"))


def test_rotations_are_converted_once_on_first_use(tmp_path):
    import copy
    import pickle

    motion, _ = sa.procedural.generate("biped31", "run", seconds=1.0, fps=30)
    path = tmp_path / "run.bvh"
    sa.write_bvh(motion, path)
    read = sa.read_bvh(path)
    # metadata does not need the rotations ...
    assert read._rotations is None
    assert (read.num_frames, read.num_joints, read.dtype) == (31, 31, torch.float64)
    # ... a pickle or a copy carries them, computed once
    for other in (pickle.loads(pickle.dumps(read)), copy.deepcopy(read)):
        assert torch.equal(other.rotations, read.rotations)
    first = read.rotations
    assert read.rotations is first and read._pending is None
    assert torch.allclose(read.global_positions(), motion.global_positions(), atol=1e-5)
    assert sa.read_bvh(path, dtype=torch.float32).rotations.dtype == torch.float32


def test_header_encodings_blank_lines_and_bad_bytes_in_the_data(tmp_path):
    # Only the hierarchy and the two header lines are decoded; blank lines may sit
    # between MOTION, Frames: and Frame Time:, and stray bytes in the data are reported
    # with their line.
    text = TINY.replace("Spine", "Spíne").replace("Frames: 3\n", "\n\nFrames: 3\n\n")
    path = tmp_path / "enc.bvh"
    path.write_bytes(text.encode("utf-8"))
    m = sa.read_bvh(path)
    assert m.skeleton.joint_names[1] == "Spíne" and m.num_frames == 3
    bad = text.encode("utf-8").replace(b"\n2 92", b"\n\xff 92")
    path.write_bytes(bad)
    line = text.splitlines().index("2 92 4 10 -10 20 20 30 40 7 8 9") + 1
    with pytest.raises(sa.BVHError, match=rf"enc.bvh:{line}: motion value '.' is not a number"):
        sa.read_bvh(path)


def test_a_name_that_is_not_utf8_is_an_error_naming_the_byte(tmp_path):
    # no guessing at latin-1: the first byte that is not UTF-8 is named
    path = tmp_path / "latin1.bvh"
    path.write_bytes(TINY.replace("Spine", "Spíne").encode("latin-1"))
    offset = TINY.encode().index(b"Spine") + 2
    with pytest.raises(sa.BVHError) as info:
        sa.read_bvh(path)
    assert (info.value.line, info.value.reason) == (
        6,
        f"invalid UTF-8 at byte offset {offset} (0xed); BVH files are read as UTF-8, re-save "
        "this one in that encoding",
    )
    # after a byte order mark the offset still counts from the start of the file
    path.write_bytes(b"\xef\xbb\xbf" + TINY.replace("Spine", "Spíne").encode("latin-1"))
    with pytest.raises(sa.BVHError, match=f"byte offset {offset + 3} "):
        sa.read_bvh(path)


def test_byte_order_mark_and_unterminated_last_line(tmp_path):
    reference = sa.parse_bvh(TINY)
    for data in ("\ufeff" + TINY, b"\xef\xbb\xbf" + TINY.encode()):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            motion = sa.parse_bvh(data)
        assert motion.skeleton == reference.skeleton
        assert torch.equal(motion.rotations, reference.rotations)
    # "...7 8 9.25" cut to "...7 8 9." reads as 9.0: warned, naming the line
    cut = TINY.removesuffix("9\n") + "9."
    path = write(tmp_path, cut, name="cut.bvh")
    with pytest.warns(BVHWarning) as record:
        motion = sa.read_bvh(path)
    assert [str(w.message) for w in record] == [
        f"{path}:30: the last motion line has no line end, so the file may be truncated (its "
        "last value read as '9.')"
    ]
    assert motion.num_frames == 3
    # the value count of that line is still checked
    with pytest.raises(sa.BVHError, match=r"cut\.bvh:30: motion line has 11 values"):
        sa.read_bvh(write(tmp_path, TINY.removesuffix(" 9\n"), name="cut.bvh"))
    # trailing blanks after the last line end are no cut
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sa.parse_bvh(TINY + "  \t")


def deep_chain(levels: int, frames: int = 2) -> str:
    """A BVH text whose joints form one chain ``levels`` deep (no indentation)."""
    lines = [
        "HIERARCHY",
        "ROOT J0",
        "{",
        "OFFSET 0 0 0",
        "CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation",
    ]
    for k in range(1, levels):
        lines += [f"JOINT J{k}", "{", "OFFSET 0 1 0", "CHANNELS 3 Zrotation Yrotation Xrotation"]
    lines += ["End Site", "{", "OFFSET 0 1 0", "}"] + ["}"] * levels
    lines += ["MOTION", f"Frames: {frames}", "Frame Time: 0.0333333"]
    for f in range(frames):
        lines.append(" ".join(["0", "0", str(f)] + ["0.5"] * (3 * levels)))
    return "\n".join(lines) + "\n"


def test_10000_level_hierarchy_reads_and_round_trips(tmp_path):
    # depth is limited by memory only: no recursion in the parser, the skeleton, body
    # groups, forward kinematics, the height or the writer
    levels = 10_000
    path = write(tmp_path, deep_chain(levels), name="deep.bvh")
    motion = sa.read_bvh(path)
    sk = motion.skeleton
    assert sk.num_joints == levels and sk.parents[-1] == levels - 2
    assert sk.end_sites == {levels - 1: [[0.0, 1.0, 0.0]]}
    assert sk.height() > 0 and len(sk.body_groups) == levels
    positions = motion.global_positions()
    assert positions.shape == (2, levels, 3) and torch.isfinite(positions).all()
    out = tmp_path / "deep_out.bvh"
    sa.write_bvh(motion, out)
    back = sa.read_bvh(out)
    assert back.skeleton == sk and back.skeleton.end_sites == sk.end_sites
    torch.testing.assert_close(back.rotations, motion.rotations, atol=1e-6, rtol=0)
    # the indentation stops growing, so the file stays proportional to the joint count
    assert out.stat().st_size < 5 * path.stat().st_size


def test_extreme_but_finite_frame_times_read_and_round_trip(tmp_path):
    # 1e-9 s was written back as "Frame Time: 0.00000000", which does not read
    for frame_time in (1e-9, 1e300):
        text = TINY.replace("Frame Time: 0.0333333", f"Frame Time: {frame_time}")
        motion = sa.read_bvh(write(tmp_path, text))
        assert motion.fps == pytest.approx(1 / frame_time, rel=1e-12)
        sa.write_bvh(motion, tmp_path / "out.bvh")
        assert sa.read_bvh(tmp_path / "out.bvh").fps == pytest.approx(motion.fps, rel=1e-12)
    # the usual rates keep their 8-decimal Frame Time line
    sa.write_bvh(sa.parse_bvh(TINY), tmp_path / "30.bvh")
    assert "\nFrame Time: 0.03333333\n" in (tmp_path / "30.bvh").read_text()


@pytest.fixture
def umask():
    """Set the process umask for the test (``umask(0o022)``) and restore it afterwards."""
    old = os.umask(0o022)
    yield os.umask
    os.umask(old)


def test_written_files_get_the_permissions_the_umask_allows(tmp_path, umask):
    motion = sa.parse_bvh(TINY)
    for mask, mode in ((0o022, 0o644), (0o027, 0o640), (0o077, 0o600)):
        umask(mask)
        path = tmp_path / f"{mask:03o}.bvh"
        sa.write_bvh(motion, path)
        assert stat.S_IMODE(path.stat().st_mode) == mode, oct(mask)
    # an existing file keeps its permissions when it is replaced
    umask(0o022)
    path = tmp_path / "private.bvh"
    path.write_text("old")
    path.chmod(0o600)
    sa.write_bvh(motion, path)
    assert stat.S_IMODE(path.stat().st_mode) == 0o600 and path.read_text().startswith("HIER")


def test_write_through_a_symbolic_link(tmp_path):
    motion = sa.parse_bvh(TINY)
    real = tmp_path / "data" / "real.bvh"
    real.parent.mkdir()
    real.write_text("old")
    link = tmp_path / "link.bvh"
    link.symlink_to(Path("data") / "real.bvh")  # a relative link
    sa.write_bvh(motion, link)
    assert link.is_symlink() and os.readlink(link) == str(Path("data") / "real.bvh")
    assert sa.read_bvh(real).num_frames == 3
    assert sorted(p.name for p in real.parent.iterdir()) == ["real.bvh"]  # no temporary left
    # a dangling link creates the file it names
    dangling = tmp_path / "dangling.bvh"
    dangling.symlink_to(tmp_path / "data" / "new.bvh")
    sa.write_bvh(motion, dangling)
    assert dangling.is_symlink() and (tmp_path / "data" / "new.bvh").is_file()
    # a link loop is one clear error
    loop = tmp_path / "loop.bvh"
    loop.symlink_to(loop)
    with pytest.raises(sa.BVHError) as info:
        sa.write_bvh(motion, loop)
    assert str(info.value) == f"{loop}: cannot write: Too many levels of symbolic links"
    assert loop.is_symlink()


def test_full_disk_is_a_bvh_error_and_leaves_the_target_untouched(tmp_path, monkeypatch):
    motion = sa.parse_bvh(TINY)
    target = tmp_path / "clip.bvh"
    target.write_text("the old file")

    def no_space(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "fsync", no_space)  # where a full disk may surface last
    with pytest.raises(sa.BVHError) as info:
        sa.write_bvh(motion, target)
    assert str(info.value) == f"{target}: cannot write: No space left on device"
    assert target.read_text() == "the old file"
    assert [p.name for p in tmp_path.iterdir()] == ["clip.bvh"]


def test_failing_write_is_a_bvh_error_and_leaves_the_target_untouched(tmp_path):
    # a real failing write(2): the file size limit (RLIMIT_FSIZE) makes it fail with
    # EFBIG, as a full disk fails with ENOSPC; in a subprocess so that the limit
    # cannot touch pytest's own files
    target = tmp_path / "clip.bvh"
    target.write_text("the old file")
    code = f"""
import resource, signal
import skelagnostic as sa
motion, _ = sa.procedural.generate("biped22", "walk", seconds=2.0, fps=30)
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
resource.setrlimit(resource.RLIMIT_FSIZE, (4096, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))
try:
    sa.write_bvh(motion, {str(target)!r})
except sa.BVHError as exc:
    print(exc)
"""
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(REPO / "src"), os.environ.get("PYTHONPATH", "")]),
    }
    proc = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == f"{target}: cannot write: File too large", proc.stderr
    assert target.read_text() == "the old file"
    assert [p.name for p in tmp_path.iterdir()] == ["clip.bvh"]
