"""The shared atomic writer: umask, existing permissions, symbolic links, failures."""

import os
import stat

import pytest

from skelagnostic.io.atomic import atomic_write


def test_new_file_follows_the_umask_and_content_is_complete(tmp_path):
    old = os.umask(0o027)
    try:
        written = atomic_write(tmp_path / "a.bin", b"abc")
        atomic_write(tmp_path / "b.bin", lambda fh: fh.write(b"def"))
    finally:
        os.umask(old)
    assert written == tmp_path / "a.bin" and written.read_bytes() == b"abc"
    assert (tmp_path / "b.bin").read_bytes() == b"def"
    assert {stat.S_IMODE(p.stat().st_mode) for p in tmp_path.iterdir()} == {0o640}


def test_a_failing_writer_leaves_the_target_and_no_temporary(tmp_path):
    target = tmp_path / "a.bin"
    target.write_bytes(b"old")
    target.chmod(0o604)

    def half(fh):
        fh.write(b"new but")
        raise RuntimeError("interrupted")

    with pytest.raises(RuntimeError, match="interrupted"):
        atomic_write(target, half)
    assert [p.name for p in tmp_path.iterdir()] == ["a.bin"] and target.read_bytes() == b"old"
    atomic_write(target, b"new")
    assert target.read_bytes() == b"new" and stat.S_IMODE(target.stat().st_mode) == 0o604


def test_symbolic_links_are_written_through(tmp_path):
    (tmp_path / "sub").mkdir()
    target = tmp_path / "sub" / "real.bin"
    target.write_bytes(b"old")
    link = tmp_path / "link.bin"
    link.symlink_to(target)
    assert atomic_write(link, b"new") == target
    assert link.is_symlink() and target.read_bytes() == b"new"
    with pytest.raises(FileNotFoundError):
        atomic_write(tmp_path / "missing" / "x.bin", b"x")
