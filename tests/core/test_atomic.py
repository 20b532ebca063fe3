"""The shared atomic writer: umask, existing permissions, symbolic links, failures."""

import os
import stat

import pytest

from skelagnostic.io.atomic import atomic_path, atomic_write


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


def test_writers_by_name_get_the_umask_mode_whatever_mode_they_create(tmp_path):
    # torch.onnx.export / torch.jit.save write by name; export used mkstemp (0o600)
    def recreate_private(path):
        path.unlink()
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        os.write(fd, b"model")
        os.close(fd)

    old = os.umask(0o022)
    try:
        with atomic_path(tmp_path / "new.onnx") as tmp:
            assert tmp.parent == tmp_path and tmp.is_file() and tmp.name != "new.onnx"
            recreate_private(tmp)
        with atomic_path(tmp_path / "plain.json") as tmp:
            tmp.write_text("{}")
    finally:
        os.umask(old)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["new.onnx", "plain.json"]
    assert (tmp_path / "new.onnx").read_bytes() == b"model"
    assert {stat.S_IMODE(p.stat().st_mode) for p in tmp_path.iterdir()} == {0o644}
    # an existing file keeps its mode; a failure leaves it and no temporary file
    (tmp_path / "new.onnx").chmod(0o640)
    with atomic_path(tmp_path / "new.onnx") as tmp:
        recreate_private(tmp)
    assert stat.S_IMODE((tmp_path / "new.onnx").stat().st_mode) == 0o640
    with (
        pytest.raises(RuntimeError, match="exporter failed"),
        atomic_path(tmp_path / "new.onnx") as tmp,
    ):
        tmp.write_bytes(b"half")
        raise RuntimeError("exporter failed")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["new.onnx", "plain.json"]
    assert (tmp_path / "new.onnx").read_bytes() == b"model"
